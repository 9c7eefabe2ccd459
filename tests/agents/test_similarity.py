"""Tests of distgprl.agents.similarity: L_sim (Eq. sim_compact) and its gradient in one pass.

The kernel is checked against the equation written with torch operations and differentiated
by autograd (float64, random read-outs of the training shapes), at a velocity below the
norm floor, and by a finite-difference check of the gradient.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from distgprl.agents.similarity import NORM_FLOOR, similarity_with_gradient

AXES, BATCH, T, N_Q = 6, 32, 50, 20
WEIGHTS = {"lambda_velocity": 0.7, "acceleration_weight": 0.3, "gradient_scale": 2.0}


def _equation(out: torch.Tensor, direction: torch.Tensor) -> torch.Tensor:
    """Batch-mean L_sim from an axis-major read-out (6, B, Q), as torch operations."""
    velocity, error = out[:, :, :T], out[:, :, T : 2 * T]
    norm = velocity.square().sum(0).sqrt().clamp_min(NORM_FLOOR)
    cos = (velocity * direction[:, None, :]).sum(0) / norm
    return (
        WEIGHTS["lambda_velocity"] * (1.0 - cos.mean())
        + WEIGHTS["acceleration_weight"] * error.abs().sum(0).mean()
    )


def _case(rng: np.random.Generator, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    out = rng.normal(size=(AXES, BATCH, 2 * T + N_Q)).astype(dtype)
    direction = rng.normal(size=(AXES, T))
    direction /= np.linalg.norm(direction, axis=0)
    return out, direction.astype(dtype)


def _kernel(out: np.ndarray, direction: np.ndarray) -> tuple[float, np.ndarray]:
    gradient = np.full(out.shape, 7.0, dtype=out.dtype)  # the kernel overwrites [:, :, :2T]
    value = similarity_with_gradient(
        out, direction, T, WEIGHTS["lambda_velocity"], WEIGHTS["acceleration_weight"],
        WEIGHTS["gradient_scale"], gradient,
    )  # fmt: skip
    return value, gradient


def test_value_and_gradient_equal_the_equation_under_autograd():
    """Value to 1e-12 and gradient of gradient_scale * L_sim to 1e-15 (float64); the
    columns after 2T (the L_hap positions) are left as they were."""
    out, direction = _case(np.random.default_rng(0))
    value, gradient = _kernel(out, direction)
    tensor = torch.tensor(out, requires_grad=True)
    expected = _equation(tensor, torch.tensor(direction))
    (WEIGHTS["gradient_scale"] * expected).backward()
    assert value == pytest.approx(float(expected.detach()), abs=1e-12)
    np.testing.assert_allclose(
        gradient[:, :, : 2 * T], tensor.grad[:, :, : 2 * T].numpy(), rtol=0, atol=1e-15
    )
    assert np.all(gradient[:, :, 2 * T :] == 7.0)


def test_a_velocity_under_the_floor_is_divided_by_the_floor():
    """A zero velocity has cos 0 (torch's cosine_similarity convention) and the gradient
    d_hat / floor (times the weights), finite."""
    out, direction = _case(np.random.default_rng(1))
    out[:, 3, 5] = 0.0
    value, gradient = _kernel(out, direction)
    tensor = torch.tensor(out, requires_grad=True)
    expected = _equation(tensor, torch.tensor(direction))
    (WEIGHTS["gradient_scale"] * expected).backward()
    assert value == pytest.approx(float(expected.detach()), abs=1e-12)
    scale = -WEIGHTS["gradient_scale"] * WEIGHTS["lambda_velocity"] / (T * BATCH)
    np.testing.assert_allclose(gradient[:, 3, 5], direction[:, 5] * scale / NORM_FLOOR, rtol=1e-12)
    assert np.all(np.isfinite(gradient))


def test_gradient_matches_finite_differences():
    """Central differences of the value along random directions (velocity block: the L1
    block is piecewise linear, exact away from its kinks)."""
    rng = np.random.default_rng(2)
    out, direction = _case(rng)
    _, gradient = _kernel(out, direction)
    for _ in range(5):
        step = np.zeros_like(out)
        step[:, :, : 2 * T] = rng.normal(size=(AXES, BATCH, 2 * T))
        h = 1e-6
        plus, _ = _kernel(out + h * step, direction)
        minus, _ = _kernel(out - h * step, direction)
        numeric = WEIGHTS["gradient_scale"] * (plus - minus) / (2 * h)
        assert np.sum(gradient * step) == pytest.approx(numeric, rel=1e-6)


def test_float32_agrees_with_float64_to_float_precision():
    out, direction = _case(np.random.default_rng(3))
    value64, gradient64 = _kernel(out, direction)
    value32, gradient32 = _kernel(out.astype(np.float32), direction.astype(np.float32))
    assert gradient32.dtype == np.float32
    assert value32 == pytest.approx(value64, rel=1e-6)
    scale = np.abs(gradient64[:, :, : 2 * T]).max()
    np.testing.assert_allclose(gradient32, gradient64, rtol=0, atol=1e-5 * scale)
