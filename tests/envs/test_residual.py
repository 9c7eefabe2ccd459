"""ProMP-RRL residual environment."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.envs.residual import (
    ResidualEnv,
    load_task_promp,
    one_demonstration_set,
    variance_gate,
)
from distgprl.sim.tasks import get_task
from distgprl.sim.tasks.base import condition_by_translation
from distgprl.skill.demos import load_demonstration


@pytest.fixture(scope="module")
def env():
    env = ResidualEnv("dcp")
    yield env
    env.close()


def test_zero_action_executes_the_nominal_trajectory(env):
    tc = env.spec_task.evaluation_tcs(2)[1]
    env.reset(options={"tc": tc})
    for step in range(3):
        segment = env.window_plan.segments[step]
        tau, lo, hi = segment.tau, segment.lo, segment.hi
        poses = env.segment_poses(step)
        # Only the first segment may blend out the robot-vs-ProMP start mismatch; past the
        # blend (and in every later segment) the nominal is executed exactly.
        past_blend = tau >= lo + env.config.blend_fraction * (hi - lo)
        np.testing.assert_allclose(poses[past_blend], env.nominal(tau[past_blend]), atol=1e-9)
        if step > 0:
            np.testing.assert_allclose(poses, env.nominal(tau), atol=1e-9)
        env.step(np.zeros(env.action_space.shape))


def test_nominal_starts_at_the_robot_and_engages_the_moved_object(env):
    """Object-centric: at the interaction time the nominal moves with the object offset."""
    tc_a, tc_b = env.spec_task.evaluation_tcs(2)
    interaction = np.array([env.spec_task.interaction_time])
    env.reset(options={"tc": tc_a})
    engage_a = env.nominal(interaction)[0, :2]
    np.testing.assert_allclose(
        env.nominal(np.zeros(1))[0, :3], env.window_plan.start_pose[:3], atol=2e-3
    )
    env.reset(options={"tc": tc_b})
    engage_b = env.nominal(interaction)[0, :2]
    shift = np.subtract(tc_b.object_offset, tc_a.object_offset)
    np.testing.assert_allclose(engage_b - engage_a, shift, atol=0.03)


def test_residual_action_changes_only_the_window_weights(env):
    env.reset(options={"tc": env.spec_task.nominal_tc})
    env.step(np.full(env.action_space.shape, 0.5))
    window = env.layout.indices[0]
    assert np.all(env.gamma[window] != 0)
    assert np.all(np.delete(env.gamma, window, axis=0) == 0)
    assert env.observation_space["state"].shape == (42,)


def test_promp_rrl_gets_only_the_one_demonstration_conditioned_on_training_tcs():
    """v5, equal information: every copy in ProMP-RRL's demonstration set is the shipped
    demonstration moved by its TC's object offset (the conditioning rule), nothing else."""
    spec = get_task("dcp")
    demo = load_demonstration(spec.demo_path)
    demos, offsets = one_demonstration_set("dcp")
    assert len(demos) == 20 and offsets.shape == (20, 3)
    assert np.ptp(offsets[:, :2], axis=0).min() > 0.1  # the TCs vary
    for (times, poses), offset in zip(demos, offsets, strict=True):
        np.testing.assert_array_equal(times, demo.times)
        expected = condition_by_translation(
            demo.times,
            demo.poses,
            offset[:2],
            spec.interaction_time,
            goal_fixed_in_world=spec.goal_fixed_in_world,
        )
        np.testing.assert_array_equal(poses, expected)


def test_one_demonstration_promp_varies_where_the_conditioning_weight_is_not_one():
    """In the object frame the conditioned copies coincide where the TC conditioning moves
    the skill whole with the object (weight 1) and differ elsewhere: on DBM (goal moves with
    the bar) everywhere after the interaction; on DCP (goal fixed, environment v6) only at
    the interaction, the push returning to the world-fixed goal after it. Before the
    interaction both differ (> 1 cm at the start). The variance gate follows: it lets the
    residual act fully where the copies coincide and not at the start."""
    for task, late_coincides in (("dbm", True), ("dcp", False)):
        promp = load_task_promp(task, "one")
        interaction = get_task(task).interaction_time
        late = np.linspace(interaction + 0.05, 1.0, 10)
        late_std = promp.trajectory_std(late)[:, :3].max()
        assert (late_std < 2e-3) == late_coincides, (task, late_std)
        assert promp.trajectory_std(np.zeros(1))[0, :2].min() > 0.01
        gate = variance_gate(promp, np.linspace(0.0, 1.0, 15))
        assert gate.min() == pytest.approx(0.0)
        assert np.all((gate >= 0.0) & (gate <= 1.0))
        at = variance_gate(promp, np.r_[np.linspace(0.0, 1.0, 15), interaction])[-1]
        assert at > 0.9, (task, at)


def test_residual_basis_is_normalised_so_the_total_range_is_the_gp_methods():
    """v5: the residual basis sums to the gate at every time (a partition of unity before
    gating), so saturating every weight by the action scale moves a pose by at most the
    scale — the GP methods' total range — never the ~2.5x of v4's unnormalised basis."""
    env = ResidualEnv("dcp")
    tau = np.linspace(0.0, 1.0, 200)
    basis = env.residual_basis(tau)
    gate = variance_gate(env.promp, env.skill.via_times)
    assert basis.min() >= 0.0 and basis.sum(axis=1).max() <= 1.0 + 1e-12
    ungated = basis / np.where(gate > 0, gate, 1.0)[None, :]
    full = gate > 0
    np.testing.assert_allclose(ungated[:, full].sum(axis=1)[tau > 0.9], 1.0, atol=1e-6)
    scale = env.layout.scale[0]
    weights = np.full((env.skill.n_via_points, 6), scale)
    assert np.abs(basis @ weights).max() <= scale + 1e-12
    env.close()


def test_expert_variant_and_nominal_reference():
    """``promp-rrl-expert`` fits the 20 shipped expert demonstrations; environment v6's
    ``promp-nominal`` reference is the residual-RL env's nominal (residual-control, not this
    windowed env, which refuses it)."""
    expert = ResidualEnv("dcp", method="promp-rrl-expert")
    assert expert.promp.demonstration_count == 20
    assert not np.allclose(expert.promp.weight_mean, load_task_promp("dcp", "one").weight_mean)
    expert.close()
    with pytest.raises(ValueError, match="not a residual method"):
        ResidualEnv("dcp", method="promp-nominal")
