"""UR5e kinematics: the PyBullet model, the analytic FK and IK agree with the official DH model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from distgprl.sim.bullet import PhysicsConfig, make_client
from distgprl.sim.robot import HOOK, SHOVEL, UR5e

# official UR5e DH parameters (Universal Robots)
D = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
A = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)


def dh_forward(q: np.ndarray) -> np.ndarray:
    """Flange pose from the standard DH convention, written out independently of the code."""
    transform = np.eye(4)
    for theta, d, a, alpha in zip(q, D, A, ALPHA, strict=True):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        transform = transform @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0, sa, ca, d],
                [0, 0, 0, 1],
            ]
        )
    return transform


@pytest.fixture(scope="module", params=[SHOVEL, HOOK], ids=["shovel", "hook"])
def robot(request):
    client = make_client(PhysicsConfig())
    yield UR5e(client, request.param)
    client.disconnect()


def test_pybullet_model_matches_official_dh(robot):
    """The URDF's flange frame in PyBullet equals the DH flange pose on random q (< 0.1 mm)."""
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, 6)
        robot.reset_joints(q)
        simulated = robot.link_transform(robot.link_index["tool0"])
        expected = dh_forward(q)
        assert np.allclose(simulated[:3, 3], expected[:3, 3], atol=1e-4)
        assert np.allclose(simulated[:3, :3], expected[:3, :3], atol=1e-4)
        assert np.allclose(robot.fk_tool0(q), expected, atol=1e-9)


def test_tcp_link_matches_fk(robot):
    """The simulated TCP link is where fk() puts it: flange pose times the tool's TCP offset."""
    rng = np.random.default_rng(1)
    for _ in range(10):
        q = rng.uniform(-math.pi, math.pi, 6)
        robot.reset_joints(q)
        assert np.allclose(robot.tcp_transform(), robot.fk(q), atol=1e-4)


def test_joint_limits_are_the_real_ones(robot):
    """Limits come from the URDF: +-2 pi except the elbow (+-pi); efforts 150/28 N m."""
    assert np.allclose(robot.upper_limits, [2 * math.pi] * 2 + [math.pi] + [2 * math.pi] * 3)
    assert np.allclose(robot.lower_limits, -robot.upper_limits)
    assert np.allclose(robot.max_forces, [150, 150, 150, 28, 28, 28])


def test_ik_fk_round_trip(robot):
    """Every IK branch reproduces the target to 1e-6, and the nearest branch recovers q."""
    rng = np.random.default_rng(2)
    checked = 0
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, 6)
        q[2] = rng.uniform(-2.8, 2.8)
        q[4] = rng.uniform(0.3, 2.8) * rng.choice([-1, 1])  # away from the wrist singularity
        target = robot.fk(q)
        branches = robot.ik_all(target)
        assert 1 <= branches.shape[0] <= 8
        for branch in branches:
            assert np.abs(robot.fk(branch) - target).max() < 1e-6
        nearest = robot.ik_nearest(target, q)
        assert nearest is not None
        assert np.abs(nearest - q).max() < 1e-6
        checked += 1
    assert checked == 50


def test_ik_nearest_wraps_around(robot):
    """Joints are shifted by 2 pi towards the reference when the limits allow it."""
    q = np.array([2.0, -1.6, 1.5, -1.4, -1.57, 3.0])
    reference = q.copy()
    reference[0] = q[0] - 2 * math.pi  # -4.28: the equivalent angle is inside the limits
    reference[5] = q[5] - 2 * math.pi  # -3.28: likewise
    solution = robot.ik_nearest(robot.fk(q), reference)
    assert solution is not None
    assert np.allclose(solution, reference, atol=1e-6)
    # a reference beyond the limit (+9.28 rad) cannot be matched: the solution stays in limits
    reference[5] = q[5] + 2 * math.pi
    solution = robot.ik_nearest(robot.fk(q), reference)
    assert solution is not None
    assert np.all(solution <= robot.upper_limits) and np.all(solution >= robot.lower_limits)
    assert np.abs(robot.fk(solution) - robot.fk(q)).max() < 1e-6


def test_unreachable_pose_has_no_solution(robot):
    """A TCP 3 m away has no IK solution."""
    target = np.eye(4)
    target[:3, 3] = [3.0, 0.0, 0.5]
    assert robot.ik_all(target).shape == (0, 6)
    assert robot.ik_nearest(target, np.zeros(6)) is None


def test_tool_points_lie_on_the_tool(robot):
    """About 50 tool points, all on the surface of one of the tool's boxes."""
    points = robot.tool_points_local
    assert 40 <= points.shape[0] <= 60
    on_surface = np.zeros(points.shape[0], dtype=bool)
    for box in robot.tool.boxes:
        local = np.abs(points - np.asarray(box.position)) - np.asarray(box.half_extents)
        inside = np.all(local <= 1e-9, axis=1)
        on_face = np.any(np.abs(local) <= 1e-9, axis=1)
        on_surface |= inside & on_face
    assert on_surface.all()
    robot.reset_joints(np.array([2.2, -1.75, 1.6, -1.42, -1.57, -2.51]))
    world = robot.tool_points()
    flange = robot.link_transform(robot.link_index["tool0"])
    assert np.allclose(world, points @ flange[:3, :3].T + flange[:3, 3], atol=1e-6)


def test_ik_nearest_returns_the_scalar_rules_branch_bit_for_bit(robot):
    """`UR5e.ik_nearest` (and `nearest_branch` from every starting hint) returns exactly the
    joint vector of the scalar rule `nearest_branch_exact` (the implementation the committed
    runs were made with), or None where it gives None: on random reachable poses with random
    references (wrap-around, branches outside the limits), and on references placed midway
    between two branches (near-ties, where the first of equals must win)."""
    import ur_analytic_ik

    from distgprl.sim.ik_branches import nearest_branch, nearest_branch_exact
    from distgprl.sim.transforms import invert_transform

    rng = np.random.default_rng(7)
    limits = tuple(zip(robot.lower_limits.tolist(), robot.upper_limits.tolist(), strict=True))
    tcp_from_tool0 = invert_transform(robot.tool.tool0_from_tcp)  # as UR5e computes it
    cases = 0
    for _ in range(400):
        q = rng.uniform(-math.pi, math.pi, 6)
        tcp = robot.fk(q)
        reference = rng.uniform(-2 * math.pi, 2 * math.pi, 6)
        solutions = ur_analytic_ik.ur5e.inverse_kinematics(robot.fk_tool0(q))
        if rng.uniform() < 0.25 and len(solutions) >= 2:  # a tie: midway between two branches
            reference = 0.5 * (solutions[0] + solutions[1])
        branches = ur_analytic_ik.ur5e.inverse_kinematics(tcp @ tcp_from_tool0)
        expected = nearest_branch_exact(branches, reference.tolist(), limits)
        for hint in range(len(branches) + 1):
            chosen = nearest_branch(
                np.array(branches).reshape(-1, 6),
                reference,
                robot.lower_limits,
                robot.upper_limits,
                hint,
            )[0]
            if expected is None:
                assert chosen is None
            else:  # the same floats, signed zeros included
                assert chosen.tolist() == expected
                assert np.array_equal(np.signbit(chosen), np.signbit(expected))
        found = robot.ik_nearest(tcp, reference)
        if expected is None:
            assert found is None
            continue
        cases += 1
        assert found is not None and found.dtype == np.float64
        assert np.array_equal(found, np.array(expected)), (q, reference)
        assert [math.copysign(1.0, v) for v in found] == [math.copysign(1.0, v) for v in expected]
    assert cases > 300


def test_tool_points_are_v7s_bit_for_bit(robot):
    """`tool_points` reads the tool link's rotation and translation without the (4, 4)
    transform around them (issue 66): the same product and sum as v7's ``tool @ R^T + t``
    with R, t sliced from `link_transform`, so the same bits (tolerance zero), at random
    configurations."""
    rng = np.random.default_rng(66)
    for q in rng.uniform(robot.lower_limits / 2, robot.upper_limits / 2, (20, 6)):
        robot.reset_joints(q)
        tool = robot.link_transform(robot.tool_link)
        v7 = robot.tool_points_local @ tool[:3, :3].T + tool[:3, 3]
        assert np.array_equal(robot.tool_points(), v7)
