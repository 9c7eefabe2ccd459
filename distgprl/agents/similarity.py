"""L_sim (paper Eq. sim_compact) and its gradient in one compiled pass (issue 29).

`ActorRegulariser` reads the adapted trajectories of a batch out as one axis-major array
(6, B, 2T + N_q) (`ActorRegulariser.readout`); this kernel computes the batch mean of

    L_sim = lambda_v (1 - 1/T sum_t cos(zeta'(t), zeta'_demo(t)))
            + lambda_a / a_ref * 1/T sum_t |zeta''(t) - zeta''_demo(t)|_1

from its velocity and acceleration-error blocks, and writes the gradient of
``gradient_scale * L_sim`` w.r.t. those blocks (d cos / d v = (d_hat - cos v_hat) / |v|,
d |e| / d e = sign e), without a temporary array of the batch's size: torch's element-wise
version made about fifteen passes over them. Per sample and time, the squared norm and the dot
product are summed over the six axes in axis order (as torch's ``sum(1)`` does); the batch sums
of cos and |e| are accumulated in float64.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["similarity_with_gradient"]

NORM_FLOOR = 1e-8
"""Smallest velocity norm a cosine is divided by (torch's ``cosine_similarity`` floor)."""


@njit(cache=True, nogil=True)
def similarity_with_gradient(
    out: np.ndarray,
    direction: np.ndarray,
    count: int,
    lambda_velocity: float,
    acceleration_weight: float,
    gradient_scale: float,
    gradient: np.ndarray,
) -> float:
    """Batch-mean L_sim (Eq. sim_compact) and d (gradient_scale L_sim) / d out.

    Args:
        out: the read-out, shape (6, B, Q), dtype D: ``[:, :, :T]`` velocities (m/s, rad/s),
            ``[:, :, T:2T]`` accelerations minus the demonstration's.
        direction: the demonstration's unit velocity directions, shape (6, T), dtype D.
        count: T, the trajectory samples.
        lambda_velocity: lambda_v.
        acceleration_weight: lambda_a over the demonstration's mean L1 acceleration.
        gradient_scale: the factor of the written gradient (lambda_sim).
        gradient: shape (6, B, >= 2T), dtype D; ``[:, :, :2T]`` is overwritten.

    Returns:
        L_sim averaged over the batch (float64).
    """
    axes, batch = out.shape[0], out.shape[1]
    dtype = out.dtype
    samples = count * batch
    # per sample, over its T times: |v|^2 then factor / |v|, v . d_hat then cos / |v|
    norm = np.empty(count, dtype=dtype)
    cosine = np.empty(count, dtype=dtype)
    ratio = np.empty(count, dtype=dtype)
    floor = dtype.type(NORM_FLOOR)
    zero = dtype.type(0.0)
    factor = dtype.type(-gradient_scale * lambda_velocity / samples)
    step = dtype.type(gradient_scale * acceleration_weight / samples)
    cosine_sums = np.zeros(count)
    error_sums = np.zeros(count)
    for b in range(batch):
        for t in range(count):
            norm[t] = zero
            cosine[t] = zero
        for a in range(axes):
            for t in range(count):
                velocity = out[a, b, t]
                norm[t] += velocity * velocity
                cosine[t] += velocity * direction[a, t]
        for t in range(count):
            length = np.sqrt(norm[t])
            length = length if length > floor else floor
            value = cosine[t] / length
            cosine_sums[t] += value
            ratio[t] = value / length
            norm[t] = factor / length
        for a in range(axes):
            for t in range(count):  # (d_hat - cos v_hat) / |v|, Eq. sim_compact's cosine
                gradient[a, b, t] = (direction[a, t] - out[a, b, t] * ratio[t]) * norm[t]
            for t in range(count):  # sign of the acceleration error, its L1 term
                error = out[a, b, count + t]
                error_sums[t] += abs(error)
                gradient[a, b, count + t] = step * np.sign(error)
    cosine_total = 0.0
    error_total = 0.0
    for t in range(count):
        cosine_total += cosine_sums[t]
        error_total += error_sums[t]
    return lambda_velocity * (1.0 - cosine_total / samples) + (
        acceleration_weight * error_total / samples
    )
