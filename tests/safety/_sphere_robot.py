"""The safety tests' UR5e sphere model checked against an EDF scene (a module of its own, so
test files import it by a name no other test folder uses; `conftest.py` holds the fixtures).

The collision checker is deliberately simple (spheres along the DH chain of the UR5e, no
self-collision), built from :class:`DistanceField`; HAP only needs *a* checker.
"""

from __future__ import annotations

import numpy as np
import ur_analytic_ik
from scipy.spatial.transform import Rotation

from distgprl.safety.edf import DistanceField
from distgprl.safety.shapes import Box, Cylinder, Plane

# UR5e standard DH parameters (official kinematics), m and rad.
UR5E_A = np.array([0.0, -0.425, -0.3922, 0.0, 0.0, 0.0])
UR5E_D = np.array([0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996])
UR5E_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])
LINK_RADIUS = 0.05  # m
DOWN_YAW_45 = (
    Rotation.from_euler("z", np.pi / 4) * Rotation.from_rotvec([np.pi, 0.0, 0.0])
).as_rotvec()
SPHERE_SPACING = 0.05  # m


def ur5e_frames(q: np.ndarray) -> np.ndarray:
    """World transforms of the DH frames 0..6, shape (7, 4, 4)."""
    frames = [np.eye(4)]
    for theta, a, d, alpha in zip(q, UR5E_A, UR5E_D, UR5E_ALPHA, strict=True):
        ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
        step = np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0.0, sa, ca, d],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
        frames.append(frames[-1] @ step)
    return np.asarray(frames)


def link_sphere_centres(q: np.ndarray) -> np.ndarray:
    """Sphere centres along the links from the shoulder to the flange, shape (s, 3), m."""
    origins = ur5e_frames(q)[:, :3, 3]
    centres = []
    for start, end in zip(origins[1:-1], origins[2:], strict=True):
        count = max(1, int(np.ceil(np.linalg.norm(end - start) / SPHERE_SPACING)))
        t = np.linspace(0.0, 1.0, count + 1)[:, None]
        centres.append(start + t * (end - start))
    return np.concatenate(centres)


class SphereRobotChecker:
    """``in_collision(q)``: any link sphere closer than its radius to the scene's obstacles."""

    def __init__(self, field: DistanceField) -> None:
        self.field = field
        self.calls = 0

    def __call__(self, q: np.ndarray) -> bool:
        self.calls += 1
        clearance = self.field.clearance(link_sphere_centres(np.asarray(q, dtype=float)))
        return bool(np.any(clearance < LINK_RADIUS))


def ur5e_ik_all(transform: np.ndarray) -> np.ndarray:
    """All analytic UR5e IK solutions (k, 6), rad, for a flange transform (4, 4)."""
    solutions = ur_analytic_ik.ur5e.inverse_kinematics(np.ascontiguousarray(transform))
    return np.asarray(solutions, dtype=float).reshape(-1, 6)


def scene_shapes() -> tuple:
    """A table plane, a pillar box in front of the robot and a cylinder post (static)."""
    return (
        Plane("table", np.array([0.0, 0.0, -0.05]), np.array([0.0, 0.0, 1.0])),
        Box("pillar", np.array([0.5, 0.05, 0.2]), np.eye(3), np.array([0.05, 0.05, 0.25])),
        Cylinder("post", np.array([0.35, -0.35, 0.15]), np.eye(3), 0.04, 0.2),
    )
