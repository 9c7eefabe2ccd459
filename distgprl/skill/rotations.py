"""Rotation-vector helpers for trajectories interpolated per axis (numpy only)."""

from __future__ import annotations

import numpy as np


def nearest_equivalent_rotvec(rotvec: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The rotation vector equivalent to ``rotvec`` that is nearest to ``reference``.

    A rotation by angle theta about unit axis u is also represented by
    (theta + 2 pi k) u for every integer k; near theta = pi the two shortest
    representations differ by ~2 pi, which would be a huge jump for a trajectory that
    interpolates rotation vectors per axis. Shapes (3,), rad.
    """
    rotvec = np.asarray(rotvec, dtype=float)
    reference = np.asarray(reference, dtype=float)
    angle = np.linalg.norm(rotvec)
    if angle < 1e-12:
        axis = reference / max(np.linalg.norm(reference), 1e-12)
        if np.linalg.norm(reference) < 1e-12:
            return rotvec.copy()
    else:
        axis = rotvec / angle
    base = np.dot(reference, axis) - angle
    candidates = [rotvec + 2 * np.pi * k * axis for k in np.round(base / (2 * np.pi)) + (-1, 0, 1)]
    return min(candidates, key=lambda c: float(np.linalg.norm(c - reference)))
