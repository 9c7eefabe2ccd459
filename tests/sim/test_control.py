"""The control loop (`distgprl.sim.control.ControlLoop`): clock, joint targets and results."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.sim.tasks.base import TaskConfig
from distgprl.sim.transforms import pose_to_matrix


def test_run_advances_the_clock_and_keeps_the_last_ik_target(dcp_sim):
    """Executing n reachable poses advances the world's clock by n control periods, leaves
    the last pose's IK solution (nearest the previous target) as ``q_command`` and reports
    n steps without IK failures; zero poses change nothing."""
    dcp_sim.reset(TaskConfig())
    start = dcp_sim.tcp_pose()
    poses = np.tile(start, (5, 1))
    poses[:, 2] += np.linspace(0.002, 0.01, 5)  # rise 1 cm
    q_before = dcp_sim.q_command.copy()
    result = dcp_sim.control.run(dcp_sim, poses)
    assert result.steps == 5 and result.ik_failures == 0 and not result.stopped
    assert dcp_sim.time == pytest.approx(5 * dcp_sim.control_dt)
    expected = q_before
    for pose in poses:
        expected = dcp_sim.robot.ik_nearest(pose_to_matrix(pose), expected)
    assert np.array_equal(dcp_sim.q_command, expected)
    time, q = dcp_sim.time, dcp_sim.q_command.copy()
    empty = dcp_sim.control.run(dcp_sim, np.zeros((0, 6)))
    assert empty.steps == 0 and dcp_sim.time == time
    assert np.array_equal(dcp_sim.q_command, q)


def test_run_rejects_malformed_poses(dcp_sim):
    """Poses must be a finite (n, 6) array."""
    with pytest.raises(UserInputError):
        dcp_sim.control.run(dcp_sim, np.zeros((3, 5)))
    with pytest.raises(UserInputError):
        dcp_sim.control.run(dcp_sim, np.full((2, 6), np.nan))


def test_clearance_is_the_minimum_over_obstacles_capped_at_the_cutoff(dcp_sim):
    """`ControlLoop.clearance` equals the smallest closest-point distance to any obstacle
    body, capped at the cutoff (checked against direct PyBullet queries)."""
    dcp_sim.reset(TaskConfig())
    cutoff = dcp_sim.clearance_cutoff
    direct = [
        point[8]
        for body in dcp_sim.obstacle_bodies
        for point in dcp_sim.client.getClosestPoints(
            bodyA=dcp_sim.robot.body, bodyB=body, distance=cutoff
        )
    ]
    assert dcp_sim.control.clearance() == min([cutoff, *direct])


def test_clearance_below_caps_the_minimum_and_changes_nothing_else(dcp_sim):
    """``clearance_below`` (the caller's minimum so far) gives min(below, the segment's
    minimum) and the same segment otherwise (the queries only look no farther); it must be
    positive."""
    spec_poses = None
    results = {}
    for below in (None, 0.06, 1e-4):
        dcp_sim.reset(TaskConfig())
        start = dcp_sim.tcp_pose()
        spec_poses = np.tile(start, (30, 1))
        spec_poses[:, 2] -= np.linspace(0.0, 0.25, 30)  # down towards the table
        results[below] = dcp_sim.control.run(dcp_sim, spec_poses, clearance_below=below)
    plain = results[None]
    for below in (0.06, 1e-4):
        result = results[below]
        assert result.min_clearance == min(below, plain.min_clearance)
        assert (result.collision, result.steps, result.peak_joint_speed) == (
            plain.collision,
            plain.steps,
            plain.peak_joint_speed,
        )
    assert 1e-4 < plain.min_clearance < 0.06  # the run comes between the two caps
    with pytest.raises(ValueError):
        dcp_sim.control.run(dcp_sim, spec_poses, clearance_below=0.0)
