"""Tests of distgprl.safety.hap_loss: the soft-min HAP prior L_hap (Eq. hap_compact)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from distgprl.safety.hap_loss import HapPrior, HapPriorConfig


def grid_points(step: float = 0.1) -> np.ndarray:
    axes = [np.arange(0.3, 0.71, step), np.arange(-0.3, 0.31, step), np.arange(0.1, 0.41, step)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


@pytest.fixture(scope="module")
def c_safe() -> np.ndarray:
    return grid_points()


@pytest.fixture(scope="module", params=["grid", "kdtree"])
def prior(request, c_safe) -> HapPrior:
    return HapPrior(c_safe, neighbour_search=request.param)


def test_loss_is_about_zero_on_the_subspace(prior, c_safe):
    """On C_safe points L_hap ~ 0 (the offset is the on-subspace soft-min)."""
    at_points = prior.per_point(torch.as_tensor(c_safe, dtype=torch.float32))
    assert torch.all(at_points.abs() < 0.01)
    assert abs(float(at_points.mean())) < 1e-4
    # The raw equation is negative there: the soft-min undercuts the nearest distance.
    raw = HapPrior(c_safe, subtract_offset=False)
    assert float(raw.loss(torch.as_tensor(c_safe, dtype=torch.float32))) < -0.01


def test_loss_tracks_the_distance_off_the_subspace(prior, c_safe):
    """Points 0.3 m above the top layer: min distance - tau log k <= L_hap + b <= min distance."""
    top = c_safe[np.isclose(c_safe[:, 2], c_safe[:, 2].max())]
    above = torch.as_tensor(top + [0.0, 0.0, 0.3], dtype=torch.float32)
    values = prior.per_point(above) + prior.offset
    lower = 0.3 - prior.temperature * np.log(prior.k)
    assert torch.all((values >= lower - 1e-6) & (values <= 0.3 + 1e-6))
    assert torch.all(values - prior.offset > 0.2)


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
