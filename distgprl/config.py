"""Configuration: frozen dataclasses with the paper's defaults, overridden by YAML presets.

A preset is shipped with the package (``distgprl/presets/<name>.yaml``, read with
`importlib.resources`, so an installed wheel has them) or is a user's own YAML file made
known with `register_preset` (the CLI's ``--config PATH``; its name is the file stem). It has
one mapping per section (``env``, ``sac``, ``run``) and optional per-task overrides under
``tasks: {dcp: {env: {...}}}``. Unknown keys (sections, fields, task names under ``tasks``)
are an error, so a typo in a preset never silently falls back to a default; so is a value
that does not convert to its field's type, or a ``clearance_timing`` other than
``"predicted"`` / ``"current"``. So is a number out of its field's range (`BOUNDS`: no
negative weight, step count or scale; counts of at least one), or a window layout that does
not fit the via-points (`check_config`). Every such error is one `ConfigError` line (a
`ValueError`, and a `UserInputError`: the CLI exits 2) naming the file, the dotted key
(``run.total_steps``), the value and what was expected.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields, replace
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import yaml

from distgprl.config_types import (
    ENVIRONMENT_VERSION,
    HASH_STABLE_DEFAULTS,
    Config,
    EnvConfig,
    RunConfig,
    SACConfig,
)
from distgprl.data import TASK_NAMES
from distgprl.errors import ConfigError, UserInputError
from distgprl.reward_scale import check_reward_scale

PRESET_DIR: Traversable | Path = resources.files("distgprl") / "presets"
"""The shipped presets (package data)."""

USER_PRESETS_ENV = "DISTGPRL_USER_PRESETS"
"""Environment variable listing the user's preset files (`os.pathsep`-separated absolute
paths) that `register_preset` made known; processes a sweep spawns inherit it."""


__all__ = [
    "ENVIRONMENT_VERSION",
    "HASH_STABLE_DEFAULTS",
    "PRESET_DIR",
    "USER_PRESETS_ENV",
    "Config",
    "EnvConfig",
    "RunConfig",
    "SACConfig",
    "check_config",
    "load_config",
    "preset_names",
    "register_preset",
    "shipped_presets",
]


_SECTIONS = {"env": EnvConfig, "sac": SACConfig, "run": RunConfig}


CHOICES: dict[str, tuple[str, ...]] = {
    "clearance_timing": ("predicted", "current"),
    "covariance_scale": ("zero-mean", "signal", "unit", "correlation", "signal-uncoupled"),
    "action_scale_rule": ("reach", "fixed"),
}
"""Fields that take one of a few strings; checked when a configuration is loaded."""


def _convert(key: str, value: Any, default: Any, where: str, section: str) -> Any:
    """``value`` converted to the type of the field ``section.key``'s ``default``, or a
    `ConfigError` naming the key, the value and the expected type."""

    def bad(expected: str) -> ConfigError:
        name = f"{section}.{key}"
        return ConfigError(f"{where}: {name} must be {expected}, got {value!r}", name)

    if isinstance(default, tuple):
        if isinstance(value, str | bytes) or not isinstance(value, list | tuple):
            raise bad("a list")
        kinds = {type(item) for item in default}
        if kinds <= {int} and not all(_is_int(item) for item in value):
            raise bad("a list of integers")
        return tuple(value)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if isinstance(default, int):
        if not _is_int(value):
            raise bad("an integer")
        return value
    if isinstance(default, float):
        if isinstance(value, bool):
            raise bad("a number")
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise bad("a number") from None
        if not math.isfinite(number):
            raise bad("a finite number")
        return number
    if isinstance(default, str):
        if not isinstance(value, str):
            raise bad("a string")
        if key in CHOICES and value not in CHOICES[key]:
            raise bad(" or ".join(repr(choice) for choice in CHOICES[key]))
        return value
    return value


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _apply(section_cls, current, overrides: Any, where: str, section: str):
    """``current`` (a section's dataclass) with ``overrides`` (that section's mapping of one
    layer) applied, each value converted to its field's type (`_convert`)."""
    if not isinstance(overrides, dict):
        raise ConfigError(
            f"{where}: {section}: a section must be a mapping of keys, got {overrides!r}", section
        )
    names = {f.name: f for f in fields(section_cls)}
    unknown = sorted(set(overrides) - set(names), key=str)
    if unknown:
        dotted = [f"{section}.{key}" for key in unknown]
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(dotted)}; valid: {', '.join(names)}", dotted[0]
        )
    values = {
        key: _convert(key, value, getattr(current, key), where, section)
        for key, value in overrides.items()
    }
    return replace(current, **values)


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


def shipped_presets() -> tuple[str, ...]:
    """Names of the presets shipped with the package, sorted."""
    return tuple(
        sorted(
            p.name.removesuffix(".yaml") for p in PRESET_DIR.iterdir() if p.name.endswith(".yaml")
        )
    )


def _user_presets() -> dict[str, Path]:
    """The registered user presets: name (file stem) -> file."""
    paths = [Path(p) for p in os.environ.get(USER_PRESETS_ENV, "").split(os.pathsep) if p]
    return {path.stem: path for path in paths}


def register_preset(path: str | Path) -> str:
    """Make a user's YAML file (same schema as the shipped presets) a preset named after its
    stem, for this process and the processes it starts; return that name.

    The file is loaded once here, so a mistake in it is reported before any run starts. Its
    location does not enter any config hash: the same file elsewhere gives the same runs.

    Raises:
        UserInputError: the file does not exist, does not load, its stem is a shipped preset's
            name, or another file of the same stem is registered already.
    """
    path = Path(path).expanduser().resolve()
    if not path.is_file():
        raise ConfigError(f"--config {path}: no such file")
    if path.suffix not in (".yaml", ".yml"):
        raise ConfigError(f"--config {path}: expected a .yaml file")
    name = path.stem
    if name in shipped_presets():
        raise ConfigError(
            f"--config {path}: its name {name!r} is a shipped preset's (shipped: "
            f"{', '.join(shipped_presets())}); rename the file so its runs are not mistaken "
            "for the shipped preset's"
        )
    registered = _user_presets()
    if name in registered and registered[name] != path:
        raise ConfigError(
            f"--config {path}: a preset named {name!r} is registered already from "
            f"{registered[name]}; rename one of the files"
        )
    if name in registered:
        return name
    previous = os.environ.get(USER_PRESETS_ENV)
    os.environ[USER_PRESETS_ENV] = os.pathsep.join(
        [*(str(p) for p in registered.values()), str(path)]
    )
    try:
        for task in (None, *TASK_NAMES):
            load_config(name, task=task)
    except UserInputError:  # a file that does not load is not left registered
        if previous is None:
            del os.environ[USER_PRESETS_ENV]
        else:
            os.environ[USER_PRESETS_ENV] = previous
        raise
    return name


def preset_names() -> tuple[str, ...]:
    """Every preset `load_config` resolves: the shipped ones, then the registered ones."""
    return shipped_presets() + tuple(sorted(set(_user_presets()) - set(shipped_presets())))


def _preset_text(preset: str) -> tuple[str, str]:
    """(YAML text, where it came from) of a preset, or a `UserInputError` listing the valid
    names."""
    shipped = PRESET_DIR / f"{preset}.yaml"
    if shipped.is_file():
        return shipped.read_text(), str(shipped)
    user = _user_presets().get(preset)
    if user is not None:
        try:
            return user.read_text(), str(user)
        except OSError as exc:
            raise ConfigError(f"preset {preset!r} ({user}): {exc.strerror}") from None
    raise ConfigError(
        f"unknown preset {preset!r}; valid presets: {', '.join(preset_names())} "
        "(or --config PATH for a YAML file of your own)",
        "preset",
    )


def load_config(
    preset: str = "paper",
    task: str | None = None,
    overrides: dict[str, dict[str, Any]] | None = None,
) -> Config:
    """Resolve a preset (and the task's overrides in it) into a `Config`.

    ``preset`` is a shipped preset's name or a registered user preset's (`register_preset`).

    Raises:
        ConfigError: the preset is unknown, not YAML, or has a key, a value or a combination
            of values that is wrong (module docstring); one line naming the file and the key.
    """
    text, path = _preset_text(preset)
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as exc:
        detail = " ".join(str(exc).split())
        raise ConfigError(f"{path}: not valid YAML ({detail})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a preset must be a mapping of sections, got {data!r}")
    tasks = data.get("tasks") or {}
    if not isinstance(tasks, dict):
        raise ConfigError(f"{path}: tasks must be a mapping of task names, got {tasks!r}", "tasks")
    unknown_tasks = sorted(set(tasks) - set(TASK_NAMES), key=str)
    if unknown_tasks:
        raise ConfigError(
            f"{path}: unknown task(s) {', '.join(map(str, unknown_tasks))} under tasks; "
            f"valid: {', '.join(TASK_NAMES)}",
            f"tasks.{unknown_tasks[0]}",
        )
    config = Config(preset=preset)
    layers = [(data, str(path), {"tasks"}, "")]
    if task is not None and task in tasks:
        layers.append((tasks[task] or {}, f"{path}: tasks.{task}", set(), f"tasks.{task}"))
    if overrides:
        layers.append((overrides, "overrides", set(), "overrides"))
    origin = {"": str(path)}  # where each key's value was last set, for `check_config`
    for layer, where, extra, name in layers:
        if not isinstance(layer, dict):
            raise ConfigError(f"{where}: must be a mapping of sections, got {layer!r}", name)
        unknown = sorted(set(layer) - set(_SECTIONS) - extra, key=str)
        if unknown:
            raise ConfigError(
                f"{where}: unknown section(s) {', '.join(map(str, unknown))}; valid: "
                f"{', '.join(_SECTIONS)}",
                str(unknown[0]),
            )
        for section, cls in _SECTIONS.items():
            if layer.get(section):
                updated = _apply(cls, getattr(config, section), layer[section], where, section)
                config = replace(config, **{section: updated})
                origin.update({f"{section}.{key}": where for key in layer[section]})
    check_config(config, origin)
    check_reward_scale(
        config.env, origin.get("env.progress_weight", str(path)), (task,) if task else TASK_NAMES
    )
    return config
