"""The UR analytic IK of a whole segment of poses in one compiled pass (issue 49).

``ur_analytic_ik`` (C++, one pose per call) solves the UR's closed-form IK (up to eight
branches) and keeps the finite, distinct branches whose forward kinematics reach the pose. The
control loop asked it once per control period, interleaved with the physics; but a segment's
poses are known before it executes, and each pose's joint target depends only on the poses
and the previous target (never on the physics). `segment_ik` therefore solves every pose of
a segment in one numba-compiled loop: the pose's transform (`distgprl.sim.transforms.
pose_to_matrix`'s Rodrigues formula), the library's algorithm, and the nearest-branch choice
(`distgprl.sim.ik_branches`), still sequential, each pose's reference the previous target.

Same bits: the kernels perform the library's IEEE operations in its order (version
0.1.0.post3's ``inverse_kinematics.hh``; its wheel calls glibc's ``sin``, ``cos``,
``sincos``, ``atan2``, ``sqrt``, ``fmod`` and has no fused multiply-add; numba calls the same
libm and does not contract without ``fastmath``), and the tool offset is NumPy's ``matmul``,
as before. ``tests/sim/test_ur_ik.py`` checks the branches
against the library and the segment's targets against ``UR5e.ik_nearest`` bit for bit. The
library's forward-kinematics check (a branch is dropped if an element of its pose is off by
more than 1e-9) is recomputed with plain sums: it could decide differently only for a branch
within rounding of that tolerance (none seen in the tests).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from distgprl.sim.ik_branches import nearest_branch_index

__all__ = ["UR5E_DH", "ik_branches", "pose_matrices", "segment_ik"]

UR5E_DH = np.array([0.1625, 0.1333, 0.0997, 0.0996, -0.425, -0.3922])
"""UR5e DH parameters d1, d4, d5, d6, a2, a3 (m), as ``ur_analytic_ik`` has them."""

_PI = math.pi
_TWO_PI = 2.0 * math.pi
_HALF_PI = math.pi / 2.0


@njit(cache=True, nogil=True, error_model="numpy")
def pose_matrices(poses):  # pragma: no cover - compiled
    """Transforms (n, 4, 4) of poses (n, 6) (x, y, z in m, rotation vector in rad): the
    operations of `distgprl.sim.transforms.pose_to_matrix`, in its order."""
    out = np.zeros((poses.shape[0], 4, 4))
    for k in range(poses.shape[0]):
        rx, ry, rz = poses[k, 3], poses[k, 4], poses[k, 5]
        angle = math.sqrt(rx * rx + ry * ry + rz * rz)
        m = out[k]
        if angle < 1e-12:
            m[0, 0] = 1.0
            m[1, 1] = 1.0
            m[2, 2] = 1.0
        else:
            kx, ky, kz = rx / angle, ry / angle, rz / angle
            c, s = math.cos(angle), math.sin(angle)
            v = 1.0 - c
            m[0, 0] = c + kx * kx * v
            m[0, 1] = kx * ky * v - kz * s
            m[0, 2] = kx * kz * v + ky * s
            m[1, 0] = ky * kx * v + kz * s
            m[1, 1] = c + ky * ky * v
            m[1, 2] = ky * kz * v - kx * s
            m[2, 0] = kz * kx * v - ky * s
            m[2, 1] = kz * ky * v + kx * s
            m[2, 2] = c + kz * kz * v
        m[0, 3] = poses[k, 0]
        m[1, 3] = poses[k, 1]
        m[2, 3] = poses[k, 2]
        m[3, 3] = 1.0
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _theta6(sign5, c1, s1, r11, r12, r21, r22):  # pragma: no cover - compiled
    h1 = (c1 * r22) - (s1 * r12)
    h2 = (s1 * r11) - (c1 * r21)
    if abs(h1) < 1e-12:
        h1 = 0.0
    if abs(h2) < 1e-12:
        h2 = 0.0
    return math.atan2(sign5 * h1, sign5 * h2)


@njit(cache=True, nogil=True, error_model="numpy")
def _dh(theta, d, a, alpha, out):  # pragma: no cover - compiled
    """The DH matrix (4, 4) of one joint into ``out``."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    out[0, 0], out[0, 1], out[0, 2], out[0, 3] = ct, -st * ca, st * sa, a * ct
    out[1, 0], out[1, 1], out[1, 2], out[1, 3] = st, ct * ca, -ct * sa, a * st
    out[2, 0], out[2, 1], out[2, 2], out[2, 3] = 0.0, sa, ca, d
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = 0.0, 0.0, 0.0, 1.0


@njit(cache=True, nogil=True, error_model="numpy")
def _reaches(q, target, dh):  # pragma: no cover - compiled
    """Whether the forward kinematics of ``q`` (6,) matches ``target`` (4, 4) to 1e-9 in
    every element (the library's last check of a branch)."""
    d1, d4, d5, d6, a2, a3 = dh[0], dh[1], dh[2], dh[3], dh[4], dh[5]
    ds = (d1, 0.0, 0.0, d4, d5, d6)
    As = (0.0, a2, a3, 0.0, 0.0, 0.0)
    alphas = (_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0)
    pose = np.eye(4)
    joint = np.empty((4, 4))
    product = np.empty((4, 4))
    for j in range(6):
        _dh(q[j], ds[j], As[j], alphas[j], joint)
        for r in range(4):
            for c in range(4):
                total = 0.0
                for i in range(4):
                    total += pose[r, i] * joint[i, c]
                product[r, c] = total
        pose[:, :] = product
    for r in range(4):
        for c in range(4):
            if abs(target[r, c] - pose[r, c]) > 1e-9:
                return False
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def ik_branches(target, dh, out):  # pragma: no cover - compiled
    """The branches of ``ur_analytic_ik``'s ``inverse_kinematics(target)``, in its order.

    Args:
        target: the flange (tool0) transform (4, 4), world frame.
        dh: d1, d4, d5, d6, a2, a3 (6,), m.
        out: (8, 6) scratch; its first rows receive the branches (rad, in [-pi, pi]).

    Returns the number of branches (0 to 8): finite, distinct (Euclidean distance >= 1e-12
    to every earlier one) and passing the forward-kinematics check.
    """
    d1, d4, d5, d6, a2, a3 = dh[0], dh[1], dh[2], dh[3], dh[4], dh[5]
    r11, r12, r13 = target[0, 0], target[0, 1], target[0, 2]
    r21, r22, r23 = target[1, 0], target[1, 1], target[1, 2]
    r31 = target[2, 0]
    px, py, pz = target[0, 3], target[1, 3], target[2, 3]
    sol = np.zeros((8, 6))
    # theta1, Eq. (24) of the library's source
    a1 = px - d6 * r13
    b1 = d6 * r23 - py
    h1 = a1 * a1 + b1 * b1 - d4 * d4
    h2 = math.atan2(math.sqrt(h1), d4)
    for row in range(4):
        sol[row, 0] = math.atan2(a1, b1) + h2
        sol[row + 4, 0] = math.atan2(a1, b1) - h2
    _wrist_angles(sol, r11, r12, r13, r21, r22, r23)
    _arm_angles(sol, r11, r21, r31, px, py, pz, d1, d5, d6, a2, a3)
    return _distinct_reaching(sol, target, dh, out)


@njit(cache=True, nogil=True, error_model="numpy")
def _wrist_angles(sol, r11, r12, r13, r21, r22, r23):  # pragma: no cover - compiled
    """theta5 and theta6 of the eight branches (columns 4, 5 of ``sol``) from theta1."""
    # Eqs. (25)-(28)
    for i in (0, 4):
        theta1 = sol[i, 0]
        c1, s1 = math.cos(theta1), math.sin(theta1)
        c5 = (s1 * r13) - (c1 * r23)
        e1 = s1 * r11 - c1 * r21
        e2 = s1 * r12 - c1 * r22
        s5 = math.sqrt(e1 * e1 + e2 * e2)
        theta5a, theta5b = math.atan2(s5, c5), math.atan2(-s5, c5)
        s5a, s5b = math.sin(theta5a), math.sin(theta5b)
        sign5a, sign5b = s5a / abs(s5a), s5b / abs(s5b)
        if abs(s5a - 0.0) <= 1e-12:
            sign5a, sign5b = 1.0, -1.0
        theta6a = _theta6(sign5a, c1, s1, r11, r12, r21, r22)
        theta6b = _theta6(sign5b, c1, s1, r11, r12, r21, r22)
        for row in (i, i + 1):
            sol[row, 4], sol[row, 5] = theta5a, theta6a
            sol[row + 2, 4], sol[row + 2, 5] = theta5b, theta6b


@njit(cache=True, nogil=True, error_model="numpy")
def _arm_angles(sol, r11, r21, r31, px, py, pz, d1, d5, d6, a2, a3):  # pragma: no cover - compiled
    """theta2, theta3, theta4 of the eight branches (columns 1-3 of ``sol``)."""
    # Eqs. (29)-(30), (52), (55), (58), (59)
    for i in (0, 2, 4, 6):
        theta1, theta5, theta6 = sol[i, 0], sol[i, 4], sol[i, 5]
        c1, s1 = math.cos(theta1), math.sin(theta1)
        c5, s5 = math.cos(theta5), math.sin(theta5)
        c6, s6 = math.cos(theta6), math.sin(theta6)
        a234 = (c1 * r11) + (s1 * r21)
        g1 = (c5 * c6 * r31) - (s6 * a234)
        g2 = (c5 * c6 * a234) + (s6 * r31)
        theta234 = math.atan2(g1, g2)
        c234, s234 = math.cos(theta234), math.sin(theta234)
        kc = (c1 * px) + (s1 * py) - (s234 * d5) + (c234 * s5 * d6)
        ks = pz - d1 + (c234 * d5) + (s234 * s5 * d6)
        f1 = (ks * ks + kc * kc - a2 * a2 - a3 * a3) / (2 * a2 * a3)
        f2 = 1.0 - f1 * f1
        if abs(f2) < 1e-12:
            f2 = 0.0
        theta3a = math.atan2(math.sqrt(f2), f1)
        theta3b = -theta3a
        theta2a = math.atan2(ks, kc) - math.atan2(
            a3 * math.sin(theta3a), (a3 * math.cos(theta3a)) + a2
        )
        theta2b = math.atan2(ks, kc) - math.atan2(
            a3 * math.sin(theta3b), (a3 * math.cos(theta3b)) + a2
        )
        sol[i, 1], sol[i, 2], sol[i, 3] = theta2a, theta3a, theta234 - theta2a - theta3a
        sol[i + 1, 1], sol[i + 1, 2], sol[i + 1, 3] = theta2b, theta3b, theta234 - theta2b - theta3b


@njit(cache=True, nogil=True, error_model="numpy")
def _distinct_reaching(sol, target, dh, out):  # pragma: no cover - compiled
    """The rows of ``sol`` wrapped to [-pi, pi], then the library's filters: finite,
    distinct, reaching ``target``; copied to the first rows of ``out``, their count returned."""
    count = 0
    for row in range(8):
        finite = True
        for j in range(6):
            y = np.fmod(sol[row, j], _TWO_PI)  # exact: any fmod gives these bits
            if y > _PI:
                y -= _TWO_PI
            elif y < -_PI:
                y += _TWO_PI
            sol[row, j] = y
            finite = finite and math.isfinite(y)
        if not finite:
            continue
        unique = True
        for earlier in range(count):
            squared = 0.0
            for j in range(6):
                difference = sol[row, j] - out[earlier, j]
                squared += difference * difference
            if math.sqrt(squared) < 1e-12:
                unique = False
                break
        if unique:
            out[count, :] = sol[row]
            count += 1
    kept = 0
    for row in range(count):
        if _reaches(out[row], target, dh):
            out[kept, :] = out[row]
            kept += 1
    return kept


@njit(cache=True, nogil=True, error_model="numpy")
def _segment(targets, reference, lower, upper, hint, dh, joints, reached):  # pragma: no cover
    """Sequential nearest-branch IK over ``targets`` (n, 4, 4); returns the last hint."""
    branches = np.empty((8, 6))
    best = np.empty(6)
    previous = reference.copy()
    for k in range(targets.shape[0]):
        count = ik_branches(targets[k], dh, branches)
        chosen = -1
        if count > 0:
            chosen = nearest_branch_index(branches[:count], previous, lower, upper, hint, best)
        if chosen >= 0:
            hint = chosen
            previous[:] = best
            reached[k] = True
        joints[k, :] = previous
    return hint


def segment_ik(
    poses: np.ndarray,
    flange_from_tcp: np.ndarray,
    reference: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    hint: int = 0,
    dh: np.ndarray = UR5E_DH,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Joint targets of a segment of TCP poses, each the IK branch nearest the previous one.

    Args:
        poses: TCP poses (n, 6): x, y, z (m), rotation vector (rad), world frame, float64.
        flange_from_tcp: the TCP-to-flange offset (4, 4) (``target = pose @ offset``).
        reference: the joint target before the segment (6,), rad.
        lower, upper: joint limits (6,), rad.
        hint: the branch index to try first (the one chosen last; speed only, never choice).
        dh: DH parameters d1, d4, d5, d6, a2, a3 (6,), m.

    Returns:
        joints: (n, 6), rad: pose k's target, the branch of its IK nearest target k - 1
            (``reference`` for k = 0), or target k - 1 held when pose k is unreachable.
        reached: (n,) bool, whether pose k had a branch within the limits.
        hint: the last chosen branch's index.
    """
    targets = np.matmul(pose_matrices(np.ascontiguousarray(poses, dtype=float)), flange_from_tcp)
    count = targets.shape[0]
    joints = np.empty((count, 6))
    reached = np.zeros(count, dtype=np.bool_)
    hint = _segment(
        targets, np.asarray(reference, dtype=float), lower, upper, hint, dh, joints, reached
    )
    return joints, reached, int(hint)
