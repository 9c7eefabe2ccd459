"""Small rigid-transform helpers (numpy only): rotation vectors, quaternions, poses.

Conventions: a pose vector is ``(x, y, z, rx, ry, rz)`` (metres, rotation vector in
radians, UR convention); a transform is a (4, 4) homogeneous matrix; quaternions are
PyBullet's ``(x, y, z, w)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def _rodrigues(rx: float, ry: float, rz: float) -> list[list[float]] | None:
    """Rows of the rotation matrix of a rotation vector (rad); None for the identity."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        return None
    kx, ky, kz = rx / angle, ry / angle, rz / angle
    c, s = math.cos(angle), math.sin(angle)
    v = 1.0 - c
    return [
        [c + kx * kx * v, kx * ky * v - kz * s, kx * kz * v + ky * s],
        [ky * kx * v + kz * s, c + ky * ky * v, ky * kz * v - kx * s],
        [kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v],
    ]


def rotvec_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a rotation vector (3,) in radians (Rodrigues)."""
    rx, ry, rz = (float(v) for v in rotvec)
    rows = _rodrigues(rx, ry, rz)
    return np.eye(3) if rows is None else np.array(rows)


def matrix_to_rotvec(rotation: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) in radians, angle in [0, pi], of a rotation matrix (3, 3)."""
    return quaternion_to_rotvec(matrix_to_quaternion(rotation))


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) with w >= 0 of a rotation matrix (3, 3)."""
    m = np.asarray(rotation, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    quat = np.asarray(q)
    quat /= np.linalg.norm(quat)
    return -quat if quat[3] < 0 else quat


def quaternion_to_matrix(quaternion: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a quaternion (x, y, z, w)."""
    x, y, z, w = map(float, quaternion)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_to_rotvec(quaternion: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) in radians, angle in [0, pi], of a quaternion (x, y, z, w)."""
    x, y, z, w = (float(v) for v in quaternion)
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    sin_half = math.sqrt(x * x + y * y + z * z)
    if sin_half < 1e-12:
        return np.zeros(3)
    angle = 2.0 * math.atan2(sin_half, w)
    return np.array([x, y, z]) * (angle / sin_half)


def rotvec_to_quaternion(rotvec: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) of a rotation vector (3,) in radians."""
    rotvec = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0])
    axis = rotvec / angle
    return np.array([*(axis * math.sin(angle / 2.0)), math.cos(angle / 2.0)])


def pose_to_matrix(pose: np.ndarray | Sequence[float]) -> np.ndarray:
    """Homogeneous transform (4, 4) of a pose (6,) ``(x, y, z, rx, ry, rz)``."""
    # One array from plain floats: called once per control period (issue 29).
    values = pose.tolist() if isinstance(pose, np.ndarray) else [float(v) for v in pose]
    x, y, z, rx, ry, rz = values[:6]
    rows = _rodrigues(float(rx), float(ry), float(rz))
    if rows is None:
        rows = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rows
    return np.array(
        [
            [r00, r01, r02, float(x)],
            [r10, r11, r12, float(y)],
            [r20, r21, r22, float(z)],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def matrix_to_pose(transform: np.ndarray) -> np.ndarray:
    """Pose (6,) ``(x, y, z, rx, ry, rz)`` of a homogeneous transform (4, 4)."""
    return np.concatenate([transform[:3, 3], matrix_to_rotvec(transform[:3, :3])])


def make_transform(rotation: np.ndarray | None = None, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Homogeneous transform (4, 4) from a rotation (3, 3) and a translation (3,) in m."""
    transform = np.eye(4)
    if rotation is not None:
        transform[:3, :3] = rotation
    transform[:3, 3] = translation
    return transform


def rotation_x(angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) about x by ``angle`` rad."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) about y by ``angle`` rad."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) about z by ``angle`` rad."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def invert_transform(transform: np.ndarray) -> np.ndarray:
    """Inverse of a rigid homogeneous transform (4, 4)."""
    inverse = np.eye(4)
    rotation_t = transform[:3, :3].T
    inverse[:3, :3] = rotation_t
    inverse[:3, 3] = -rotation_t @ transform[:3, 3]
    return inverse
