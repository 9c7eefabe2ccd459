"""Tests of distgprl.safety.hap_kernels: the compiled soft-min and box test of L_hap.

The kernels replaced NumPy code (`_reference_numpy_softmin`, kept verbatim) for speed
(issue 29); every v5 run before the change was trained with that code, so the soft-min must
give the same bits in float32 and float64, ties at the k-th distance included (a grid C_safe
makes them common), and the box test the same mask.
"""

from __future__ import annotations

import numpy as np
import pytest
from _reference_numpy_softmin import blocked as reference_blocked
from _reference_numpy_softmin import softmin_values as reference_softmin

from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.hap_kernels import grid_candidates, grid_softmin, softmin_with_gradient
from distgprl.safety.shapes import Box


def _grid(step: float = 0.1) -> np.ndarray:
    axes = [np.arange(0.3, 0.71, step), np.arange(-0.3, 0.31, step), np.arange(0.1, 0.41, step)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _case(dtype, rng, n=400, c=12):
    points = _grid()
    # half the queries on grid points and cell centres (equal distances: ties), half random
    exact = points[rng.integers(0, len(points), n // 4)]
    centres = exact + 0.05
    random = rng.uniform([0.2, -0.4, 0.0], [0.8, 0.4, 0.5], (n - 2 * (n // 4), 3))
    query = np.concatenate([exact, centres, random]).astype(dtype)
    index = np.stack([rng.permutation(len(points))[:c] for _ in range(n)])
    # the nearest points too, so the soft-min's top k is decided among close candidates
    nearest = np.argsort(np.linalg.norm(points[None] - query[:, None].astype(float), axis=2), 1)
    index[:, : c // 2] = nearest[:, : c // 2]
    return points, query, index


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("with_blocked", [False, True])
def test_softmin_gives_the_numpy_implementations_bits(dtype, with_blocked):
    rng = np.random.default_rng(3)
    points, query, index = _case(dtype, rng)
    blocked = rng.random(index.shape) < 0.3 if with_blocked else None
    if blocked is not None:
        blocked[:, 0] = False  # every row keeps a free candidate
    coordinates = np.ascontiguousarray(points.T.astype(dtype))
    values, jacobian = softmin_with_gradient(query, coordinates, index, blocked, 8, 0.05)
    expected_values, expected_jacobian = reference_softmin(
        query, list(coordinates), index, blocked, 8, 0.05
    )
    assert values.dtype == jacobian.dtype == dtype
    np.testing.assert_array_equal(values, expected_values)
    np.testing.assert_array_equal(jacobian, expected_jacobian)


def test_softmin_keeps_the_k_nearest_and_the_earlier_of_equal_distances():
    """Candidates at distances 1, 1, 1, 2 with k = 2: the first two ones are kept, so the
    soft-min is that of two points at distance 1 and the gradient points away from them."""
    coordinates = np.array([[1.0, 0.0, -1.0, 2.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
    query = np.zeros((1, 3))
    values, jacobian = softmin_with_gradient(
        query, coordinates, np.array([[0, 1, 2, 3]]), None, 2, 0.1
    )
    np.testing.assert_allclose(values, [1.0 - 0.1 * np.log(2.0)], rtol=0, atol=1e-15)
    np.testing.assert_allclose(jacobian, [[-0.5, -0.5, 0.0]], rtol=0, atol=1e-15)
    # the same candidates in another order keep the other two of the equal ones
    _, jacobian = softmin_with_gradient(query, coordinates, np.array([[2, 1, 0, 3]]), None, 2, 0.1)
    np.testing.assert_allclose(jacobian, [[0.5, -0.5, 0.0]], rtol=0, atol=1e-15)


@pytest.mark.parametrize("rotated", [False, True])
def test_blocked_candidates_give_the_numpy_implementations_mask(rotated):
    rng = np.random.default_rng(5)
    yaw = 0.4 if rotated else 0.0
    rotation = np.array(
        [[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]]
    )
    shapes = [
        Box("bar", np.array([0.5, 0.0, 0.25]), rotation, np.array([0.02, 0.2, 0.02])),
        Box("post", np.array([0.5, 0.2, 0.15]), np.eye(3), np.array([0.02, 0.02, 0.1])),
    ]
    moving = MovingObstacleFilter(shapes, np.array([0.0, 0.0, -0.05]), np.full(3, 0.03), 0.03)
    points = _grid(0.05)
    index = rng.integers(0, len(points), (300, 12))
    anchors = np.array([0.5, 0.0, 0.25]) + rng.normal(0.0, 0.1, (300, 3))
    mask, counts = moving.blocked_candidates(points, index, anchors)
    template = moving.template
    expected = reference_blocked(
        points[index],
        anchors,
        np.stack([b.position for b in template]),
        np.stack([b.rotation for b in template]),
        np.stack([b.half_extents for b in template]),
        moving.margin,
        moving.reach,
    )
    assert expected.any() and not expected.all()
    np.testing.assert_array_equal(mask, expected)
    np.testing.assert_array_equal(counts, expected.sum(axis=1))
    np.testing.assert_array_equal(moving.blocked(points[index], anchors), expected)


def test_grid_candidates_are_the_table_rows_of_the_clipped_cells():
    lower, resolution, shape = np.array([0.1, -0.2, 0.0]), 0.1, np.array([4, 5, 6])
    table = np.arange(int(np.prod(shape)) * 3, dtype=np.int16).reshape(-1, 3)
    rng = np.random.default_rng(7)
    positions = rng.uniform(-0.5, 1.0, (500, 3))  # many outside the table: clipped
    cell = np.clip(np.floor((positions - lower) / resolution).astype(int), 0, shape - 1)
    flat = np.ravel_multi_index(tuple(cell.T), tuple(shape))
    candidates = grid_candidates(positions, lower, resolution, shape, table)
    assert candidates.dtype == table.dtype
    np.testing.assert_array_equal(candidates, table[flat])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_grid_softmin_gives_the_separate_kernels_bits_on_float64_copies(dtype):
    """`grid_softmin` on the batch as given (float32 in training) equals the environment v7
    path bit for bit: `grid_candidates` and `boxes_block` on float64 copies of the queries and
    anchors, then `softmin_with_gradient` in the queries' dtype — values, gradients, blocked
    counts and the rows left to the fallback (fewer than k free candidates: all occur)."""
    from distgprl.safety.hap_loss import HapPrior

    rng = np.random.default_rng(11)
    prior = HapPrior(_grid(), neighbour_search="grid")
    shapes = [Box("cube", np.zeros(3), np.eye(3), np.full(3, 0.05), True)]
    moving = MovingObstacleFilter(shapes, np.zeros(3), np.full(3, 0.02), 0.03)
    query = rng.uniform([0.2, -0.4, 0.0], [0.8, 0.4, 0.5], (2000, 3)).astype(dtype)
    anchors = (query + rng.normal(0.0, 0.1, query.shape)).astype(dtype)
    grid, k, tau = prior._grid, prior.k, prior.temperature
    coordinates = prior._coordinates_as(np.dtype(dtype))
    values, jacobian, counts, short = grid_softmin(
        query, grid, coordinates, prior.points_numpy, anchors, moving.boxes, k, tau
    )
    index = grid_candidates(query.astype(float), *grid)
    blocked, expected_counts = moving.blocked_candidates(
        prior.points_numpy, index, anchors.astype(float)
    )
    expected_short = expected_counts > index.shape[1] - k
    full = ~expected_short
    expected_values, expected_jacobian = softmin_with_gradient(
        query[full], coordinates, index[full], blocked[full], k, tau
    )
    assert expected_counts.any() and expected_short.any() and full.any()
    np.testing.assert_array_equal(counts, expected_counts)
    np.testing.assert_array_equal(short, expected_short)
    assert values.dtype == jacobian.dtype == dtype
    np.testing.assert_array_equal(values[full], expected_values)
    np.testing.assert_array_equal(jacobian[full], expected_jacobian)
    assert not values[short].any() and not jacobian[short].any()
    # without moving obstacles: the same as the kernels on the float64 look-up
    values, jacobian, counts, short = grid_softmin(
        query, grid, coordinates, prior.points_numpy, None, None, k, tau
    )
    expected_values, expected_jacobian = softmin_with_gradient(
        query, coordinates, index, None, k, tau
    )
    assert not counts.any() and not short.any()
    np.testing.assert_array_equal(values, expected_values)
    np.testing.assert_array_equal(jacobian, expected_jacobian)
