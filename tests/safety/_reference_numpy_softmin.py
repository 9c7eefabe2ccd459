"""The NumPy soft-min and box test that `distgprl.safety.hap_kernels` replaced (issue 29),
kept verbatim (as functions) so the tests can check the compiled loops give the same bits.

From `HapPrior._softmin_values` and `MovingObstacleFilter.blocked` at commit e7fbbc7, the
code every v5 run before the change was trained with.
"""

from __future__ import annotations

import numpy as np


def softmin_values(
    x: np.ndarray,
    coordinates: list[np.ndarray],
    index: np.ndarray,
    blocked: np.ndarray | None,
    k: int,
    tau: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Soft-min (n,) over the k nearest free candidates and its gradient (n, 3) w.r.t. x;
    ``coordinates``: C_safe's three coordinate arrays (m,) in x's dtype."""
    columns = np.ascontiguousarray(index.T)  # (c, n)
    query = np.ascontiguousarray(x.T)  # (3, n)
    dx, dy, dz = (q - c[columns] for q, c in zip(query, coordinates, strict=True))
    distances = dx * dx
    distances += dy * dy
    distances += dz * dz
    distances += 1e-18
    np.sqrt(distances, out=distances)
    if blocked is not None:
        np.copyto(distances, np.inf, where=blocked.T)
    count = distances.shape[0]
    keep = None
    if count > k:
        rows = np.ascontiguousarray(distances.T)  # (n, c)
        threshold = np.partition(rows, k - 1, axis=1)[:, k - 1]
        keep = distances <= threshold
        if np.count_nonzero(keep) > k * keep.shape[1]:
            ties = np.flatnonzero(keep.sum(axis=0) > k)
            order = np.argsort(rows[ties], axis=1, kind="stable")[:, :k]
            keep[:, ties] = False
            keep[order, ties[:, None]] = True
    nearest = distances.min(axis=0)
    weights = np.subtract(nearest, distances)
    weights *= 1.0 / tau
    np.exp(weights, out=weights)
    if keep is not None:
        weights *= keep
    total = weights.sum(axis=0)
    values = nearest - tau * np.log(total)
    weights /= total
    weights /= distances
    jacobian = np.stack([(weights * d).sum(axis=0) for d in (dx, dy, dz)], axis=1)
    return values, jacobian


def blocked(
    points: np.ndarray,
    anchors: np.ndarray,
    centres: np.ndarray,
    rotations: np.ndarray,
    half_extents: np.ndarray,
    margin: float,
    reach: float,
) -> np.ndarray:
    """Mask ``points.shape[:-1]``: the point p (rows (..., c, 3)) is within ``margin`` of a
    template box (centres (b, 3), rotations (b, 3, 3), grown half extents (b, 3)) placed at
    its row's anchor (..., 3). The general (rotated-box) path."""
    relative = (points - anchors[..., None, :]).reshape(-1, 3)
    out = np.zeros(len(relative), dtype=bool)
    near = np.flatnonzero(np.einsum("ij,ij->i", relative, relative) < reach**2)
    if near.size:
        local = relative[near][:, None, :] - centres
        local = np.einsum("mbi,bij->mbj", local, rotations)
        local = np.abs(local, out=local) - half_extents
        np.maximum(local, 0.0, out=local)
        squared = np.einsum("mbi,mbi->mb", local, local)
        out[near] = (squared < margin**2).any(axis=1)
    return out.reshape(points.shape[:-1])
