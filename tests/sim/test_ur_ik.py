"""`distgprl.sim.ur_ik`: the compiled segment IK gives the bits of the per-pose path it
replaces (``pose_to_matrix``, NumPy's ``@`` with the tool offset, ``ur_analytic_ik``'s
``inverse_kinematics`` and `UR5e.ik_nearest`), on reachable, singular and unreachable poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
import ur_analytic_ik

from distgprl.sim.bullet import PhysicsConfig, make_client
from distgprl.sim.robot import HOOK, SHOVEL, UR5e
from distgprl.sim.transforms import matrix_to_pose, pose_to_matrix
from distgprl.sim.ur_ik import UR5E_DH, ik_branches, pose_matrices, segment_ik


def _library(target: np.ndarray) -> np.ndarray:
    return np.array(ur_analytic_ik.ur5e.inverse_kinematics(target)).reshape(-1, 6)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _poses(rng: np.random.Generator, count: int) -> np.ndarray:
    """TCP-like poses: FK of random joints (with wrist, elbow and shoulder singularities, the
    identity rotation and a rotation under the 1e-12 cutoff) and random boxes of space (most
    unreachable, some with 2 or 6 branches)."""
    poses = []
    for k in range(count):
        if k % 2:
            poses.append(np.concatenate([rng.uniform(-1.1, 1.1, 3), rng.uniform(-4, 4, 3)]))
            continue
        q = rng.uniform(-math.pi, math.pi, 6)
        if k % 10 == 2:
            q[4] = 0.0  # wrist singularity: theta5 = 0, theta6 undetermined
        if k % 10 == 4:
            q[2] = 0.0  # elbow stretched
        if k % 10 == 6:
            q[4] = math.pi
        pose = matrix_to_pose(np.asarray(ur_analytic_ik.ur5e.forward_kinematics(*q)))
        if k % 14 == 0:
            pose[3:] = 0.0
        if k % 22 == 0:
            pose[3:] = (0.0, 0.0, 1e-13)
        poses.append(pose)
    return np.array(poses)


def test_branches_and_transforms_are_the_librarys_bit_for_bit():
    """On 6 000 poses, `pose_matrices` equals ``pose_to_matrix`` and `ik_branches` equals
    ``ur_analytic_ik.ur5e.inverse_kinematics`` (count, order and every bit, signed zeros
    included); every branch count the library gives (0, 2, 4, 6, 8) occurs."""
    rng = np.random.default_rng(3)
    poses = _poses(rng, 6000)
    matrices = pose_matrices(poses)
    out = np.empty((8, 6))
    counts = set()
    for pose, matrix in zip(poses, matrices, strict=True):
        expected = pose_to_matrix(pose)
        assert _same_bits(matrix, expected), pose
        count = ik_branches(expected, UR5E_DH, out)
        assert _same_bits(out[:count].copy(), _library(expected)), pose
        counts.add(count)
    assert {0, 2, 4, 6, 8} <= counts


def test_stacked_matmul_has_the_single_products_bits():
    """`segment_ik` applies the tool offset with one stacked ``np.matmul``: each product has
    the bits of the per-pose ``transform @ offset`` (the same BLAS call per matrix)."""
    rng = np.random.default_rng(4)
    client = make_client(PhysicsConfig())
    try:
        offset = UR5e(client, SHOVEL)._tcp_from_tool0
    finally:
        client.disconnect()
    matrices = pose_matrices(_poses(rng, 500))
    stacked = np.matmul(matrices, offset)
    for matrix, product in zip(matrices, stacked, strict=True):
        assert _same_bits(product, matrix @ offset)


@pytest.fixture(scope="module", params=[SHOVEL, HOOK], ids=["shovel", "hook"])
def robot(request):
    client = make_client(PhysicsConfig())
    yield UR5e(client, request.param)
    client.disconnect()


def _sequential(robot: UR5e, poses: np.ndarray, start: np.ndarray):
    """The control loop's old per-period IK: `ik_nearest` from the previous target."""
    previous, joints, reached = start.tolist(), [], []
    for pose in poses:
        solution = robot.ik_nearest(pose_to_matrix(pose), previous)
        reached.append(solution is not None)
        if solution is not None:
            previous = solution.tolist()
        joints.append(previous)
    return np.array(joints), np.array(reached)


def test_segment_ik_gives_the_per_pose_targets_bit_for_bit(robot):
    """`UR5e.ik_segment` returns the targets the control loop computed pose by pose with
    `UR5e.ik_nearest` (reference: the previous target, held where a pose is unreachable),
    bit for bit, from any starting hint: on smooth segments through reachable space (the
    control loop's case, wrap-around of wrist 3 included), on segments with unreachable
    poses in the middle, and on random jumps between branches."""
    rng = np.random.default_rng(5)
    checked = unreachable = 0
    for case in range(120):
        q0 = rng.uniform(-math.pi, math.pi, 6)
        q1 = q0 + rng.uniform(-1.5, 1.5, 6)
        q1[5] += 2 * math.pi * (case % 3 == 0)
        steps = np.linspace(0.0, 1.0, int(rng.integers(1, 40)))[:, None]
        poses = np.array([matrix_to_pose(robot.fk(q)) for q in q0 + steps * (q1 - q0)], dtype=float)
        if case % 4 == 1:  # unreachable poses inside the segment
            poses[rng.uniform(size=len(poses)) < 0.3, :3] = (2.0, 0.0, 0.5)
        if case % 4 == 2:  # random jumps
            poses = _poses(rng, len(poses))
        start = q0 + rng.normal(0.0, 0.3, 6)
        expected_joints, expected_reached = _sequential(robot, poses, start)
        for hint in (0, int(rng.integers(8)), 7):
            robot._last_branch = hint
            joints, reached = robot.ik_segment(poses, start)
            assert _same_bits(joints, expected_joints), (case, hint)
            assert reached.tolist() == expected_reached.tolist()
        checked += len(poses)
        unreachable += int((~expected_reached).sum())
    assert checked > 1000 and unreachable > 50


def test_empty_segment():
    """No poses: no targets, the hint unchanged."""
    joints, reached, hint = segment_ik(
        np.zeros((0, 6)), np.eye(4), np.zeros(6), -np.full(6, 6.3), np.full(6, 6.3), hint=3
    )
    assert joints.shape == (0, 6) and reached.shape == (0,) and hint == 3
