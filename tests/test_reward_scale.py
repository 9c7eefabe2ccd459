"""r_tc's scale against λ_ga's stated purpose (protocol v8 rule 1, `distgprl.reward_scale`).

Both ratios are computed from the reward code itself: episodes of the adaptation env on each
task, whose ``info`` carries every reward term, never pay λ_ga Σ r_ga beyond the idle bound,
and a successful episode's r_tc is the success return the ratios divide by."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.config import load_config
from distgprl.config_types import Config, EnvConfig
from distgprl.envs.via_point_env import AdaptationEnv
from distgprl.errors import ConfigError, UserInputError
from distgprl.reward_scale import (
    MAX_GA_SHARE_OF_SUCCESS,
    MAX_IDLE_SHARE_OF_DEMO,
    check_reward_scale,
    demo_outcome,
    demo_task_return,
    ga_share_of_success,
    idle_episode_return,
    idle_share_of_demo,
    success_task_return,
)

TASKS = ("dcp", "dbm")


@pytest.mark.parametrize("task", TASKS)
def test_the_paper_defaults_keep_both_bounds_on_each_task(task):
    """Table I's scale: r_ga can pay 3 % of a success (bound 5 %), and an idle episode under
    10 % of the demonstration's mean r_tc, on each task."""
    env = load_config("paper", task=task).env
    assert ga_share_of_success(env) == pytest.approx(0.03)
    assert ga_share_of_success(env) <= MAX_GA_SHARE_OF_SUCCESS
    assert idle_share_of_demo(env, demo_outcome(task)) <= MAX_IDLE_SHARE_OF_DEMO


def test_v7s_unit_breaks_bound_a_and_is_refused_naming_the_key():
    """r_tc in units of one task (v7) lets r_ga pay 30 % of a success: a `ConfigError` (exit 2
    at the CLI) naming ``env.progress_weight``."""
    env = EnvConfig(progress_weight=1.0, success_bonus=1.0, collision_penalty=1.0)
    assert ga_share_of_success(env) == pytest.approx(0.3)
    with pytest.raises(ConfigError) as caught:
        check_reward_scale(env, "v7.yaml")
    assert caught.value.key == "env.progress_weight" and "v7.yaml" in str(caught.value)
    assert isinstance(caught.value, UserInputError)


def test_bound_b_is_checked_per_task():
    """A scale that keeps (a) but lets idling pay over 10 % of the demonstration on a task
    (a collision penalty that eats what the demonstration earns on DBM) is refused."""
    env = EnvConfig(collision_penalty=25.0)
    assert ga_share_of_success(env) <= MAX_GA_SHARE_OF_SUCCESS
    assert max(idle_share_of_demo(env, demo_outcome(t)) for t in TASKS) > MAX_IDLE_SHARE_OF_DEMO
    with pytest.raises(ConfigError):
        check_reward_scale(env, "b.yaml")


def test_demo_return_is_linear_in_the_outcome():
    outcome = demo_outcome("dcp")
    env = Config().env
    expected = 10 * (outcome.progress + outcome.success_rate - outcome.collision_rate)
    assert demo_task_return(env, outcome) == pytest.approx(expected)


def _episode_terms(env: AdaptationEnv, tc, rng: np.random.Generator, scale: float) -> dict:
    """Sum of every reward term of one episode under random actions of ``scale``."""
    env.reset(options={"tc": tc})
    totals: dict[str, float] = {}
    info: dict = {}
    terminated = False
    while not terminated:
        action = scale * rng.uniform(-1, 1, env.action_space.shape)
        _, reward, terminated, _, info = env.step(action.astype(np.float32))
        terms = {k: v for k, v in info.items() if k.startswith("r_")}
        assert reward == pytest.approx(sum(terms.values()))
        for name, value in terms.items():
            totals[name] = totals.get(name, 0.0) + value
    totals["success"] = bool(info["success"])
    return totals


@pytest.mark.parametrize("task", TASKS)
def test_the_reward_code_pays_r_ga_within_the_idle_bound_and_success_as_divided_by(task):
    """Episodes of the env with distance rewards: λ_ga Σ r_ga never exceeds
    `idle_episode_return`; a successful episode's r_tc (progress + bonus, no collision) is at
    most `success_task_return`, and the demonstration's own TC (no offset) is such a success
    whose r_tc is that return up to the progress the scene starts with."""
    config = load_config("paper", task=task).env
    env = AdaptationEnv(task, "dist-gprl", config)
    rng = np.random.default_rng(0)
    try:
        for tc in env.spec_task.evaluation_tcs(3):
            for scale in (0.0, 1.0):
                totals = _episode_terms(env, tc, rng, scale)
                assert totals["r_ga"] <= idle_episode_return(config) + 1e-9
                r_tc = totals["r_progress"] + totals["r_success"] + totals["r_collision"]
                assert r_tc <= success_task_return(config) + 1e-9
    finally:
        env.close()
