"""The covariance operator's K read as the paper's zero-mean GP (Eq. 1).

The paper's skill is a GP ζ(t) ~ GP(0, k) (Eq. 1), and K_tt in S = K_tt (K_tt + λI)⁻¹
(Eq. global_S) is "the covariance matrix" of that GP at the via-point times. So, per axis a,
K_a = σ_a² R(ℓ_a) with σ_a², ℓ_a and the noise fitted by maximum marginal likelihood to the
*raw* demonstration samples of that axis (m, rad), with zero mean: not mean-centred, not
standardised, not one variance shared with the other axes (docs/findings/protocol.md,
rule 3). An axis the demonstration keeps constant (the tool's rotation vector: 0 throughout)
has no signal of its own, and its ML variance collapses to the lower bound, which would make
S_a = 0 (no adaptation on that axis at all); such an axis takes K_a = s² R(ℓ_skill), s its
physical scale (`CONSTANT_AXIS_SCALE`) and ℓ_skill the skill's fitted length scale.

`fit_zero_mean_axes` fits the six axes (called by `distgprl.skill.gp.fit_skill`, stored on
the skill as ``axis_kernels``); `axis_operator` builds S_a; `row_gains` is a window
operator's one-step reach per unit action (the row sums of |S_W|).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from distgprl.skill.kernels import KernelParams, maximum_likelihood_kernel
from distgprl.skill.portable import correlation_operator, kernel_matrix

__all__ = [
    "CONSTANT_AXIS_SCALE",
    "axis_operator",
    "fit_zero_mean_axes",
    "row_gain_diagonal",
    "row_gains",
    "row_normalised",
]

CONSTANT_AXIS_SCALE = np.array([0.05, 0.05, 0.05, 0.2, 0.2, 0.2])
"""Physical scale (m, m, m, rad, rad, rad) of an axis the demonstration keeps constant: the
prior standard deviation its K takes (the observation floor)."""

MIN_SIGNAL_VARIANCE = 1e-8
"""Lower bound of the zero-mean fit's signal variance (m², rad²). A fit that ends within a
factor 10 of it found no signal: the axis is treated as constant."""


def _fit_axis(
    tau: np.ndarray, values: np.ndarray, bounds: tuple[float, float], min_noise: float
) -> KernelParams:
    """Zero-mean SE hyperparameters of one axis ``values`` (n,) at ``tau`` (n,) by ML."""
    y = np.asarray(values, dtype=float)[:, None]
    start_variance = max(float(np.mean(y**2)), 1e-4)
    # The jitter floor relative to the signal's mean square, as the skill fit's is relative
    # to its standardised unit variance: an absolute 1e-10 makes K numerically singular.
    return maximum_likelihood_kernel(
        tau, y, bounds, (MIN_SIGNAL_VARIANCE, 1e3), start_variance, min_noise * start_variance
    )


def fit_zero_mean_axes(
    tau: np.ndarray,
    poses: np.ndarray,
    length_scale_bounds: tuple[float, float],
    skill_length_scale: float,
    min_noise_variance: float = 1e-6,
) -> tuple[KernelParams, ...]:
    """Per axis, the zero-mean GP's kernel (module docstring), six `KernelParams`.

    Args:
        tau: (n,) normalised times of the demonstration samples.
        poses: (n, 6) raw samples, m and rad.
        length_scale_bounds: (min, max) length scale, normalised time (the skill fit's).
        skill_length_scale: the skill's fitted length scale, for constant axes.
        min_noise_variance: lower bound of the noise variance, relative to the axis's mean
            square (the skill fit's default jitter, 1e-6).

    Returns:
        Six kernels; a constant axis gets (skill_length_scale, `CONSTANT_AXIS_SCALE`², 0).
    """
    kernels = []
    for axis in range(6):
        column = np.asarray(poses, dtype=float)[:, axis]
        if np.ptp(column) <= 1e-12:
            fitted = None
        else:
            fitted = _fit_axis(tau, column, length_scale_bounds, min_noise_variance)
        if fitted is None or fitted.signal_variance <= 10.0 * MIN_SIGNAL_VARIANCE:
            scale = float(CONSTANT_AXIS_SCALE[axis])
            fitted = KernelParams(float(skill_length_scale), scale**2, 0.0)
        kernels.append(fitted)
    return tuple(kernels)


def axis_operator(
    via_times: np.ndarray, kernel: KernelParams, correlation_lambda: float
) -> np.ndarray:
    """S_a = K_a (K_a + λ I)⁻¹ at the via-point times (N, N), K_a = σ_a² R(ℓ_a) (Eq. global_S);
    symmetric, eigenvalues μ / (μ + λ) in (0, 1); CPU-independent (`distgprl.skill.portable`)."""
    k = kernel_matrix(via_times, kernel.length_scale, kernel.signal_variance)
    return correlation_operator(k, correlation_lambda)  # the same bits on every CPU


def row_gains(operator: np.ndarray) -> np.ndarray:
    """One-step reach per unit raw action of each row's via-point: Σ_j |S_ij|, shape (L,) for
    an (L, L) operator, or (..., L) for a stack (the largest change a raw action in [-1, 1]^L
    can make to that via-point)."""
    gains: np.ndarray = np.abs(np.asarray(operator)).sum(axis=-1)
    return gains


def row_normalised(operator: np.ndarray) -> np.ndarray:
    """The operator with each row divided by its row gain (`row_gains`): every via-point's
    reach equals the action scale, the correlation between neighbours is kept (the
    ``operator-correlation`` study reading: the transform without its shrink)."""
    operator = np.asarray(operator, dtype=float)
    normalised: np.ndarray = operator / row_gains(operator)[..., :, None]
    return normalised


def row_gain_diagonal(operator: np.ndarray) -> np.ndarray:
    """The diagonal matrix of the operator's row gains (`row_gains`): every via-point keeps
    its reach and moves with its own action only — the coupling between neighbours removed
    (the ``operator-signal-uncoupled`` control: the signal reading's reach without its
    coupling). Shape as ``operator``, (..., L, L)."""
    operator = np.asarray(operator, dtype=float)
    diagonal: np.ndarray = np.eye(operator.shape[-1]) * row_gains(operator)[..., :, None]
    return diagonal


def window_blocks(operator: np.ndarray, windows: Sequence[Sequence[int]]) -> list[np.ndarray]:
    """The principal sub-blocks S_W of an (N, N) operator for each window's indices."""
    return [operator[np.ix_(list(w), list(w))].copy() for w in windows]
