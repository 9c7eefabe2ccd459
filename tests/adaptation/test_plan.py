"""The plan state of an episode (distgprl/adaptation/plan.py) on the GP skill's trajectory model
(distgprl/adaptation/trajectories.py), without a simulator."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from distgprl.adaptation.layout import build_action_layout
from distgprl.adaptation.plan import WindowPlan, min_jerk, segment_instants
from distgprl.adaptation.trajectories import GPSkillTrajectory
from distgprl.config_types import EnvConfig
from distgprl.methods import get_method
from distgprl.skill.gp import GPSkill
from distgprl.skill.kernels import KernelParams

# v5's operator and fixed scales: these tests check the plumbing, not the v6 reading
# (tests/adaptation/test_layout.py checks the Table I operator and the reach rule).
V5_OPERATOR = EnvConfig(covariance_scale="signal", action_scale_rule="fixed")

DT = 0.02


def skill() -> GPSkill:
    tau = np.linspace(0, 1, 15)
    via = np.column_stack([tau, 0.5 * tau, np.full(15, 0.3), np.zeros((15, 3))])
    return GPSkill(KernelParams(0.12), tau, via, via.mean(axis=0), 4.0, axis_scale=np.full(6, 0.3))


def make_plan(method: str = "dist-gprl") -> tuple[WindowPlan, GPSkill]:
    s = skill()
    spec = get_method(method)
    layout = build_action_layout(s, V5_OPERATOR, spec)
    model = GPSkillTrajectory(s, s.nearest_via_index(0.5))
    plan = WindowPlan(
        model, layout, s.duration, DT, 0.3, s.via_points[0, 3:], s.via_points, spec.trainable
    )
    return plan, s


TC = SimpleNamespace(object_offset=(0.05, -0.02))


def test_segments_tile_the_control_instants_once():
    """Every control instant of the trajectory belongs to exactly one segment, in order."""
    bounds = np.array([0.0, 0.3, 0.7, 1.0])
    parts = segment_instants(4.0, DT, bounds)
    joined = np.concatenate(parts)
    np.testing.assert_allclose(joined, np.arange(1, 201) * DT / 4.0)
    assert all(
        p.min() > lo and p.max() <= hi + 1e-12
        for p, lo, hi in zip(parts, bounds[:-1], bounds[1:], strict=True)
    )


def test_segment_poses_are_the_planned_trajectory_after_the_blend():
    """offset + map @ Gamma is the GP's position; the start mismatch is blended out over
    blend_fraction of the first segment only (min-jerk weight 1 at the start, 0 after)."""
    plan, s = make_plan()
    start = s.via_points[0] + np.array([0.01, 0, 0, 0, 0, 0])
    plan.start(TC, start, 2.0)
    assert plan.start_time == 2.0
    np.testing.assert_array_equal(plan.gamma[0], start)
    for step in range(plan.layout.n_steps):
        segment = plan.segments[step]
        poses = plan.segment_poses(step)
        planned = s.position(plan.gamma, segment.tau)
        past = segment.tau >= segment.lo + 0.3 * (segment.hi - segment.lo)
        np.testing.assert_allclose(poses[past], planned[past], atol=1e-9)
        plan.mark_commanded(step, poses)
        np.testing.assert_array_equal(plan.last_commanded, poses[-1])
    assert min_jerk(np.array([0.0]))[0] == 0.0


def test_apply_adds_the_layout_delta_to_the_window_only():
    """apply(step, a) clips a, adds S_W a to Gamma's window rows and returns it; the other
    rows do not move; a reference method (demo) leaves Gamma unchanged."""
    plan, s = make_plan()
    plan.start(TC, s.via_points[0], 0.0)
    before = plan.gamma.copy()
    action = np.random.default_rng(0).uniform(-2, 2, plan.layout.points_per_step * 6)
    delta = plan.apply(1, action)
    np.testing.assert_array_equal(delta, plan.layout.delta(1, np.clip(action, -1, 1)))
    window = plan.layout.indices[1]
    np.testing.assert_array_equal(plan.gamma[window], before[window] + delta)
    np.testing.assert_array_equal(np.delete(plan.gamma, window, 0), np.delete(before, window, 0))
    reference, _ = make_plan("demo")
    reference.start(TC, s.via_points[0], 0.0)
    held = reference.gamma.copy()
    assert not np.any(reference.apply(0, action))
    np.testing.assert_array_equal(reference.gamma, held)


def test_segment_poses_need_a_started_plan():
    plan, _ = make_plan()
    with pytest.raises(RuntimeError):
        plan.segment_poses(0)
