"""Kinematic collision check used by HAP: static obstacles only, moving ones on request."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.sim.tasks import get_task
from distgprl.sim.transforms import pose_to_matrix


@pytest.fixture(scope="module")
def dcp_sim():
    sim = get_task("dcp").make_sim()
    yield sim
    sim.close()


def configuration_at(sim, position):
    """Joint configuration putting the TCP at ``position`` with the start orientation."""
    pose = sim.tcp_pose()
    pose[:3] = position
    q = sim.robot.ik_nearest(pose_to_matrix(pose), sim.start_joint_positions)
    assert q is not None
    return q


def test_start_configuration_is_free_and_a_tool_in_the_table_is_not(dcp_sim):
    dcp_sim.reset(get_task("dcp").nominal_tc)
    start = dcp_sim.start_joint_positions
    assert not dcp_sim.configuration_in_collision(start)
    table_top = max(
        s.position[2] + s.half_extents[2] for s in dcp_sim.obstacle_shapes() if s.name == "table"
    )
    below = dcp_sim.tcp_pose()[:3].copy()
    below[2] = table_top - 0.03
    assert dcp_sim.configuration_in_collision(configuration_at(dcp_sim, below))


def test_margin_makes_the_check_conservative(dcp_sim):
    dcp_sim.reset(get_task("dcp").nominal_tc)
    table_top = max(
        s.position[2] + s.half_extents[2] for s in dcp_sim.obstacle_shapes() if s.name == "table"
    )
    hovering = dcp_sim.tcp_pose()[:3].copy()
    hovering[2] = table_top + 0.04
    q = configuration_at(dcp_sim, hovering)
    clearance_free = not dcp_sim.configuration_in_collision(q, margin=0.0)
    assert clearance_free
    assert dcp_sim.configuration_in_collision(q, margin=0.2)


def test_moving_obstacle_is_ignored_unless_requested(dcp_sim):
    dcp_sim.reset(get_task("dcp").nominal_tc)
    obstacle = next(s for s in dcp_sim.obstacle_shapes() if s.dynamic)
    inside = np.asarray(obstacle.position, dtype=float).copy()
    q = configuration_at(dcp_sim, inside + [0.0, 0.0, 0.02])
    in_static = dcp_sim.configuration_in_collision(q)
    in_any = dcp_sim.configuration_in_collision(q, include_dynamic=True)
    assert in_any and not in_static


def test_registry_and_lightweight_task_names_agree():
    """`distgprl.data.TASK_NAMES` (used without importing pybullet) lists exactly the tasks."""
    from distgprl.data import TASK_NAMES
    from distgprl.sim.tasks import TASKS

    assert tuple(TASKS) == TASK_NAMES
