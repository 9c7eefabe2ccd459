"""The gates between a plan and the world: the paper's protocol lets a plan through with its
IK, the check refuses an unsafe one (force executes it), the repair retimes a too-fast one,
and each tracks the commanded joints at the end of what was executed."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_repair import DT, fast_plan  # tests/hardware is on sys.path (rootdir conftest)

from distgprl.envs.world import SegmentReport
from distgprl.limits import SafetyLimits
from distgprl.safety.edf import DistanceField
from distgprl.safety.shapes import Box
from distgprl.safety_layer.gates import CheckGate, RepairGate, UncheckedGate
from distgprl.safety_layer.plan_check import ik_chain
from distgprl.safety_layer.retime import RepairConfig


def _far_field():
    box = Box("far", np.array([5.0, 5.0, 5.0]), np.eye(3), np.full(3, 0.1), False)
    return DistanceField((box,)), (lambda time: (box,))


def test_the_papers_protocol_lets_the_plan_through_with_its_ik(model_sim):
    q0, _, poses = fast_plan(model_sim)
    gate = UncheckedGate(model_sim.robot, SafetyLimits(), DT, q0)
    reviewed = gate.review(0, poses)
    assert not reviewed.refused and reviewed.poses is poses
    assert np.array_equal(reviewed.joints, ik_chain(poses, q0, model_sim.robot)[0])
    gate.executed(reviewed, SegmentReport(3))
    assert np.array_equal(gate.q, reviewed.joints[2])
    assert np.allclose(gate.velocity, (reviewed.joints[2] - reviewed.joints[1]) / DT)


@pytest.mark.parametrize("force", [False, True])
def test_the_check_refuses_a_too_fast_plan_unless_forced(model_sim, force):
    q0, _, poses = fast_plan(model_sim)
    field, shapes = _far_field()
    gate = CheckGate(model_sim.robot, SafetyLimits(), DT, q0, field, shapes, lambda: 0.0, force)
    reviewed = gate.review(0, poses)
    assert reviewed.refused is not force
    assert "joint_speed" in gate.last.refused_limits and gate.last.decision == "refused"
    gate.executed(reviewed, SegmentReport(0))  # nothing executed: the joints stay
    assert np.array_equal(gate.q, q0) and not gate.velocity.any()


def test_the_repair_retimes_a_too_fast_plan(model_sim):
    q0, _, poses = fast_plan(model_sim)
    field, shapes = _far_field()
    no_via_points = SimpleNamespace(method=SimpleNamespace(action_mode="residual"))
    gate = RepairGate(
        no_via_points,
        model_sim.robot,
        SafetyLimits(),
        DT,
        q0,
        field,
        shapes,
        lambda: 0.0,
        lambda: None,
        RepairConfig(),
    )
    reviewed = gate.review(0, poses)
    assert not reviewed.refused and gate.last.decision == "retimed"
    assert len(reviewed.poses) > len(poses) and gate.last.time_added > 0.0
    assert np.allclose(reviewed.poses[-1], poses[-1], atol=1e-9)
