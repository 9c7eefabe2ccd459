"""The trial adapter observes and plans exactly as the environment the policy trained in:
the same environment class, its world the perceived scene (`TrialAdapter`)."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.envs.episode import commit_segment
from distgprl.envs.residual_control_env import ResidualRLEnv
from distgprl.envs.via_point_env import AdaptationEnv
from distgprl.envs.windowed_residual_env import ResidualEnv
from distgprl.hardware.adapter import (
    PerceivedScene,
    TrackedObject,
    adapt,
    begin_trial,
    observe,
    perceived_env,
)
from distgprl.sim.tasks.base import TaskConfig

TC = TaskConfig(object_offset=(0.0, 0.07), obstacle_offset=(0.0, -0.12))


def _training_env(method: str):
    from distgprl.experiments.factories import make_env
    from distgprl.identity import resolve_run

    return make_env(resolve_run("dbm", method, 0, preset="ci"))


def _bar_transform(position: np.ndarray) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, 3] = position
    return transform


@pytest.mark.parametrize(
    ("method", "kind"),
    [
        ("dist-gprl", AdaptationEnv),
        ("promp-rrl-windowed", ResidualEnv),
        ("demo", AdaptationEnv),
    ],
)
def test_perceived_adapter_matches_the_training_env(method, kind):
    env = _training_env(method)
    adapter = perceived_env(method, env.config)
    try:
        # the training env's own class, whose world (what the observation reads) is perceived
        assert type(adapter.env) is type(env) is kind
        assert adapter.env.world is adapter.world and isinstance(adapter.world, PerceivedScene)
        obs, _ = env.reset(options={"tc": TC})
        # The adapter perceives exactly what the simulation holds at the episode start.
        now = float(env.sim.time)
        adapter.world.tracks["target_bar"] = TrackedObject(
            _bar_transform(env.sim.object_position()), now
        )
        adapter.world.tracks["other_bar"] = TrackedObject(
            _bar_transform(env.sim.other_bar_position_at(now)), now
        )
        tc = begin_trial(adapter, env.sim.tcp_pose(), now)
        trial = adapter.env
        np.testing.assert_allclose(tc.object_offset, TC.object_offset, atol=1e-3)
        np.testing.assert_allclose(tc.obstacle_offset, TC.obstacle_offset, atol=1e-3)
        np.testing.assert_allclose(trial.gamma, env.gamma, atol=1e-3)
        # the nominal under the adapted parameters (conditioned demo / ProMP mean)
        np.testing.assert_allclose(
            trial.plan(trial.segment_tau(0)), env.plan(env.segment_tau(0)), atol=1e-3
        )
        np.testing.assert_allclose(observe(adapter)["state"], obs["state"], atol=1e-2)

        action = np.random.default_rng(0).uniform(-1, 1, env.action_space.shape)
        planned = adapt(adapter, action)
        env.step(action)
        # The executed segment of the training env: same plan from the same parameters.
        np.testing.assert_allclose(trial.gamma, env.gamma, atol=1e-3)
        assert planned.shape[1] == 6 and len(planned) == len(trial.segment_tau(0))
        commit_segment(trial, trial.step_index, planned)
        assert trial.step_index == 1
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
    begin_trial(adapter, env.sim.tcp_pose(), now)
    return env, adapter


def test_apply_action_is_the_one_window_update():
    """`AdaptationEnv.apply_action` clips, maps through the layout (S_W per axis) and adds
    Delta Gamma to the step's via-points only; the adapter's `adapt` is exactly that plus the
    segment's poses, and committing them moves the continuity blend's start to the last
    pose."""
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

        trial = adapter.env
        adapter_before = trial.gamma.copy()
        planned = adapt(adapter, action)
        np.testing.assert_array_equal(trial.gamma - adapter_before, env.gamma - before)
        np.testing.assert_array_equal(planned, trial.segment_poses(0))
        np.testing.assert_allclose(trial.last_commanded[:3], env.sim.tcp_pose()[:3], atol=1e-3)
        commit_segment(trial, trial.step_index, planned)
        np.testing.assert_array_equal(trial.last_commanded, planned[-1])
        assert trial.step_index == 1
    finally:
        adapter.close()
        env.close()


def test_the_demo_reference_ignores_the_action():
    """``demo`` (no trained policy) keeps the conditioned demonstration whatever action it is
    given, in the env and in the adapter alike (both go through `apply_action`)."""
    env, adapter = _begun("demo")
    try:
        action = np.ones(env.action_space.shape)
        before, adapter_before = env.gamma.copy(), adapter.env.gamma.copy()
        assert not np.any(env.apply_action(0, action))
        np.testing.assert_array_equal(env.gamma, before)
        np.testing.assert_array_equal(adapt(adapter, action), adapt(adapter, None))
        np.testing.assert_array_equal(adapter.env.gamma, adapter_before)
    finally:
        adapter.close()
        env.close()


def test_the_residual_adapter_is_built_for_the_requested_promp_method():
    """`perceived_env` builds the residual adapter with the method it is asked for:
    `promp-rrl-windowed` and `promp-rrl-expert` (the latter fits the 20 expert
    demonstrations) get windowed weights; environment v6's residual-control methods
    (`promp-rrl`, `promp-nominal`) residual RL at 10 Hz."""
    windowed = perceived_env("promp-rrl-windowed")
    expert = perceived_env("promp-rrl-expert")
    nominal = perceived_env("promp-nominal")
    try:
        assert windowed.env.method.name == "promp-rrl-windowed"
        assert isinstance(windowed.env, ResidualEnv) and windowed.trial_steps == 3
        assert expert.env.method.name == "promp-rrl-expert"
        assert expert.env.promp.demonstration_count == 20
        assert isinstance(nominal.env, ResidualRLEnv)
        assert nominal.env.method.name == "promp-nominal" and nominal.trial_steps == 50
        assert (windowed.decision_unit, nominal.decision_unit) == ("window", "RL step")
        assert (windowed.streams_decisions, nominal.streams_decisions) == (False, True)
        # an image where each of the 3 windows starts (0, 1 2/3, 3 1/3 s of the 5 s trial)
        assert nominal.image_steps == (0, 17, 34)
        assert 1 in windowed.image_steps and 1 not in nominal.image_steps
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
        assert type(adapter.env) is type(env) is ResidualRLEnv
        trial = adapter.env
        obs, _ = env.reset(options={"tc": TC})
        _perceive_truth(env, adapter)
        tc = begin_trial(adapter, env.sim.tcp_pose(), float(env.sim.time))
        np.testing.assert_allclose(tc.object_offset, TC.object_offset, rtol=0, atol=1e-12)
        np.testing.assert_allclose(trial.nominal_poses, env.nominal_poses, rtol=0, atol=1e-12)
        np.testing.assert_allclose(observe(adapter)["state"], obs["state"], rtol=0, atol=1e-6)
        np.testing.assert_allclose(adapter.world.tool_points(), env.sim.tool_points(), atol=1e-9)
        rng = np.random.default_rng(2)
        for step in range(4):
            action = rng.uniform(-1, 1, 6)
            planned = adapt(adapter, action)
            expected = env.step_poses(step, env.step_residual(step, action))
            np.testing.assert_allclose(planned, expected, rtol=0, atol=1e-12)
            assert len(planned) in (2, 3)
            obs, *_ = env.step(action)
            commit_segment(trial, step, planned)
            assert trial.step_index == step + 1
            np.testing.assert_allclose(trial.last_commanded, planned[-1])
            _perceive_truth(env, adapter)
            state = observe(adapter)["state"]
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
        begin_trial(adapter, env.sim.tcp_pose(), float(env.sim.time))
        trial = adapter.env
        planned = adapt(adapter, np.ones(6))  # the reference ignores the action: the nominal
        np.testing.assert_allclose(planned, trial.nominal_poses[1 : len(planned) + 1])
        commit_segment(trial, 0, planned[:1])
        np.testing.assert_array_equal(trial.last_commanded, planned[0])
        assert trial.step_index == 1
    finally:
        adapter.close()
        env.close()
