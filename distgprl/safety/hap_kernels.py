"""Compiled loops of L_hap (issue 29): the soft-min with its gradient, the grid look-up of
candidates and the moving-obstacle box test, one query at a time (numba, no Python per
element).

They are the only implementations of what they compute; `distgprl.safety.hap_loss.HapPrior`
and `distgprl.safety.hap_filter.MovingObstacleFilter` call them. The arithmetic is in the
queries' dtype in the order NumPy's vectorised code used before (distances
sqrt(dx^2 + dy^2 + dz^2 + 1e-18), sums over candidates in candidate order), and ``exp`` and
``log`` are still NumPy's (its SIMD loops, called between the two compiled passes), so the
results are bit-identical to that code in float32 and float64 (tested against it, kept in
``tests/safety/_reference_numpy_softmin.py``); the box test is in float64, also bit-identical.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np
from numba import njit

__all__ = ["boxes_block", "grid_candidates", "softmin_with_gradient"]

_Function = TypeVar("_Function", bound=Callable[..., Any])


def _compiled(function: _Function) -> _Function:
    """``numba.njit(cache=True, nogil=True)``, keeping the function's signature for type
    checkers (numba has no type information: its dispatcher would be ``Any``)."""
    return cast(_Function, njit(cache=True, nogil=True)(function))


def softmin_with_gradient(
    query: np.ndarray,
    coordinates: np.ndarray,
    index: np.ndarray,
    blocked: np.ndarray | None,
    k: int,
    temperature: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Soft-min over the k nearest free candidates of each query, and its gradient.

    Args:
        query: query positions, shape (n, 3), m, dtype D (float32 or float64).
        coordinates: C_safe coordinates per axis, shape (3, m), dtype D.
        index: candidate C_safe indices per query, shape (n, c), integer.
        blocked: shape (n, c) bool, candidates to leave out, or None.
        k: neighbours kept per query: the k smallest distances (where distances tie, the
            earlier candidate).
        temperature: tau, m.

    Returns:
        values (n,), dtype D: -tau log sum_kept exp(-d_j / tau) (Eq. hap_compact), computed as
        d_min - tau log sum_kept exp((d_min - d_j) / tau); jacobian (n, 3): sum_kept
        w_j (x - y_j) / d_j with w = softmax(-d / tau) over the kept candidates. Blocked
        candidates have d = inf and weight 0. Distances are sqrt(|x - y|^2 + 1e-18).

    Candidate-major (c, n) arrays, so that the loops over queries vectorise; ``exp`` and
    ``log`` are NumPy's (its SIMD loops) between the two compiled passes.
    """
    dtype = query.dtype
    constants = np.array([1.0 / temperature, 1e-18], dtype=dtype)
    no_blocked = blocked is None
    distances, nearest, exponent, keep, offsets = _candidate_distances(
        np.ascontiguousarray(query.T),
        coordinates,
        np.ascontiguousarray(index.T),
        np.zeros((0, 0), dtype=bool) if blocked is None else np.ascontiguousarray(blocked.T),
        not no_blocked,
        k,
        constants,
    )
    np.exp(exponent, out=exponent)  # exp((d_min - d_j) / tau); 0 where d = inf
    total, jacobian = _weighted_sums(exponent, keep, distances, offsets)
    values = nearest - dtype.type(temperature) * np.log(total)
    return values, jacobian


@_compiled
def _candidate_distances(
    query: np.ndarray,
    coordinates: np.ndarray,
    index: np.ndarray,
    blocked: np.ndarray,
    use_blocked: bool,
    k: int,
    constants: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """First pass of `softmin_with_gradient`, candidate-major: distances (c, n), their
    minimum d_min (n,), (d_min - d) / tau (c, n), the kept candidates (c, n) and the offsets
    x - y (3, c, n)."""
    count, n = index.shape
    inverse_tau, tiny = constants[0], constants[1]
    distances = np.empty((count, n), dtype=query.dtype)
    offsets = np.empty((3, count, n), dtype=query.dtype)
    for j in range(count):
        for i in range(n):
            point = index[j, i]
            dx = query[0, i] - coordinates[0, point]
            dy = query[1, i] - coordinates[1, point]
            dz = query[2, i] - coordinates[2, point]
            offsets[0, j, i] = dx
            offsets[1, j, i] = dy
            offsets[2, j, i] = dz
            squared = dx * dx
            squared += dy * dy
            squared += dz * dz
            squared += tiny
            distances[j, i] = np.sqrt(squared)
    if use_blocked:
        infinity = query.dtype.type(np.inf)
        for j in range(count):
            for i in range(n):
                if blocked[j, i]:
                    distances[j, i] = infinity
    nearest = distances[0].copy()
    for j in range(1, count):
        for i in range(n):
            if distances[j, i] < nearest[i]:
                nearest[i] = distances[j, i]
    # keep the k smallest by (distance, candidate order): a candidate's rank counts the
    # candidates before it in that order
    keep = np.ones((count, n), dtype=np.bool_)
    if count > k:
        rank = np.empty(n, dtype=np.int32)
        for j in range(count):
            rank[:] = 0
            for other in range(count):
                if other < j:
                    for i in range(n):
                        rank[i] += distances[other, i] <= distances[j, i]
                elif other > j:
                    for i in range(n):
                        rank[i] += distances[other, i] < distances[j, i]
            for i in range(n):
                keep[j, i] = rank[i] < k
    exponent = np.empty((count, n), dtype=query.dtype)
    for j in range(count):
        for i in range(n):
            exponent[j, i] = (nearest[i] - distances[j, i]) * inverse_tau
    return distances, nearest, exponent, keep, offsets


@_compiled
def _weighted_sums(
    weights: np.ndarray, keep: np.ndarray, distances: np.ndarray, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Second pass of `softmin_with_gradient`: the kept weights' sum (n,) and the soft-min's
    gradient (n, 3), summed over candidates in candidate order. ``weights`` (c, n) is
    overwritten."""
    count, n = weights.shape
    zero = weights.dtype.type(0.0)
    total = np.zeros(n, dtype=weights.dtype)
    for j in range(count):
        for i in range(n):
            if not keep[j, i]:
                weights[j, i] = zero
            total[i] += weights[j, i]
    jacobian = np.zeros((n, 3), dtype=weights.dtype)
    for j in range(count):
        for i in range(n):
            weight = weights[j, i] / total[i] / distances[j, i]
            jacobian[i, 0] += weight * offsets[0, j, i]
            jacobian[i, 1] += weight * offsets[1, j, i]
            jacobian[i, 2] += weight * offsets[2, j, i]
    return total, jacobian


@_compiled
def boxes_block(
    points: np.ndarray,
    index: np.ndarray,
    anchors: np.ndarray,
    centres: np.ndarray,
    rotations: np.ndarray,
    half_extents: np.ndarray,
    axis_aligned: bool,
    bounds: np.ndarray,
    margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Which candidate points the moving boxes block: mask (n, c) bool and the blocked
    candidates per row (n,) (float64 arithmetic).

    A point p is blocked when |max(|R_b^T (p - a - c_b)| - h_b, 0)| < margin for a box b
    (anchor a of its row; centres c_b, rotations R_b, grown half extents h_b of the
    template).

    Args:
        points: positions, shape (m, 3), m.
        index: the candidates of each row, indices into ``points``, shape (n, c).
        anchors: the obstacles' anchor per row, shape (n, 3), m.
        centres, rotations, half_extents: the template boxes, (b, 3), (b, 3, 3), (b, 3).
        axis_aligned: every rotation is the identity (the test then skips the rotation).
        bounds: a cheap first cut, shape (7,): axis-aligned, the middle (3,) and half span
            (3,) of the boxes' common bounding box grown by the margin (points outside are
            not blocked); otherwise its first entry is the reach: points farther than it from
            the anchor are not blocked.
        margin: required clearance, m.
    """
    n, count = index.shape
    boxes = centres.shape[0]
    limit = margin * margin
    out = np.zeros((n, count), dtype=np.bool_)
    counts = np.zeros(n, dtype=np.int64)
    # one row at a time, its candidates in branch-free loops (they vectorise): the first cut,
    # then, if any candidate passes it, every box for every candidate
    rx, ry, rz = np.empty(count), np.empty(count), np.empty(count)
    near = np.empty(count, dtype=np.bool_)
    hit = np.empty(count, dtype=np.bool_)
    reach = bounds[0] * bounds[0]
    for i in range(n):
        any_near = False
        for j in range(count):
            point = index[i, j]
            x = points[point, 0] - anchors[i, 0]
            y = points[point, 1] - anchors[i, 1]
            z = points[point, 2] - anchors[i, 2]
            rx[j], ry[j], rz[j] = x, y, z
            if axis_aligned:
                inside = (
                    (abs(x - bounds[1]) < bounds[4])
                    & (abs(y - bounds[2]) < bounds[5])
                    & (abs(z - bounds[3]) < bounds[6])
                )
            else:
                inside = x * x + y * y + z * z < reach
            near[j] = inside
            any_near |= inside
        if not any_near:
            continue
        hit[:] = False
        for b in range(boxes):
            for j in range(count):
                ex = rx[j] - centres[b, 0]
                ey = ry[j] - centres[b, 1]
                ez = rz[j] - centres[b, 2]
                if not axis_aligned:
                    ex, ey, ez = (
                        (ex * rotations[b, 0, 0] + ey * rotations[b, 1, 0])
                        + ez * rotations[b, 2, 0],
                        (ex * rotations[b, 0, 1] + ey * rotations[b, 1, 1])
                        + ez * rotations[b, 2, 1],
                        (ex * rotations[b, 0, 2] + ey * rotations[b, 1, 2])
                        + ez * rotations[b, 2, 2],
                    )
                excess_x = max(abs(ex) - half_extents[b, 0], 0.0)
                excess_y = max(abs(ey) - half_extents[b, 1], 0.0)
                excess_z = max(abs(ez) - half_extents[b, 2], 0.0)
                squared = 0.0
                squared += excess_x * excess_x
                squared += excess_y * excess_y
                squared += excess_z * excess_z
                hit[j] |= squared < limit
        blocked = 0
        for j in range(count):
            value = hit[j] & near[j]
            out[i, j] = value
            blocked += value
        counts[i] = blocked
    return out, counts


@_compiled
def grid_candidates(
    positions: np.ndarray,
    lower: np.ndarray,
    resolution: float,
    shape: np.ndarray,
    table: np.ndarray,
) -> np.ndarray:
    """The lookup table's candidates (n, c) of each position (n, 3), m: the cell
    floor((p - lower) / resolution), clipped to the table's ``shape`` (3,), of a table
    (cells, c) stored in C order over the cells."""
    n = positions.shape[0]
    count = table.shape[1]
    out = np.empty((n, count), dtype=table.dtype)
    for i in range(n):
        flat = 0
        for a in range(3):
            cell: np.int64 | int = np.int64(np.floor((positions[i, a] - lower[a]) / resolution))
            if cell < 0:
                cell = 0
            elif cell > shape[a] - 1:
                cell = shape[a] - 1
            flat = flat * shape[a] + cell
        for j in range(count):
            out[i, j] = table[flat, j]
    return out
