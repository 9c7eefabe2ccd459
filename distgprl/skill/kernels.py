"""Squared-exponential kernels and their maximum-likelihood fit (the GP skill's and the
covariance operator's; `distgprl.skill.gp`, `distgprl.skill.operator`).

    k(a, b) = sigma_f^2 exp(-(a - b)^2 / (2 l^2)),

with its first and second derivatives in ``a`` (analytic, for the velocity and acceleration
maps) and the negative log marginal likelihood of multi-axis data under one shared kernel,
with its gradient in the log parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import OptimizeResult, minimize

__all__ = [
    "KernelParams",
    "fit_kernel",
    "maximum_likelihood_kernel",
    "negative_log_marginal_likelihood",
    "se_kernel",
    "se_kernel_d1",
    "se_kernel_d2",
    "standardise",
]


@dataclass(frozen=True)
class KernelParams:
    """Squared-exponential kernel hyperparameters, in normalised time.

    Attributes:
        length_scale: correlation length in normalised time tau (dimensionless).
        signal_variance: prior variance of the standardised signal.
        noise_variance: observation-noise variance of the standardised signal.
    """

    length_scale: float
    signal_variance: float = 1.0
    noise_variance: float = 1e-6


def se_kernel(
    a: np.ndarray, b: np.ndarray, length_scale: float, variance: float = 1.0
) -> np.ndarray:
    """k(a, b), shape (len(a), len(b))."""
    diff = a[:, None] - b[None, :]
    k: np.ndarray = variance * np.exp(-0.5 * (diff / length_scale) ** 2)
    return k


def se_kernel_d1(
    a: np.ndarray, b: np.ndarray, length_scale: float, variance: float = 1.0
) -> np.ndarray:
    """d k(a, b) / d a, shape (len(a), len(b))."""
    diff = a[:, None] - b[None, :]
    d1: np.ndarray = -diff / length_scale**2 * se_kernel(a, b, length_scale, variance)
    return d1


def se_kernel_d2(
    a: np.ndarray, b: np.ndarray, length_scale: float, variance: float = 1.0
) -> np.ndarray:
    """d^2 k(a, b) / d a^2, shape (len(a), len(b))."""
    diff = a[:, None] - b[None, :]
    l2 = length_scale**2
    d2: np.ndarray = (diff**2 / l2**2 - 1.0 / l2) * se_kernel(a, b, length_scale, variance)
    return d2


def negative_log_marginal_likelihood(
    log_params: np.ndarray, tau: np.ndarray, y: np.ndarray
) -> tuple[float, np.ndarray]:
    """Sum over axes of -log p(y_axis | tau, theta) and its gradient w.r.t. log params."""
    length_scale, signal_variance, noise_variance = np.exp(log_params)
    n, n_axes = y.shape
    base = se_kernel(tau, tau, length_scale, 1.0)
    k_signal = signal_variance * base
    k = k_signal + noise_variance * np.eye(n)
    try:
        factor = cho_factor(k, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        return 1e12, np.zeros(3)
    alpha = cho_solve(factor, y, check_finite=False)  # (n, axes)
    log_det = 2.0 * np.sum(np.log(np.diag(factor[0])))
    nll = 0.5 * np.sum(y * alpha) + 0.5 * n_axes * log_det + 0.5 * n * n_axes * np.log(2 * np.pi)
    # d nll / d theta = -0.5 tr((alpha alpha^T - axes K^-1) dK/dtheta), summed over axes.
    inner = alpha @ alpha.T - n_axes * cho_solve(factor, np.eye(n), check_finite=False)
    diff2 = (tau[:, None] - tau[None, :]) ** 2
    d_length = k_signal * diff2 / length_scale**2  # dK / dlog(l)
    d_signal = k_signal  # dK / dlog(sf2)
    d_noise = noise_variance * np.eye(n)  # dK / dlog(sn2)
    grad = np.array([-0.5 * np.sum(inner * d) for d in (d_length, d_signal, d_noise)])
    return nll, grad


def fit_kernel(
    tau: np.ndarray,
    values: np.ndarray,
    length_scale_bounds: tuple[float, float] = (1e-3, 2.0),
    min_noise_variance: float = 1e-8,
) -> KernelParams:
    """Fit shared SE hyperparameters to standardised multi-axis data by marginal likelihood.

    Args:
        tau: shape (n,), normalised times in [0, 1].
        values: shape (n, d); each axis is standardised (zero mean, unit std) before fitting.
        length_scale_bounds: (min, max) length scale, normalised time.
        min_noise_variance: jitter floor for the standardised noise variance (it also
            bounds how strongly a via-point change can overshoot between via-points).

    Returns:
        The maximum-likelihood `KernelParams` (for the standardised signal).
    """
    y = standardise(values)[0]
    return maximum_likelihood_kernel(
        tau, y, length_scale_bounds, (1e-2, 1e3), 1.0, min_noise_variance
    )


def maximum_likelihood_kernel(
    tau: np.ndarray,
    y: np.ndarray,
    length_scale_bounds: tuple[float, float],
    signal_variance_bounds: tuple[float, float],
    start_variance: float,
    min_noise_variance: float,
) -> KernelParams:
    """The SE hyperparameters maximising the marginal likelihood of ``y`` (n, d) at ``tau``
    (n,) under one shared kernel, by L-BFGS-B from four starts across the length-scale range
    (the likelihood is multimodal), the signal variance started at ``start_variance``."""
    lo, hi = length_scale_bounds
    best: OptimizeResult | None = None
    for start_length in np.geomspace(max(lo, 1e-3), hi, 4):
        x0 = np.log([start_length, start_variance, max(1e-4, min_noise_variance)])
        result = minimize(
            negative_log_marginal_likelihood,
            x0,
            args=(tau, y),
            jac=True,
            method="L-BFGS-B",
            bounds=[
                (np.log(lo), np.log(hi)),
                tuple(np.log(signal_variance_bounds)),
                (np.log(min_noise_variance), np.log(1.0)),
            ],
        )
        if best is None or result.fun < best.fun:
            best = result
    assert best is not None  # the four starts above
    length_scale, signal_variance, noise_variance = np.exp(best.x)
    return KernelParams(float(length_scale), float(signal_variance), float(noise_variance))


def standardise(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-axis (values - mean) / std; returns (standardised, mean, std); std floored at 1e-9."""
    mean = values.mean(axis=0)
    std = np.maximum(values.std(axis=0), 1e-9)
    return (values - mean) / std, mean, std
