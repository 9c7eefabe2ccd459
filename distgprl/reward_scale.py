"""r_tc's scale against λ_ga's stated purpose (protocol rule 1).

The paper sets λ_ga = 0.2 "to provide more importance to the task completion while avoiding
local collisions" (§V-A) but gives r_tc no unit. The unit is chosen so that the purpose holds,
which this module states as two ratios computed from the reward terms of Eq. (total_reward):

(a) ``ga_share_of_success``: the most λ_ga Σ r_ga one episode can earn (a cosine ≤ 1 at each
    of the ``n_windows`` steps: ``n_windows · λ_ga``) over the r_tc of a success (the whole
    progress plus the success bonus). Bound: `MAX_GA_SHARE_OF_SUCCESS` = 5 %. Argument: a
    success-rate difference Table I can resolve at 100 evaluation TCs is about 0.1 (the 95 %
    binomial half-width at p = 0.5 is 0.098); whatever r_ga pays must be worth less than half
    of that, so that no policy gains by trading task completions for alignment.
(b) ``idle_share_of_demo``: the most an episode that never attempts the task (no progress, no
    success, no collision) can earn — r_ga's maximum, r_sd being ≤ 0 — over the mean r_tc of
    executing the TC-conditioned demonstration on the evaluation TCs (`DemoOutcome`, measured
    per task). Bound: `MAX_IDLE_SHARE_OF_DEMO` = 10 %: doing nothing must pay clearly less than
    the demonstration, which every adaptation starts from.

`check_reward_scale` raises a `ConfigError` (the CLI exits 2) naming the key when a
configuration breaks either bound; `distgprl.config.load_config` calls it for every preset.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from distgprl.config_types import EnvConfig
from distgprl.data import DATA_DIR, TASK_NAMES
from distgprl.errors import ConfigError, UserInputError

__all__ = [
    "DEMO_OUTCOMES_PATH",
    "MAX_GA_SHARE_OF_SUCCESS",
    "MAX_IDLE_SHARE_OF_DEMO",
    "DemoOutcome",
    "check_reward_scale",
    "describe_reward_scale",
    "demo_outcome",
    "demo_task_return",
    "ga_share_of_success",
    "idle_episode_return",
    "idle_share_of_demo",
    "success_task_return",
]

MAX_GA_SHARE_OF_SUCCESS = 0.05
"""Bound (a): λ_ga Σ r_ga's maximum per episode over a success's r_tc."""

MAX_IDLE_SHARE_OF_DEMO = 0.10
"""Bound (b): an idle episode's maximum return over the demonstration's mean r_tc."""

DEMO_OUTCOMES_PATH = DATA_DIR / "demo_outcomes.json"
"""Per task, the TC-conditioned demonstration's outcome on the 100 evaluation TCs."""


@dataclass(frozen=True)
class DemoOutcome:
    """What executing the unadapted demonstration achieves on a task's evaluation TCs.

    Attributes:
        episodes: evaluation TCs the figures are means over.
        progress: mean task progress gained per episode, in [0, 1].
        success_rate: share of episodes completed without collision.
        collision_rate: share of episodes with a collision (each ends at its collision, so it
            pays the collision penalty once).
        source: where the figures were measured.
    """

    episodes: int
    progress: float
    success_rate: float
    collision_rate: float
    source: str


def success_task_return(env: EnvConfig) -> float:
    """r_tc of a successful episode: the whole progress plus the success bonus (Eq.
    total_reward's r_tc; no collision)."""
    return env.progress_weight + env.success_bonus


def idle_episode_return(env: EnvConfig) -> float:
    """The most an episode that never attempts the task can earn: λ_ga times a cosine of 1 at
    every step (Eq. grad_alignment_reward); its r_tc is 0 and r_sd ≤ 0 (Eq. safety_reward)."""
    return env.n_windows * env.lambda_ga


def demo_task_return(env: EnvConfig, outcome: DemoOutcome) -> float:
    """Mean r_tc of executing the demonstration under ``env``'s reward scale."""
    return (
        env.progress_weight * outcome.progress
        + env.success_bonus * outcome.success_rate
        - env.collision_penalty * outcome.collision_rate
    )


def ga_share_of_success(env: EnvConfig) -> float:
    """Ratio (a): λ_ga Σ r_ga's maximum per episode over a success's r_tc."""
    return idle_episode_return(env) / success_task_return(env)


def idle_share_of_demo(env: EnvConfig, outcome: DemoOutcome) -> float:
    """Ratio (b): an idle episode's maximum return over the demonstration's mean r_tc
    (infinite when the demonstration earns nothing)."""
    earned = demo_task_return(env, outcome)
    return idle_episode_return(env) / earned if earned > 0 else float("inf")


@cache
def _outcomes() -> dict[str, DemoOutcome]:
    path = Path(DEMO_OUTCOMES_PATH)
    try:
        data = json.loads(path.read_text())
        return {
            task: DemoOutcome(
                episodes=int(row["episodes"]),
                progress=float(row["progress"]),
                success_rate=float(row["success_rate"]),
                collision_rate=float(row["collision_rate"]),
                source=str(data["source"]),
            )
            for task, row in data["tasks"].items()
        }
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise UserInputError(
            f"{path}: not a readable demonstration-outcome file ({error})"
        ) from None


def demo_outcome(task: str) -> DemoOutcome:
    """The committed demonstration outcome of ``task`` (`DEMO_OUTCOMES_PATH`)."""
    outcomes = _outcomes()
    if task not in outcomes:
        raise UserInputError(f"{DEMO_OUTCOMES_PATH}: no demonstration outcome for task {task!r}")
    return outcomes[task]


def check_reward_scale(env: EnvConfig, origin: str, tasks: tuple[str, ...] = TASK_NAMES) -> None:
    """Raise a `ConfigError` naming ``env.progress_weight`` when ``env`` breaks bound (a) or,
    on any of ``tasks``, bound (b). ``origin`` is where the configuration came from."""
    share = ga_share_of_success(env)
    if share > MAX_GA_SHARE_OF_SUCCESS:
        raise ConfigError(
            f"{origin}: env.progress_weight = {env.progress_weight}: with env.success_bonus = "
            f"{env.success_bonus} and env.lambda_ga = {env.lambda_ga}, r_ga can pay "
            f"{share:.0%} of a success's r_tc (protocol v8 rule 1 (a) allows "
            f"{MAX_GA_SHARE_OF_SUCCESS:.0%})",
            "env.progress_weight",
        )
    for task in tasks:
        idle = idle_share_of_demo(env, demo_outcome(task))
        if idle > MAX_IDLE_SHARE_OF_DEMO:
            raise ConfigError(
                f"{origin}: env.progress_weight = {env.progress_weight}: on {task} an idle "
                f"episode can earn {idle:.0%} of the demonstration's mean r_tc (protocol v8 "
                f"rule 1 (b) allows {MAX_IDLE_SHARE_OF_DEMO:.0%})",
                "env.progress_weight",
            )


def describe_reward_scale(env: EnvConfig, task: str) -> str:
    """One line: both ratios of rule 1 for ``task`` under ``env``, with their bounds."""
    outcome = demo_outcome(task)
    idle = idle_share_of_demo(env, outcome)
    return (
        f"{task}: r_ga can pay {ga_share_of_success(env):.1%} of a success's r_tc "
        f"(bound {MAX_GA_SHARE_OF_SUCCESS:.0%}); an idle episode {idle:.1%} "
        f"of the demonstration's mean r_tc {demo_task_return(env, outcome):.2f} "
        f"(bound {MAX_IDLE_SHARE_OF_DEMO:.0%})"
    )
