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

`grid_softmin` (issue 66, rule 6) chains the look-up, the box test and the soft-min of the
grid mode on the batch as given (float32 queries and anchors promoted element by element in
the float64 look-up and box test, no float64 or transposed copies of the batch).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple, TypeVar, cast

import numpy as np
from numba import njit

__all__ = ["MovingBoxes", "boxes_block", "grid_candidates", "grid_softmin", "softmin_with_gradient"]

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

    Candidate-major (c, n) arrays, so that the loops over queries vectorise (``index`` and
    ``blocked`` are read as given, no transposed copies); ``exp`` and ``log`` are NumPy's
    (its SIMD loops) between the two compiled passes. The offsets x - y are recomputed in the
    second pass rather than stored (C_safe's coordinates are few and stay in cache).
    """
    dtype = query.dtype
    constants = np.array([1.0 / temperature, 1e-18], dtype=dtype)
    queries = np.ascontiguousarray(query.T)
    distances, nearest, exponent = _candidate_distances(
        queries,
        coordinates,
        np.ascontiguousarray(index),
        np.zeros((0, 0), dtype=bool) if blocked is None else np.ascontiguousarray(blocked),
        blocked is not None,
        k,
        constants,
    )
    np.exp(exponent, out=exponent)  # exp((d_min - d_j) / tau); 0 where d = inf or not kept
    total, jacobian = _weighted_sums(exponent, distances, queries, coordinates, index)
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
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First pass of `softmin_with_gradient`, candidate-major: distances (c, n) of the
    candidates ``index`` (n, c) (inf where ``blocked`` (n, c)), their minimum d_min (n,) and
    (d_min - d) / tau (c, n) of the kept candidates, -inf for the others (so that ``exp``
    gives their weight 0)."""
    n, count = index.shape
    inverse_tau, tiny = constants[0], constants[1]
    distances = np.empty((count, n), dtype=query.dtype)
    for j in range(count):
        for i in range(n):
            point = index[i, j]
            dx = query[0, i] - coordinates[0, point]
            dy = query[1, i] - coordinates[1, point]
            dz = query[2, i] - coordinates[2, point]
            squared = dx * dx
            squared += dy * dy
            squared += dz * dz
            squared += tiny
            distances[j, i] = np.sqrt(squared)
    infinity = query.dtype.type(np.inf)
    if use_blocked:
        _block_candidates(distances, blocked, infinity)
    nearest = distances[0].copy()
    for j in range(1, count):
        for i in range(n):
            if distances[j, i] < nearest[i]:
                nearest[i] = distances[j, i]
    exponent = np.empty((count, n), dtype=query.dtype)
    for j in range(count):
        for i in range(n):
            exponent[j, i] = (nearest[i] - distances[j, i]) * inverse_tau
    if count > k:
        _drop_beyond_k(distances, exponent, k, -infinity)
    return distances, nearest, exponent


@_compiled
def _block_candidates(distances: np.ndarray, blocked: np.ndarray, infinity: float) -> None:
    """Set the distance (c, n) of every candidate ``blocked`` (n, c) to ``infinity``."""
    count, n = distances.shape
    for j in range(count):
        for i in range(n):
            if blocked[i, j]:
                distances[j, i] = infinity


@_compiled
def _drop_beyond_k(distances: np.ndarray, exponent: np.ndarray, k: int, dropped: float) -> None:
    """Keep the k smallest candidates per query by (distance, candidate order): a candidate's
    rank counts the candidates before it in that order; the others' ``exponent`` (c, n)
    becomes ``dropped``."""
    count, n = distances.shape
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
            if rank[i] >= k:
                exponent[j, i] = dropped


@_compiled
def _weighted_sums(
    weights: np.ndarray,
    distances: np.ndarray,
    query: np.ndarray,
    coordinates: np.ndarray,
    index: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Second pass of `softmin_with_gradient`: the weights' sum (n,) and the soft-min's
    gradient (n, 3), summed over candidates in candidate order (weights (c, n), 0 for the
    candidates not kept; the offsets x - y recomputed from ``query`` (3, n), ``coordinates``
    and ``index`` (n, c))."""
    count, n = weights.shape
    total = np.zeros(n, dtype=weights.dtype)
    for j in range(count):
        for i in range(n):
            total[i] += weights[j, i]
    jacobian = np.zeros((n, 3), dtype=weights.dtype)
    for j in range(count):
        for i in range(n):
            point = index[i, j]
            weight = weights[j, i] / total[i] / distances[j, i]
            jacobian[i, 0] += weight * (query[0, i] - coordinates[0, point])
            jacobian[i, 1] += weight * (query[1, i] - coordinates[1, point])
            jacobian[i, 2] += weight * (query[2, i] - coordinates[2, point])
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


class MovingBoxes(NamedTuple):
    """`boxes_block`'s description of the moving boxes (`MovingObstacleFilter.boxes`).

    Attributes:
        centres, rotations, half_extents: the template boxes, (b, 3), (b, 3, 3), (b, 3), m.
        axis_aligned: every rotation is the identity.
        bounds: the first cut, shape (7,) (see `boxes_block`).
        margin: required clearance, m.
    """

    centres: np.ndarray
    rotations: np.ndarray
    half_extents: np.ndarray
    axis_aligned: bool
    bounds: np.ndarray
    margin: float


_NO_BOXES = MovingBoxes(
    np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)), True, np.zeros(7), 1.0
)


class GridTable(NamedTuple):
    """`grid_candidates`' look-up table: ``lower`` (3,) m, ``resolution`` m, ``shape`` (3,)
    cells, ``table`` (cells, c) C_safe indices (C order over the cells)."""

    lower: np.ndarray
    resolution: float
    shape: np.ndarray
    table: np.ndarray


def grid_softmin(
    query: np.ndarray,
    grid: GridTable,
    coordinates: np.ndarray,
    points: np.ndarray,
    anchors: np.ndarray | None,
    boxes: MovingBoxes | None,
    k: int,
    temperature: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Look-up, moving-obstacle box test and soft-min of the grid mode, without copies.

    `grid_candidates`, `boxes_block` and `softmin_with_gradient` one after another on the
    queries and anchors as given (float32 in training: numba promotes each element to float64
    in the look-up and the box test, exactly as a float64 copy would, so the decisions are
    those of the float64 path), with the candidates and the mask read in place (no float64 or
    transposed copies). The values and gradients of the queries that keep at least k free
    candidates are those of the separate kernels on float64 copies, bit for bit (tested).

    Args:
        query: query positions, shape (n, 3), m, dtype D (float32 or float64).
        grid: the look-up table.
        coordinates: C_safe coordinates per axis, shape (3, m), dtype D (the soft-min's).
        points: C_safe positions, shape (m, 3), float64 (the box test's).
        anchors: the moving obstacles' anchor per query, shape (n, 3), m, any float dtype;
            None (with ``boxes`` None): no moving obstacles.
        boxes: the moving boxes, or None.
        k: neighbours kept per query (<= the table's candidates).
        temperature: tau, m.

    Returns:
        values (n,) and jacobian (n, 3), dtype D (Eq. hap_compact and its gradient, see
        `softmin_with_gradient`), 0 in the rows that are ``short``; ``counts`` (n,) int64,
        the blocked candidates per query; ``short`` (n,) bool, the queries with fewer than
        k free candidates (left to the caller's exact fallback).
    """
    use_moving = boxes is not None
    if use_moving and anchors is None:
        raise ValueError("a moving-obstacle filter needs the obstacles' anchors")
    query = np.ascontiguousarray(query)
    # float32 queries and anchors enter the float64 look-up and box test as they are: numba
    # promotes each element (exactly), so no float64 copy of the batch is made
    index = grid_candidates(query, grid.lower, grid.resolution, grid.shape, grid.table)
    if boxes is None or anchors is None:
        counts = np.zeros(len(query), dtype=np.int64)
        values, jacobian = softmin_with_gradient(query, coordinates, index, None, k, temperature)
        return values, jacobian, counts, counts.astype(np.bool_)
    blocked, counts = boxes_block(points, index, np.ascontiguousarray(anchors), *boxes)
    short = counts > index.shape[1] - k
    with np.errstate(invalid="ignore", divide="ignore"):  # short rows: fewer than k free
        values, jacobian = softmin_with_gradient(query, coordinates, index, blocked, k, temperature)
    if short.any():
        values[short] = 0.0
        jacobian[short] = 0.0
    return values, jacobian, counts, short
