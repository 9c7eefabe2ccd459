"""Plan repair: retiming keeps the path within every limit, via-point pushes restore clearance,
and what cannot be saved is refused naming the limit."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.limits import SafetyLimits
from distgprl.safety.edf import DistanceField
from distgprl.safety.shapes import Box
from distgprl.safety_layer.plan_check import check_plan, tool_check_points
from distgprl.safety_layer.repair import ViaPoints, repair_plan
from distgprl.safety_layer.retime import RepairConfig, retime_plan
from distgprl.sim.transforms import matrix_to_pose, matrix_to_rotvec, rotvec_to_matrix

DT = 0.04


PUSH = RepairConfig(repair=True)
"""The via-point push is off by default (see `RepairConfig.repair`); these tests turn it on."""


def fast_plan(model_sim, steps=8, dy=0.06, wrist=0.9):
    """A straight 6 cm TCP line with a 0.9 rad wrist turn in 8 steps: above 2 rad/s."""
    q0 = model_sim.start_joint_positions
    start = matrix_to_pose(model_sim.robot.fk(q0))
    poses = np.tile(start, (steps, 1))
    poses[:, 1] += np.linspace(dy / steps, dy, steps)
    rotation = rotvec_to_matrix(start[3:])
    for i in range(steps):
        angle = wrist * (i + 1) / steps
        c, s = np.cos(angle), np.sin(angle)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        poses[i, 3:] = matrix_to_rotvec(rotation @ turn)
    return q0, start, poses


def kinematics(q0, joints, v_start=None):
    """(max joint speed rad/s, max joint acceleration rad/s^2) as the check measures them."""
    velocity = np.diff(np.vstack([q0, joints]), axis=0) / DT
    previous = np.zeros(6) if v_start is None else v_start
    acceleration = np.diff(np.vstack([previous, velocity]), axis=0) / DT
    return np.abs(velocity).max(), np.abs(acceleration).max()


@pytest.mark.parametrize("moving", [False, True])  # from rest, or already moving along it
def test_fast_plan_is_retimed_within_every_limit_on_its_path(model_sim, moving):
    robot, limits = model_sim.robot, SafetyLimits()
    q0, start, poses = fast_plan(model_sim)
    before = check_plan(poses, q0, robot, limits, DT, force=True)
    assert kinematics(q0, before.joints)[0] > 2.0
    assert {"joint_speed", "joint_acceleration"} <= {v.limit for v in before.violations}
    v_start = 0.4 * (before.joints[0] - q0) / DT if moving else None

    result = repair_plan(poses, q0, robot, limits, DT, v_start=v_start)
    assert result.decision == "retimed" and result.check.ok and not result.remaining
    speed, acceleration = kinematics(q0, result.check.joints, v_start)
    assert speed <= limits.max_joint_speed and acceleration <= limits.max_joint_acceleration
    tcp = np.vstack([start[:3], result.poses[:, :3]])
    assert np.linalg.norm(np.diff(tcp, axis=0), axis=1).max() / DT <= limits.max_tcp_speed
    # the same path: every retimed TCP position lies on the original line (x, z fixed,
    # y monotone between the start and the end), and the plan ends where it ended
    offset = result.poses[:, :3] - start[:3]
    assert np.abs(offset[:, [0, 2]]).max() <= 1e-6
    assert np.all(np.diff(offset[:, 1]) >= -1e-9) and offset[:, 1].min() >= -1e-6
    assert np.allclose(result.poses[-1], poses[-1], atol=1e-9)
    assert result.time_added == pytest.approx(DT * (len(result.poses) - len(poses)))
    assert result.time_added > 0.0 and np.all(result.shift_end == 0.0)


def test_retimed_plan_never_runs_faster_than_planned(model_sim):
    q0, _, poses = fast_plan(model_sim)
    retimed = retime_plan(poses, q0, model_sim.robot, SafetyLimits(), DT)
    assert retimed is not None
    # plan time advances by at most one control period per control period
    assert np.all(np.diff(np.concatenate([[0.0], retimed.parameter])) <= DT + 1e-9)


def test_retiming_on_a_belt_follows_the_belt(model_sim):
    """With a belt, pose k is shifted by v (t_k - s(t_k)): the path is kept in the belt frame."""
    q0, start, poses = fast_plan(model_sim)
    belt = np.array([0.0, 0.04, 0.0])
    result = repair_plan(poses, q0, model_sim.robot, SafetyLimits(), DT, belt_velocity=belt)
    assert result.decision == "retimed"
    times = DT * np.arange(1, len(result.poses) + 1)
    expected = result.path_poses[:, :3] + (times - result.path_parameter)[:, None] * belt
    assert np.allclose(result.poses[:, :3], expected, atol=1e-12)
    assert np.allclose(result.shift_end, belt * result.time_added)


def slow_line(model_sim, steps=20, dx=0.12):
    """A 12 cm TCP line along x in 20 steps (0.15 m/s), well within the limits."""
    q0 = model_sim.start_joint_positions
    start = matrix_to_pose(model_sim.robot.fk(q0))
    poses = np.tile(start, (steps, 1))
    poses[:, 0] += np.linspace(dx / steps, dx, steps)
    return q0, start, poses


def hat_via_points(poses, count=3):
    """The plan as a piecewise-linear blend of ``count`` via-points (hat functions)."""
    steps = len(poses)
    centres = np.linspace(0, steps - 1, count + 2)[1:-1]
    width = centres[1] - centres[0]
    weights = np.clip(1.0 - np.abs(np.arange(steps)[:, None] - centres) / width, 0.0, 1.0)

    def replan(displacement):
        out = poses.copy()
        out[:, :3] += weights @ displacement
        return out

    return ViaPoints(replan, count)


def grazing_box(model_sim, q0, poses, gap, half=(0.01, 0.06, 0.02)):
    """A box under the tool at the plan's middle, ``gap`` m below its lowest tool point."""
    robot = model_sim.robot
    joints = check_plan(poses, q0, robot, SafetyLimits(), DT, force=True).joints
    points = tool_check_points(robot, joints[len(poses) // 2])
    low = points[points[:, 2].argmin()]
    centre = np.array([low[0], low[1], low[2] - gap - half[2]])
    return Box("block", centre, np.eye(3), np.asarray(half, dtype=float))


def oracles(box):
    field = DistanceField([box])
    return (lambda p, s: field.clearance(p)), (lambda p, s: field.distance(p))


def test_grazing_plan_is_pushed_to_the_clearance_limit(model_sim):
    robot, limits = model_sim.robot, SafetyLimits()
    q0, _, poses = slow_line(model_sim)
    clearance, gradient = oracles(grazing_box(model_sim, q0, poses, gap=0.002))
    before = check_plan(poses, q0, robot, limits, DT, clearance, force=True)
    assert 0.0 < before.min_clearance < limits.min_clearance
    assert {v.limit for v in before.violations} == {"clearance"}

    via = hat_via_points(poses)
    result = repair_plan(poses, q0, robot, limits, DT, clearance, gradient, via, config=PUSH)
    assert result.decision in ("repaired", "refused")
    if result.decision == "repaired":
        assert result.check.ok and result.check.min_clearance >= limits.min_clearance
        assert 0.0 < result.max_displacement <= RepairConfig().max_displacement
        assert result.displacement[:, 2].max() > 0.0  # away from the box below: up
        again = check_plan(result.poses, q0, robot, limits, DT, clearance)  # does not raise
        assert again.min_clearance == pytest.approx(result.check.min_clearance)
    else:
        assert "clearance" in result.reason
    assert result.decision == "repaired"  # this plan is repairable: the field is one box
    assert repair_plan(poses, q0, robot, limits, DT, clearance, gradient, via).decision == (
        "refused"
    )  # by default (no push) the same plan is refused


def test_plan_the_repair_cannot_save_is_refused_with_its_reason(model_sim):
    robot, limits = model_sim.robot, SafetyLimits()
    q0, _, poses = slow_line(model_sim)
    # the tool is 10 cm deep in a block; the push may move a via-point 3 cm at most
    buried = grazing_box(model_sim, q0, poses, gap=-0.10, half=(0.2, 0.2, 0.1))
    clearance, gradient = oracles(buried)
    result = repair_plan(
        poses, q0, robot, limits, DT, clearance, gradient, hat_via_points(poses), config=PUSH
    )
    assert result.decision == "refused"
    assert result.refused_limits == ["clearance"] and "clearance" in result.reason
    assert result.remaining[0].value < limits.min_clearance
    assert np.array_equal(result.poses, poses)  # what --force would execute: the plan as given
    # a limit neither retiming nor a push can fix is refused at once, named
    narrow = SafetyLimits(workspace_upper=(0.3, 0.55, 0.7))
    refused = repair_plan(poses, q0, robot, narrow, DT)
    assert refused.decision == "refused" and refused.refused_limits == ["workspace"]


def test_safe_plan_is_left_alone(model_sim):
    robot, limits = model_sim.robot, SafetyLimits()
    q0, _, poses = slow_line(model_sim)
    result = repair_plan(poses, q0, robot, limits, DT, via_points=hat_via_points(poses))
    plain = check_plan(poses, q0, robot, limits, DT)
    assert result.decision == "none" and result.time_added == 0.0
    assert np.array_equal(result.poses, poses)
    assert np.array_equal(result.check.joints, plain.joints)
    assert result.max_displacement == 0.0


def test_no_retime_refuses_a_fast_plan_for_its_speed(model_sim):
    q0, _, poses = fast_plan(model_sim)
    result = repair_plan(
        poses, q0, model_sim.robot, SafetyLimits(), DT, config=RepairConfig(retime=False)
    )
    assert result.decision == "refused"
    assert result.refused_limits == ["joint_speed", "joint_acceleration"]
