"""The zero-mean GP reading of K in S (distgprl/skill/operator.py; environment v6)."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.skill.kernels import KernelParams, negative_log_marginal_likelihood
from distgprl.skill.operator import (
    CONSTANT_AXIS_SCALE,
    axis_operator,
    fit_zero_mean_axes,
    row_gain_diagonal,
    row_gains,
    row_normalised,
)

TAU = np.linspace(0.0, 1.0, 200)
BOUNDS = (0.5 / 14, 2.0)


def demonstration(offset: float = 0.5, amplitude: float = 0.1) -> np.ndarray:
    """Poses (200, 6): x = offset + amplitude sin(2 pi tau), y a ramp, z constant 0.1,
    rotations constant 0 (as the shipped demonstrations)."""
    poses = np.zeros((len(TAU), 6))
    poses[:, 0] = offset + amplitude * np.sin(2 * np.pi * TAU)
    poses[:, 1] = -0.2 + 0.4 * TAU
    poses[:, 2] = 0.1
    return poses


def test_the_fit_is_zero_mean_maximum_likelihood_on_the_raw_values():
    """The fitted x kernel is a (local) maximum of the zero-mean likelihood of the raw x
    samples: perturbing any log-parameter lowers it. Moving the signal away from 0 raises its
    fitted variance (zero mean, not centred), which a standardised fit would not see."""
    poses = demonstration()
    kernels = fit_zero_mean_axes(TAU, poses, BOUNDS, skill_length_scale=0.06)
    x = kernels[0]
    best = np.log([x.length_scale, x.signal_variance, x.noise_variance])
    nll = negative_log_marginal_likelihood(best, TAU, poses[:, [0]])[0]
    for index in range(2):  # the noise sits on its bound, the other two are interior
        for step in (-0.2, 0.2):
            probe = best.copy()
            probe[index] += step
            assert negative_log_marginal_likelihood(probe, TAU, poses[:, [0]])[0] > nll
    far = fit_zero_mean_axes(TAU, demonstration(offset=2.0), BOUNDS, skill_length_scale=0.06)
    assert far[0].signal_variance > 4 * x.signal_variance


def test_constant_axes_take_their_physical_scale_and_the_skill_length_scale():
    """An axis the demonstration keeps constant (the rotations) gets K = s^2 R(l_skill), s its
    physical scale, instead of a collapsed variance that would make S_a = 0."""
    kernels = fit_zero_mean_axes(TAU, demonstration(), BOUNDS, skill_length_scale=0.06)
    for axis in (3, 4, 5):
        assert kernels[axis] == KernelParams(0.06, float(CONSTANT_AXIS_SCALE[axis]) ** 2, 0.0)
    # a constant non-zero axis (z = 0.1) has signal: a zero-mean GP explains its level
    assert kernels[2].signal_variance > 10 * 1e-8


def test_axis_operator_is_k_over_k_plus_lambda():
    """S = K (K + lambda I)^-1 (Eq. global_S), symmetric, eigenvalues mu / (mu + lambda)."""
    via = np.linspace(0, 1, 15)
    kernel = KernelParams(0.06, 0.05, 1e-10)
    operator = axis_operator(via, kernel, 1e-2)
    k = 0.05 * np.exp(-0.5 * ((via[:, None] - via[None, :]) / 0.06) ** 2)
    np.testing.assert_allclose(operator, k @ np.linalg.inv(k + 1e-2 * np.eye(15)), atol=1e-10)
    mu = np.linalg.eigvalsh(k)
    np.testing.assert_allclose(np.linalg.eigvalsh(operator), np.sort(mu / (mu + 1e-2)), atol=1e-9)
    with pytest.raises(ValueError):
        axis_operator(via, kernel, 0.0)


def test_row_gains_bound_every_action_and_row_normalising_makes_them_one():
    """No action in [-1, 1]^L moves via-point i by more than its row gain, and the action
    sign(S_i) reaches it; the row-normalised operator has every gain 1."""
    via = np.linspace(0, 1, 15)
    operator = axis_operator(via, KernelParams(0.06, 0.02, 1e-10), 1e-2)[1:6, 1:6]
    gains = row_gains(operator)
    rng = np.random.default_rng(0)
    moves = np.abs(operator @ rng.uniform(-1, 1, (5, 2000)))
    assert np.all(moves.max(axis=1) <= gains + 1e-12)
    for i in range(5):
        assert (operator @ np.sign(operator[i]))[i] == pytest.approx(gains[i])
    np.testing.assert_allclose(row_gains(row_normalised(operator)), 1.0)


def test_the_row_gain_diagonal_keeps_each_reach_and_drops_the_coupling():
    """``signal-uncoupled``'s transform: a diagonal matrix (no via-point moves with another's
    action) whose row gains, and so every via-point's reach, are the operator's; per block of
    a stack."""
    via = np.linspace(0, 1, 15)
    blocks = np.stack(
        [
            axis_operator(via, KernelParams(length, variance, 1e-10), 1e-2)[1:6, 1:6]
            for length, variance in ((0.06, 0.02), (0.04, 0.005))
        ]
    )
    assert np.abs(blocks - np.diagonal(blocks, axis1=-2, axis2=-1)[..., None] * np.eye(5)).max() > 0
    diagonal = row_gain_diagonal(blocks)
    assert diagonal.shape == blocks.shape
    np.testing.assert_allclose(row_gains(diagonal), row_gains(blocks), rtol=1e-12)
    np.testing.assert_array_equal(diagonal * (1 - np.eye(5)), 0.0)
    np.testing.assert_allclose(np.diagonal(diagonal, axis1=-2, axis2=-1), row_gains(blocks))
