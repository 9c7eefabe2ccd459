"""The range of each configuration field and the checks of a resolved configuration
(`check_config`): `distgprl.config.load_config` runs them on every preset it resolves."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from distgprl.config_types import Config, RunConfig
from distgprl.errors import ConfigError

__all__ = [
    "AT_LEAST_ONE",
    "BOUNDS",
    "FRACTION",
    "NON_NEGATIVE",
    "POSITIVE",
    "Bound",
    "check_config",
]

_SECTIONS = ("env", "sac", "run")


@dataclass(frozen=True)
class Bound:
    """The values a numeric field admits: at least ``low`` (more than it if ``strict``) and,
    if ``high`` is set, at most ``high``."""

    low: float = 0.0
    strict: bool = False
    high: float | None = None

    def admits(self, value: float) -> bool:
        """Whether ``value`` is in the range."""
        above = value > self.low if self.strict else value >= self.low
        return above and (self.high is None or value <= self.high)

    def describe(self) -> str:
        """The range in words: ``>= 0``, ``> 0``, ``in [0, 1]``."""
        if self.high is not None:
            return f"in [{self.low:g}, {self.high:g}]"
        return f"{'>' if self.strict else '>='} {self.low:g}"


NON_NEGATIVE = Bound()
POSITIVE = Bound(strict=True)
AT_LEAST_ONE = Bound(1)
FRACTION = Bound(0, high=1)

BOUNDS: dict[str, Bound] = {
    "env.n_via_points": Bound(2),
    "env.window_size": Bound(2),  # windows overlap by one via-point
    "env.n_windows": AT_LEAST_ONE,
    "env.position_action_scale": POSITIVE,
    "env.rotation_action_scale": POSITIVE,
    "env.sd_epsilon": POSITIVE,
    "env.sd_samples_per_segment": AT_LEAST_ONE,
    "env.blend_fraction": FRACTION,
    "env.clearance_clip": POSITIVE,
    "env.clearance_scale": POSITIVE,
    "env.relative_position_scale": POSITIVE,
    "env.signature_depth": AT_LEAST_ONE,
    "env.signature_scale": POSITIVE,
    "sac.learning_rate": POSITIVE,
    "sac.buffer_size": AT_LEAST_ONE,
    "sac.batch_size": AT_LEAST_ONE,
    "sac.gamma": FRACTION,
    "sac.tau": FRACTION,
    "sac.train_freq": AT_LEAST_ONE,
    "sac.gradient_steps": AT_LEAST_ONE,
    "sac.net_arch": AT_LEAST_ONE,  # every layer's width
    "sac.n_similarity_samples": AT_LEAST_ONE,
    "sac.hap_k": AT_LEAST_ONE,
    "sac.hap_temperature": POSITIVE,
    "sac.hap_n_query": AT_LEAST_ONE,
    "sac.anneal_start": POSITIVE,
    "sac.anneal_end": POSITIVE,
    "sac.ent_coef_init": POSITIVE,
    **{f"run.{f.name}": AT_LEAST_ONE for f in fields(RunConfig)},
}
"""The range of each numeric field (``section.key``; list fields: of each item) where it is
narrower than `NON_NEGATIVE`, the range of every other one: no weight (every ``lambda_*``
included), penalty, distance or count is negative; step counts, sizes and periods are at
least one; scales and rates are positive."""


def _numbers(value: Any) -> list[float]:
    """The numbers a field's value holds: itself, or a list field's items."""
    items = value if isinstance(value, tuple) else (value,)
    return [item for item in items if isinstance(item, int | float) and not isinstance(item, bool)]


def check_config(config: Config, origin: dict[str, str]) -> None:
    """Raise a `ConfigError` for the first value out of its range (`BOUNDS`) or values that
    do not fit together (the windows in the via-points; stopping between episodes).

    ``origin`` maps ``section.key`` to where its value was set (a file, ``overrides``);
    ``""`` to where the defaults were merged (the preset file)."""

    def fail(name: str, message: str) -> ConfigError:
        return ConfigError(f"{origin.get(name, origin[''])}: {name} = {message}", name)

    length_scale = config.env.correlation_length_scale
    if length_scale < 0:
        raise fail(
            "env.correlation_length_scale",
            f"{length_scale} must be > 0 (normalised time), or 0 for the kernel fitted to "
            "the demonstration",
        )
    for section in _SECTIONS:
        values = getattr(config, section)
        for item in fields(values):
            name = f"{section}.{item.name}"
            bound = BOUNDS.get(name, NON_NEGATIVE)
            value = getattr(values, item.name)
            if not all(bound.admits(number) for number in _numbers(value)):
                shown = list(value) if isinstance(value, tuple) else value
                raise fail(name, f"{shown!r} must be {bound.describe()}")
    env = config.env
    if env.window_size > env.n_via_points:
        raise fail(
            "env.window_size",
            f"{env.window_size} is larger than env.n_via_points = {env.n_via_points}",
        )
    needed = env.n_windows * (env.window_size - 1) + 3  # start, windows, last two points
    if needed > env.n_via_points:
        raise fail(
            "env.window_size",
            f"{env.window_size}: {env.n_windows} windows of {env.window_size} via-points, "
            f"overlapping by one, need {needed} (the first and the last two are not adapted); "
            f"env.n_via_points is {env.n_via_points}",
        )
    episode = env.n_windows
    for key in ("total_steps", "eval_every", "checkpoint_every"):
        if getattr(config.run, key) % episode:
            raise fail(
                f"run.{key}",
                f"{getattr(config.run, key)} must be a multiple of the episode length "
                f"({episode} RL steps) so that runs stop between episodes",
            )
