"""The trial adapter observes and plans exactly as the environment the policy trained in."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.hardware.adapter import (
    PerceivedAdaptation,
    PerceivedResidual,
    TrackedObject,
    perceived_env,
)
from distgprl.sim.tasks.base import TaskConfig

TC = TaskConfig(object_offset=(0.0, 0.07), obstacle_offset=(0.0, -0.12))


def _training_env(method: str):
    from distgprl.experiments.runner import make_env, resolve_run

    return make_env(resolve_run("dbm", method, 0, preset="ci"))


def _bar_transform(position: np.ndarray) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, 3] = position
    return transform


@pytest.mark.parametrize(
    ("method", "kind"),
    [
        ("dist-gprl", PerceivedAdaptation),
        ("promp-rrl", PerceivedResidual),
        ("demo", PerceivedAdaptation),
    ],
)
def test_perceived_adapter_matches_the_training_env(method, kind):
    env = _training_env(method)
    adapter = perceived_env(method, env.config)
    try:
        assert isinstance(adapter, kind)
        obs, _ = env.reset(options={"tc": TC})
        # The adapter perceives exactly what the simulation holds at the episode start.
        now = float(env.sim.time)
        adapter.world.tracks["target_bar"] = TrackedObject(
            _bar_transform(env.sim.object_position()), now
        )
        adapter.world.tracks["other_bar"] = TrackedObject(
            _bar_transform(env.sim.other_bar_position_at(now)), now
        )
        tc = adapter.begin(env.sim.tcp_pose(), now)
        np.testing.assert_allclose(tc.object_offset, TC.object_offset, atol=1e-3)
        np.testing.assert_allclose(tc.obstacle_offset, TC.obstacle_offset, atol=1e-3)
        np.testing.assert_allclose(adapter.gamma, env.gamma, atol=1e-3)
        # the nominal under the adapted parameters (conditioned demo / ProMP mean)
        np.testing.assert_allclose(adapter._segment_base(0), env._segment_base(0), atol=1e-3)
        np.testing.assert_allclose(adapter.observe()["state"], obs["state"], atol=1e-2)

        action = np.random.default_rng(0).uniform(-1, 1, env.action_space.shape)
        planned = adapter.adapt(action)
        env.step(action)
        # The executed segment of the training env: same plan from the same parameters.
        np.testing.assert_allclose(adapter.gamma, env.gamma, atol=1e-3)
        assert planned.shape[1] == 6 and len(planned) == len(adapter.segment_times(0))
        adapter.executed(planned)
        assert adapter.step_index == 1
    finally:
        adapter.close()
        env.close()
