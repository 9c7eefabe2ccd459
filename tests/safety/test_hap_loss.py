"""Tests of distgprl.safety.hap_loss: the soft-min HAP prior L_hap (Eq. hap_compact)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.hap_loss import HapPrior, HapPriorConfig
from distgprl.safety.shapes import Box


def grid_points(step: float = 0.1) -> np.ndarray:
    axes = [np.arange(0.3, 0.71, step), np.arange(-0.3, 0.31, step), np.arange(0.1, 0.41, step)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


@pytest.fixture(scope="module")
def c_safe() -> np.ndarray:
    return grid_points()


@pytest.fixture(scope="module", params=["grid", "kdtree"])
def prior(request, c_safe) -> HapPrior:
    return HapPrior(c_safe, neighbour_search=request.param)


def test_loss_is_the_equation_as_written_without_offset(prior, c_safe):
    """Environment v8 (issue 66, rule 4): L_hap per query is Eq. hap_compact's soft-min
    itself, -tau log sum_kNN exp(-d / tau) in m, no constant subtracted: on C_safe points it
    is negative (the other neighbours, a grid step away, still contribute) and equals the
    exact soft-min there; the prior has no offset."""
    assert prior.offset == 0.0 and prior.hinge_step == 0.0
    at_points = prior.per_point(torch.as_tensor(c_safe, dtype=torch.float64)).numpy()
    exact = _exact_softmin(prior, c_safe, c_safe)
    np.testing.assert_allclose(at_points, exact, rtol=0, atol=1e-6)
    assert np.all(at_points < -0.01)


def test_loss_tracks_the_distance_off_the_subspace(prior, c_safe):
    """Points 0.3 m above the top layer: min distance - tau log k <= L_hap <= min distance."""
    top = c_safe[np.isclose(c_safe[:, 2], c_safe[:, 2].max())]
    above = torch.as_tensor(top + [0.0, 0.0, 0.3], dtype=torch.float32)
    values = prior.per_point(above)
    lower = 0.3 - prior.temperature * np.log(prior.k)
    assert torch.all((values >= lower - 1e-6) & (values <= 0.3 + 1e-6))


def test_gradient_step_decreases_the_loss_off_the_subspace(prior):
    rng = np.random.default_rng(0)
    # (B, N_q, 3) trajectories off the subspace (beside and above the grid).
    x = torch.as_tensor(rng.uniform([0.8, -0.5, 0.5], [1.0, 0.5, 0.7], (16, 20, 3)))
    x = x.float().requires_grad_(True)
    loss = prior.loss(x)
    assert loss.ndim == 0
    loss.backward()
    per_point_grad = x.grad.reshape(-1, 3).norm(dim=1) * (16 * 20)  # undo the mean
    assert torch.all(per_point_grad > 0.5)  # each point is pulled (|d softmin / dx| ~ 1)
    with torch.no_grad():
        stepped = x - 0.05 * x.grad / x.grad.reshape(-1, 3).norm(dim=1).max()
    assert float(prior.loss(stepped)) < float(loss.detach()) - 1e-3


def test_gradient_points_towards_the_subspace(prior, c_safe):
    x = torch.tensor([[0.5, 0.0, 0.8]], requires_grad=True)
    prior.loss(x).backward()
    assert x.grad[0, 2] > 0.9 * x.grad.norm()  # descent moves the point down to the grid


def test_grid_search_matches_exact_neighbours(c_safe):
    rng = np.random.default_rng(1)
    x = torch.as_tensor(rng.uniform([0.1, -0.6, -0.1], [0.9, 0.6, 0.7], (4000, 3)))
    grid = HapPrior(c_safe, neighbour_search="grid", dtype=torch.float64).per_point(x)
    exact = HapPrior(c_safe, neighbour_search="kdtree", dtype=torch.float64).per_point(x)
    error = (grid - exact).abs()
    assert float(torch.quantile(error, 0.99)) < 1e-6
    assert float(error.max()) < 2e-3


def test_gradient_matches_finite_differences():
    """torch.autograd.gradcheck on the recomputed distances (double precision)."""
    rng = np.random.default_rng(2)
    prior = HapPrior(grid_points(), neighbour_search="kdtree", dtype=torch.float64)
    x = torch.as_tensor(rng.uniform([0.3, -0.3, 0.1], [0.7, 0.3, 0.5], (6, 3)))
    x.requires_grad_(True)
    assert torch.autograd.gradcheck(prior.loss, (x,), eps=1e-6, atol=1e-6)


def test_coinciding_points_have_finite_gradient_and_config_defaults(c_safe):
    config = HapPriorConfig()
    assert (config.k, config.temperature, config.query_points) == (8, 0.05, 20)
    prior = HapPrior.from_config(c_safe, config)
    x = torch.as_tensor(c_safe[:5], dtype=torch.float32).requires_grad_(True)
    prior.loss(x).backward()
    assert torch.all(torch.isfinite(x.grad))
    with pytest.raises(ValueError):
        HapPrior(np.zeros((0, 3)))


def _exact_softmin(prior: HapPrior, points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Eq. hap_compact's summand over ``points`` with exact neighbours (float64)."""
    distances = np.sort(np.linalg.norm(x[:, None, :] - points[None], axis=2), axis=1)
    nearest = distances[:, : prior.k]
    tau = prior.temperature
    return -tau * np.log(np.exp(-nearest / tau).sum(axis=1))


@pytest.mark.parametrize("search", ["grid", "kdtree"])
def test_moving_filter_gives_the_soft_min_over_the_unblocked_subspace(c_safe, search):
    """With a moving obstacle, each query's soft-min runs over C_safe without the points the
    obstacle blocks at that query's anchor: equal to the exact soft-min over the filtered
    subspace — also for queries next to the obstacle, whose lookup candidates are mostly
    blocked (the exact fallback search). Exact with the k-d tree; with the lookup table, whose
    candidates are the nearest points of the cell centre, within 2.5 mm."""
    prior = HapPrior(c_safe, neighbour_search=search, dtype=torch.float64)
    obstacle = (Box("cube", np.zeros(3), np.eye(3), np.full(3, 0.04), True),)
    moving = MovingObstacleFilter(obstacle, np.zeros(3), np.full(3, 0.02), margin=0.03)
    rng = np.random.default_rng(0)
    anchors = rng.uniform([0.35, -0.25, 0.15], [0.65, 0.25, 0.35], (60, 3))
    x = anchors + rng.normal(0.0, 0.08, (60, 3))  # queries around the obstacle
    values = prior.per_point(torch.as_tensor(x), anchors, moving).numpy()
    expected = []
    for query, anchor in zip(x, anchors, strict=True):
        free = c_safe[~moving.blocked(c_safe[None], anchor[None])[0]]
        expected.append(_exact_softmin(prior, free, query[None])[0])
    assert prior.last_moving_counts["fallback"] > 0  # the fallback path ran
    assert prior.last_moving_counts["no_free"] == 0
    np.testing.assert_allclose(values, expected, atol=2.5e-3 if search == "grid" else 1e-9)
    # The filter matters: without it the loss is lower near the obstacle.
    plain = prior.per_point(torch.as_tensor(x)).numpy()
    assert np.mean(values - plain) > 0.005


def test_moving_filter_leaves_a_query_without_free_points_unpulled(c_safe):
    """A query whose nearest C_safe points are all blocked (deep in the blocked zone, few
    fallback candidates) contributes 0 and no gradient; the others keep their gradient."""
    prior = HapPrior(c_safe, fallback_candidates=8)
    obstacle = (Box("slab", np.zeros(3), np.eye(3), np.array([0.3, 0.3, 0.3]), True),)
    moving = MovingObstacleFilter(obstacle, np.zeros(3), np.zeros(3), margin=0.01)
    anchors = np.array([[0.5, 0.0, 0.25], [5.0, 5.0, 5.0]])
    x = torch.tensor([[0.5, 0.0, 0.25], [0.52, 0.01, 0.24]], requires_grad=True)
    values = prior.per_point(x, anchors, moving)
    assert prior.last_moving_counts["no_free"] == 1
    assert float(values[0].detach()) == 0.0
    values.sum().backward()
    assert torch.all(x.grad[0] == 0) and torch.any(x.grad[1] != 0)


def test_moving_filter_needs_one_anchor_per_query(c_safe):
    prior = HapPrior(c_safe)
    moving = MovingObstacleFilter(
        (Box("b", np.zeros(3), np.eye(3), np.full(3, 0.05), True),), np.zeros(3), np.zeros(3), 0.03
    )
    with pytest.raises(ValueError, match="anchors"):
        prior.loss(torch.zeros(4, 3), None, moving)
    with pytest.raises(ValueError, match="3 anchors for 4"):
        prior.loss(torch.zeros(4, 3), np.zeros((3, 3)), moving)


# ----------------------------------------------------- against the pre-rewrite implementation
def _reference_prior(*args, **kwargs):
    """The pre-rewrite prior without its offset (``subtract_offset=False``): Eq. hap_compact
    as written, what `HapPrior` computes since environment v8."""
    from _reference_hap_loss import ReferenceHapPrior

    return ReferenceHapPrior(*args, subtract_offset=False, **kwargs)


def _random_queries(rng: np.random.Generator, shape=(256, 20)) -> np.ndarray:
    """Queries of the training batch's shape (B, N_q, 3), m: on, near and far from C_safe."""
    x = rng.uniform([0.2, -0.4, 0.0], [0.8, 0.4, 0.5], (*shape, 3))
    on = grid_points()[rng.integers(0, len(grid_points()), (40, shape[1]))]
    x[:40] = on + rng.normal(0.0, 1e-4, on.shape)  # at C_safe points (not exactly: see below)
    x[40:80] += rng.uniform(-1.0, 1.0, (40, shape[1], 3))  # far outside the lookup box
    return x


def _values_and_gradient(prior, x: np.ndarray, anchors=None, moving=None, weights=None):
    """per_point values and d(sum w * values)/dx in float64."""
    leaf = torch.as_tensor(x, dtype=torch.float64).requires_grad_(True)
    values = prior.per_point(leaf, anchors, moving)
    (values * torch.as_tensor(weights)).sum().backward()
    return values.detach().numpy(), leaf.grad.numpy()


@pytest.mark.parametrize("search", ["grid", "kdtree"])
@pytest.mark.parametrize("candidates", [None, 8])
def test_soft_min_and_its_gradient_equal_the_reference(c_safe, search, candidates):
    """Without the moving filter, per-query soft-min values and their gradient w.r.t. the
    queries (weighted by a random upstream gradient) equal the pre-rewrite autograd version
    to 1e-9 in float64, for both neighbour searches, with more candidates than k (the k
    nearest are selected) and exactly k, on 256 x 20 queries on, near and far from C_safe.
    Exactly at a grid point several neighbours tie at the k-th
    distance; which of them enter is arbitrary in both (torch.topk does not specify it), so
    there only the values are compared."""
    kwargs = dict(neighbour_search=search, candidates=candidates)
    new = HapPrior(c_safe, **kwargs)
    old = _reference_prior(c_safe, **kwargs)
    rng = np.random.default_rng(1)
    x = _random_queries(rng)
    weights = rng.normal(size=x.shape[:-1])
    values, grad = _values_and_gradient(new, x, weights=weights)
    ref_values, ref_grad = _values_and_gradient(old, x, weights=weights)
    assert np.abs(ref_grad).max() > 0.1
    np.testing.assert_allclose(values, ref_values, rtol=0, atol=1e-9)
    np.testing.assert_allclose(grad, ref_grad, rtol=0, atol=1e-9)
    exact = torch.as_tensor(c_safe, dtype=torch.float64)
    np.testing.assert_allclose(new.per_point(exact), old.per_point(exact), rtol=0, atol=1e-9)


@pytest.mark.parametrize("search", ["grid", "kdtree"])
def test_moving_filter_values_gradients_and_counts_equal_the_reference(c_safe, search):
    """With a moving-obstacle filter (two boxes, anchors spread over the workspace per query),
    values, gradients and `last_moving_counts` equal the pre-rewrite version to 1e-9 in
    float64 — including queries with blocked candidates, fallback rows and rows without any
    free point (all three occur) — and, with the lookup table, for a batch where no query
    falls back."""
    shapes = (
        Box("a", np.zeros(3), np.eye(3), np.full(3, 0.06), True),
        Box("b", np.array([0.0, 0.15, 0.05]), np.eye(3), np.array([0.03, 0.05, 0.1]), True),
    )
    moving = MovingObstacleFilter(shapes, np.zeros(3), np.full(3, 0.02), margin=0.03)
    new = HapPrior(c_safe, neighbour_search=search, fallback_candidates=16)
    old = _reference_prior(c_safe, neighbour_search=search, fallback_candidates=16)
    rng = np.random.default_rng(2)
    x = _random_queries(rng)
    anchors = x + rng.normal(0.0, 0.08, x.shape)  # obstacles near most queries
    anchors[100:140] = x[100:140]  # centred on the query: many blocked
    anchors[200:] = 5.0  # far away: nothing blocked
    weights = rng.normal(size=x.shape[:-1])
    values, grad = _values_and_gradient(new, x, anchors, moving, weights)
    ref_values, ref_grad = _values_and_gradient(old, x, anchors, moving, weights)
    assert new.last_moving_counts == old.last_moving_counts
    counts = new.last_moving_counts
    assert counts["with_blocked"] > 0 and counts["fallback"] > 0 and counts["no_free"] > 0
    np.testing.assert_allclose(values, ref_values, rtol=0, atol=1e-9)
    np.testing.assert_allclose(grad, ref_grad, rtol=0, atol=1e-9)
    if search == "kdtree":
        return  # (with exactly k candidates, every row with a blocked one falls back)
    # Obstacles 0.3 m above the queries inside the lookup box: some candidates blocked, no
    # fallback (the common case in training).
    x, weights = x[80:], weights[80:]
    above = x + np.array([0.0, 0.0, 0.3])
    values, grad = _values_and_gradient(new, x, above, moving, weights)
    ref_values, ref_grad = _values_and_gradient(old, x, above, moving, weights)
    assert new.last_moving_counts == old.last_moving_counts
    assert new.last_moving_counts["with_blocked"] > 0 and new.last_moving_counts["fallback"] == 0
    np.testing.assert_allclose(values, ref_values, rtol=0, atol=1e-9)
    np.testing.assert_allclose(grad, ref_grad, rtol=0, atol=1e-9)


def test_float32_loss_agrees_with_the_reference_to_float_precision(c_safe):
    """In training's float32 the values and gradients agree with the reference to ~1e-6."""
    new, old = HapPrior(c_safe), _reference_prior(c_safe)
    x = _random_queries(np.random.default_rng(3)).astype(np.float32)
    results = []
    for prior in (new, old):
        leaf = torch.as_tensor(x).requires_grad_(True)
        loss = prior.loss(leaf)
        loss.backward()
        assert loss.dtype == leaf.grad.dtype == torch.float32
        results.append((float(loss.detach()), leaf.grad.numpy()))
    assert results[0][0] == pytest.approx(results[1][0], abs=1e-6)
    np.testing.assert_allclose(results[0][1], results[1][1], rtol=0, atol=1e-8)


def _cube_grid(step: float = 0.1, n: int = 6) -> np.ndarray:
    """A fully safe n^3 grid of C_safe points with spacing ``step`` (m)."""
    axis = np.arange(n) * step
    return np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)


def test_the_v6_hinge_is_zero_inside_c_safe_and_a_grid_step_outside_costs_about_one():
    """Environment v6–v7's variant: with ``hinge_step`` h, L_hap per query is
    max(0, softmin - c) / h, c the largest soft-min inside a safe cell: 0 with no gradient
    at the nodes and cell centres deep inside a fully safe grid (no pull towards the
    lattice), positive and growing outside, about 1 a grid step beyond the subspace's
    face, and the gradient is that of the hinged value (finite differences)."""
    from distgprl.safety.hap_loss import HapPrior

    points = _cube_grid()
    prior = HapPrior(points, k=8, temperature=0.05, hinge_step=0.1, dtype=torch.float64)
    inside = np.array([[0.2, 0.2, 0.2], [0.25, 0.25, 0.25], [0.3, 0.25, 0.2]])
    values, gradient = prior.values_and_gradient(inside)
    np.testing.assert_array_equal(values, 0.0)
    np.testing.assert_array_equal(gradient, 0.0)
    outside = np.array([[0.23, 0.31, 0.5 + 0.1 * k] for k in (1, 2, 3)])  # no kNN ties
    values, gradient = prior.values_and_gradient(outside)
    assert np.all(np.diff(values) > 0.5)  # about one per grid step
    assert 0.5 < values[0] < 1.5
    eps = 1e-6
    for axis in range(3):
        shift = np.zeros(3)
        shift[axis] = eps
        up, _ = prior.values_and_gradient(outside + shift)
        down, _ = prior.values_and_gradient(outside - shift)
        np.testing.assert_allclose(gradient[:, axis], (up - down) / (2 * eps), atol=1e-5)
    plain = HapPrior(points, k=8, temperature=0.05, dtype=torch.float64)
    assert np.abs(plain.values_and_gradient(inside)[1]).sum() > 0.01  # as written: pulls
