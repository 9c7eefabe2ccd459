"""The trial adapter observes and plans exactly as the environment the policy trained in."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.hardware.adapter import (
    PerceivedAdaptation,
    PerceivedResidual,
    PerceivedResidualControl,
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
        ("promp-rrl-windowed", PerceivedResidual),
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
        np.testing.assert_allclose(
            adapter.plan(adapter.segment_tau(0)), env.plan(env.segment_tau(0)), atol=1e-3
        )
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


def _begun(method: str):
    """A training env after reset and an adapter begun on the same perceived state."""
    env = _training_env(method)
    adapter = perceived_env(method, env.config)
    env.reset(options={"tc": TC})
    now = float(env.sim.time)
    adapter.world.tracks["target_bar"] = TrackedObject(
        _bar_transform(env.sim.object_position()), now
    )
    adapter.world.tracks["other_bar"] = TrackedObject(
        _bar_transform(env.sim.other_bar_position_at(now)), now
    )
    adapter.begin(env.sim.tcp_pose(), now)
    return env, adapter


def test_apply_action_is_the_one_window_update():
    """`AdaptationEnv.apply_action` clips, maps through the layout (S_W per axis) and adds
    Delta Gamma to the step's via-points only; the adapter's `adapt` is exactly that plus the
    segment's poses, and `executed` moves the continuity blend's start to the last pose."""
    env, adapter = _begun("dist-gprl")
    try:
        action = np.random.default_rng(1).uniform(-2, 2, env.action_space.shape)  # some clipped
        before = env.gamma.copy()
        delta = env.apply_action(0, action)
        indices = env.layout.indices[0]
        np.testing.assert_array_equal(delta, env.layout.delta(0, np.clip(action, -1, 1)))
        np.testing.assert_array_equal(env.gamma[indices], before[indices] + delta)
        untouched = np.setdiff1d(np.arange(len(before)), indices)
        np.testing.assert_array_equal(env.gamma[untouched], before[untouched])
        assert np.abs(delta).max() > 0

        adapter_before = adapter.gamma.copy()
        planned = adapter.adapt(action)
        np.testing.assert_array_equal(adapter.gamma - adapter_before, env.gamma - before)
        np.testing.assert_array_equal(planned, adapter.segment_poses(0))
        np.testing.assert_allclose(
            adapter.segment_times(0), adapter.segment_tau(0) * adapter.skill.duration
        )
        np.testing.assert_allclose(adapter.last_commanded[:3], env.sim.tcp_pose()[:3], atol=1e-3)
        adapter.executed(planned)
        np.testing.assert_array_equal(adapter.last_commanded, planned[-1])
        assert adapter.step_index == 1
    finally:
        adapter.close()
        env.close()


def test_the_demo_reference_ignores_the_action():
    """``demo`` (no trained policy) keeps the conditioned demonstration whatever action it is
    given, in the env and in the adapter alike (both go through `apply_action`)."""
    env, adapter = _begun("demo")
    try:
        action = np.ones(env.action_space.shape)
        before, adapter_before = env.gamma.copy(), adapter.gamma.copy()
        assert not np.any(env.apply_action(0, action))
        np.testing.assert_array_equal(env.gamma, before)
        np.testing.assert_array_equal(adapter.adapt(action), adapter.adapt(None))
        np.testing.assert_array_equal(adapter.gamma, adapter_before)
    finally:
        adapter.close()
        env.close()


def test_the_residual_adapter_is_built_for_the_requested_promp_method():
    """`perceived_env` builds the residual adapter with the method it is asked for:
    `promp-rrl-windowed` and `promp-rrl-expert` (the latter fits the 20 expert
    demonstrations) get windowed weights; environment v6's residual-control methods
    (`promp-rrl`, `promp-nominal`) residual RL at 10 Hz."""
    from distgprl.hardware.adapter import perceived_env

    windowed = perceived_env("promp-rrl-windowed")
    expert = perceived_env("promp-rrl-expert")
    nominal = perceived_env("promp-nominal")
    try:
        assert windowed.method.name == "promp-rrl-windowed"
        assert expert.method.name == "promp-rrl-expert"
        assert expert.promp.demonstration_count == 20
        assert isinstance(nominal, PerceivedResidualControl)
        assert nominal.method.name == "promp-nominal" and nominal.trial_steps == 50
        assert (windowed.decision_unit, nominal.decision_unit) == ("window", "RL step")
        # an image where each of the 3 windows starts (0, 1 2/3, 3 1/3 s of the 5 s trial)
        assert nominal.image_steps == (0, 17, 34)
        assert windowed.takes_image(1) and not nominal.takes_image(1)
    finally:
        windowed.close()
        expert.close()
        nominal.close()


def _perceive_truth(env, adapter) -> None:
    """Give the adapter's perceived world exactly what the training simulation holds now:
    both bars, the TCP pose, the joints, the time."""
    now = float(env.sim.time)
    adapter.world.tracks["target_bar"] = TrackedObject(
        _bar_transform(env.sim.object_position()), now
    )
    adapter.world.tracks["other_bar"] = TrackedObject(
        _bar_transform(env.sim.other_bar_position_at(now)), now
    )
    adapter.world.set_robot(env.sim.tcp_pose(), now, env.sim.joint_positions())


def test_residual_control_adapter_commands_what_the_training_env_commands():
    """With perfect perception, ProMP-RRL's trial adapter conditions the same nominal,
    observes the same state (the tool's clearance from the joints by forward kinematics) and
    commands, RL step by RL step, the same 2-3 control-period poses as `ResidualRLEnv`, to
    float tolerance (the same code on the same numbers: poses to 1e-12 m / rad, the float32
    observation to 1e-6)."""
    env = _training_env("promp-rrl")
    adapter = perceived_env("promp-rrl", env.config)
    try:
        assert isinstance(adapter, PerceivedResidualControl)
        obs, _ = env.reset(options={"tc": TC})
        _perceive_truth(env, adapter)
        tc = adapter.begin(env.sim.tcp_pose(), float(env.sim.time))
        np.testing.assert_allclose(tc.object_offset, TC.object_offset, rtol=0, atol=1e-12)
        np.testing.assert_allclose(adapter.nominal_poses, env.nominal_poses, rtol=0, atol=1e-12)
        np.testing.assert_allclose(adapter.observe()["state"], obs["state"], rtol=0, atol=1e-6)
        np.testing.assert_allclose(adapter.world.tool_points(), env.sim.tool_points(), atol=1e-9)
        rng = np.random.default_rng(2)
        for step in range(4):
            action = rng.uniform(-1, 1, 6)
            planned = adapter.adapt(action)
            expected = env.step_poses(step, env.step_residual(step, action))
            np.testing.assert_allclose(planned, expected, rtol=0, atol=1e-12)
            assert len(planned) in (2, 3)
            obs, *_ = env.step(action)
            adapter.executed(planned)
            assert adapter.step_index == step + 1
            np.testing.assert_allclose(adapter.last_commanded, planned[-1])
            _perceive_truth(env, adapter)
            state = adapter.observe()["state"]
            np.testing.assert_allclose(state, obs["state"], rtol=0, atol=1e-6)
    finally:
        adapter.close()
        env.close()


def test_residual_control_records_a_stopped_step_by_what_ran():
    """A step stopped after its first control period counts one instant as done (the
    nominal the next observation compares with), and its residual as the one in force."""
    env = _training_env("promp-nominal")
    adapter = perceived_env("promp-nominal", env.config)
    try:
        env.reset(options={"tc": TC})
        _perceive_truth(env, adapter)
        adapter.begin(env.sim.tcp_pose(), float(env.sim.time))
        planned = adapter.adapt(np.ones(6))  # the reference ignores the action: the nominal
        np.testing.assert_allclose(planned, adapter.nominal_poses[1 : len(planned) + 1])
        adapter.executed(planned[:1])
        np.testing.assert_array_equal(adapter.last_commanded, planned[0])
        assert adapter.step_index == 1
    finally:
        adapter.close()
        env.close()
