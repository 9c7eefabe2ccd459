"""ProMP-RRL residual environment."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.envs.residual import ResidualEnv


@pytest.fixture(scope="module")
def env():
    env = ResidualEnv("dcp")
    yield env
    env.close()


def test_zero_action_executes_the_nominal_trajectory(env):
    tc = env.spec_task.evaluation_tcs(2)[1]
    env.reset(options={"tc": tc})
    for step in range(3):
        tau, _, lo, hi = env._segment_maps[step]
        poses = env._segment_poses(step)
        # Only the first segment may blend out the robot-vs-ProMP start mismatch; past the
        # blend (and in every later segment) the nominal is executed exactly.
        past_blend = tau >= lo + env.config.blend_fraction * (hi - lo)
        np.testing.assert_allclose(poses[past_blend], env._nominal(tau[past_blend]), atol=1e-9)
        if step > 0:
            np.testing.assert_allclose(poses, env._nominal(tau), atol=1e-9)
        env.step(np.zeros(env.action_space.shape))


def test_nominal_starts_at_the_robot_and_engages_the_moved_object(env):
    """Object-centric: at the interaction time the nominal moves with the object offset."""
    tc_a, tc_b = env.spec_task.evaluation_tcs(2)
    interaction = np.array([env.spec_task.interaction_time])
    env.reset(options={"tc": tc_a})
    engage_a = env._nominal(interaction)[0, :2]
    np.testing.assert_allclose(env._nominal(np.zeros(1))[0, :3], env._start_pose[:3], atol=2e-3)
    env.reset(options={"tc": tc_b})
    engage_b = env._nominal(interaction)[0, :2]
    shift = np.subtract(tc_b.object_offset, tc_a.object_offset)
    np.testing.assert_allclose(engage_b - engage_a, shift, atol=0.03)


def test_residual_action_changes_only_the_window_weights(env):
    env.reset(options={"tc": env.spec_task.nominal_tc})
    env.step(np.full(env.action_space.shape, 0.5))
    window = env.layout.indices[0]
    assert np.all(env.gamma[window] != 0)
    assert np.all(np.delete(env.gamma, window, axis=0) == 0)
    assert env.observation_space["state"].shape == (42,)
