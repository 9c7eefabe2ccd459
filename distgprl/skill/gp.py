"""The GP via-point skill model (paper §III-A, §IV-A; DESIGN §2).

A demonstration is modelled by six independent Gaussian processes (x, y, z, rx, ry, rz)
over normalised time tau in [0, 1] that share one squared-exponential kernel

    k(a, b) = sigma_f^2 exp(-(a - b)^2 / (2 l^2)).

The kernel's length scale ``l``, signal variance and noise variance are fitted to the
demonstration by maximising the marginal likelihood (summed over the six axes, each
axis standardised first). The skill is then the posterior mean conditioned on N
via-points Gamma (N, 6) at evenly spaced times (Eq. gp_param):

    zeta(tau) = mu + k_v(tau) [K_vv + sigma_y^2 I]^{-1} (Gamma - mu),

with a constant per-axis prior mean ``mu`` (the demonstration's mean), which keeps the
trajectory well behaved between via-points. Position, velocity and acceleration at any
query times are therefore affine maps of Gamma; this module precomputes the matrices
``M``, ``dM``, ``ddM`` (analytic kernel derivatives) so that

    position     = mu + M   (Gamma - mu)         # m, rad
    velocity     =      dM  (Gamma - mu)         # m/s, rad/s
    acceleration =      ddM (Gamma - mu)         # m/s^2, rad/s^2

The correlation operator S = K (K + lambda I)^{-1} (Eq. global_S): `correlation_operator`
builds it from the kernel's unit-variance correlation matrix (study preset ``operator-unit``),
and `axis_window_operators` per axis at a given prior variance (``operator-signal``); Table I's
operator takes K from the zero-mean GP of Eq. 1 fitted per axis to the raw demonstration
(``axis_kernels``, `distgprl.skill.operator`). `distgprl.adaptation.layout.window_operators`
chooses between them (docs/findings/protocol.md, rule 3).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from distgprl.skill.demos import Demonstration
from distgprl.skill.kernels import (
    KernelParams,
    fit_kernel,
    se_kernel,
    se_kernel_d1,
    se_kernel_d2,
    standardise,
)
from distgprl.skill.operator import fit_zero_mean_axes
from distgprl.skill.portable import correlation_operator as portable_operator
from distgprl.skill.portable import kernel_matrix

N_AXES = 6
DEFAULT_N_VIA_POINTS = 15
DEFAULT_CORRELATION_LAMBDA = 1e-2


@dataclass(frozen=True)
class FitConfig:
    """How `fit_skill` fits the kernel and places the via-points.

    Attributes:
        n_via_points: number of via-points N (paper: 15).
        max_fit_samples: demonstration samples used for the marginal-likelihood fit
            (evenly subsampled; the fit is O(n^3)).
        min_length_scale_fraction: lower bound of the length scale as a fraction of the
            via-point spacing (a length scale far below the spacing cannot be
            represented by N via-points).
        max_length_scale: upper bound of the length scale (normalised time).
        min_noise_variance: lower bound of the standardised noise variance (jitter).
    """

    n_via_points: int = DEFAULT_N_VIA_POINTS
    max_fit_samples: int = 300
    min_length_scale_fraction: float = 0.5
    max_length_scale: float = 2.0
    min_noise_variance: float = 1e-6


@dataclass(frozen=True)
class GPSkill:
    """A fitted via-point skill: kernel, via-point times, demonstration via-points.

    Attributes:
        kernel: fitted `KernelParams` (standardised signal).
        via_times: shape (N,), normalised times of the via-points in [0, 1].
        via_points: shape (N, 6), the demonstration's via-points Gamma_0, m and rad.
        prior_mean: shape (6,), constant prior mean per axis, m and rad.
        duration: trajectory duration in seconds (tau = t / duration).
        name: skill name.
        axis_scale: shape (6,), the demonstration's standard deviation per axis (m, rad):
            the scale by which each axis was standardised for the kernel fit, so the GP's
            covariance of axis a in via-point units is ``axis_scale[a]**2 * K`` (None for a
            skill saved before it was recorded).
        axis_kernels: six `KernelParams`, the paper's zero-mean GP of each axis fitted to the
            raw demonstration (`distgprl.skill.operator`; Table I's K of S, m² and
            rad²); None for a skill saved before they were recorded.
    """

    kernel: KernelParams
    via_times: np.ndarray
    via_points: np.ndarray
    prior_mean: np.ndarray
    duration: float
    name: str = "skill"
    axis_scale: np.ndarray | None = None
    axis_kernels: tuple[KernelParams, ...] | None = None
    _cache: dict[tuple[str, float, float], np.ndarray] = field(
        default_factory=dict, repr=False, compare=False
    )

    @property
    def n_via_points(self) -> int:
        return int(self.via_times.shape[0])

    # -- linear maps -----------------------------------------------------------------------
    @cached_property
    def _inverse_gram(self) -> np.ndarray:
        """[K_vv + sigma_y^2 I]^{-1}, shape (N, N) (Eq. gp_param)."""
        k = self.kernel
        gram = se_kernel(self.via_times, self.via_times, k.length_scale, k.signal_variance)
        gram = gram + k.noise_variance * np.eye(self.n_via_points)
        return cho_solve(cho_factor(gram, lower=True), np.eye(self.n_via_points))

    def position_map(self, tau: np.ndarray) -> np.ndarray:
        """M, shape (m, N): position(tau) = mu + M (Gamma - mu)."""
        k = self.kernel
        cross = se_kernel(np.asarray(tau, float), self.via_times, k.length_scale, k.signal_variance)
        position: np.ndarray = cross @ self._inverse_gram
        return position

    def velocity_map(self, tau: np.ndarray) -> np.ndarray:
        """dM, shape (m, N): velocity(tau) = dM (Gamma - mu), per second."""
        k = self.kernel
        cross = se_kernel_d1(
            np.asarray(tau, float), self.via_times, k.length_scale, k.signal_variance
        )
        velocity: np.ndarray = cross @ self._inverse_gram / self.duration
        return velocity

    def acceleration_map(self, tau: np.ndarray) -> np.ndarray:
        """ddM, shape (m, N): acceleration(tau) = ddM (Gamma - mu), per second squared."""
        k = self.kernel
        cross = se_kernel_d2(
            np.asarray(tau, float), self.via_times, k.length_scale, k.signal_variance
        )
        acceleration: np.ndarray = cross @ self._inverse_gram / self.duration**2
        return acceleration

    def maps(self, tau: np.ndarray) -> TrajectoryMaps:
        """All three maps at the query times, bundled for repeated evaluation."""
        tau = np.asarray(tau, dtype=float)
        return TrajectoryMaps(
            tau=tau,
            position=self.position_map(tau),
            velocity=self.velocity_map(tau),
            acceleration=self.acceleration_map(tau),
            prior_mean=self.prior_mean,
        )

    # -- evaluation -------------------------------------------------------------------------
    def position(self, via_points: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Trajectory poses at ``tau`` for via-points (N, 6): shape (m, 6), m and rad."""
        poses: np.ndarray = self.prior_mean + self.position_map(tau) @ (
            via_points - self.prior_mean
        )
        return poses

    def velocity(self, via_points: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Velocities at ``tau``: shape (m, 6), m/s and rad/s."""
        velocities: np.ndarray = self.velocity_map(tau) @ (via_points - self.prior_mean)
        return velocities

    def acceleration(self, via_points: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Accelerations at ``tau``: shape (m, 6), m/s^2 and rad/s^2."""
        accelerations: np.ndarray = self.acceleration_map(tau) @ (via_points - self.prior_mean)
        return accelerations

    # -- correlation operator ---------------------------------------------------------------
    def correlation_operator(
        self,
        correlation_lambda: float = DEFAULT_CORRELATION_LAMBDA,
        length_scale: float | None = None,
    ) -> np.ndarray:
        """S = K (K + lambda I)^{-1}, shape (N, N) (Eq. global_S).

        K is the kernel's correlation matrix (unit variance) at the via-point times, so
        S is symmetric with eigenvalues mu / (mu + lambda) in (0, 1), computed with
        `distgprl.skill.portable` (the same bits on every CPU). ``length_scale`` (normalised
        time) replaces the fitted one in K only; None = the fitted one.
        """
        length_scale = self.kernel.length_scale if length_scale is None else length_scale
        key = ("S", float(correlation_lambda), float(length_scale))
        if key not in self._cache:
            if correlation_lambda <= 0:
                raise ValueError("correlation_lambda must be > 0")
            if length_scale <= 0:
                raise ValueError("length_scale must be > 0")
            corr = kernel_matrix(self.via_times, length_scale)
            # I - lambda (K + lambda I)^{-1}, symmetrised, the same bits on every CPU.
            self._cache[key] = portable_operator(corr, correlation_lambda)
        return self._cache[key]

    def window_operator(
        self,
        indices: Sequence[int] | np.ndarray,
        correlation_lambda: float = DEFAULT_CORRELATION_LAMBDA,
        length_scale: float | None = None,
    ) -> np.ndarray:
        """Principal sub-block S_W, shape (L, L), for the via-point indices of a window
        (``length_scale``: as in `correlation_operator`)."""
        idx = np.asarray(indices, dtype=int)
        operator = self.correlation_operator(correlation_lambda, length_scale)
        block: np.ndarray = operator[np.ix_(idx, idx)].copy()
        return block

    def signal_variance_per_axis(self, axis_floor: np.ndarray) -> np.ndarray:
        """The GP prior variance of each axis in via-point units, shape (6,), m^2 / rad^2.

        The kernel was fitted to the standardised signal, so axis a's covariance matrix is
        ``sigma_f^2 s_a^2 R`` (Eq. 2's K_tt in the via-points' units) with s_a the axis's
        demonstration std. An axis the demonstration keeps constant (s_a = 0, e.g. the tool
        orientation) has no scale of its own; s_a is floored at ``axis_floor`` (6,), the
        physical scale an axis is measured in (the env's observation floor).
        """
        if self.axis_scale is None:
            raise ValueError(
                f"skill {self.name!r} has no axis_scale (saved before it was recorded); refit it"
            )
        scale = np.maximum(np.asarray(self.axis_scale, dtype=float), axis_floor)
        variance: np.ndarray = self.kernel.signal_variance * scale**2
        return variance

    def axis_window_operators(
        self,
        indices: Sequence[int] | np.ndarray,
        correlation_lambda: float,
        axis_variance: np.ndarray,
        length_scale: float | None = None,
    ) -> np.ndarray:
        """S_W per axis, shape (6, L, L), for K_a = v_a R (Eq. global_S with Eq. 2's scale).

        S_a = v_a R (v_a R + lambda I)^{-1} = R (R + (lambda / v_a) I)^{-1}: the unit-variance
        operator at lambda / v_a. With v_a of the order of lambda the eigenvalues spread over
        (0, 1): lambda then "controls the strength of action correlation", as the paper says.
        """
        variance = np.asarray(axis_variance, dtype=float)
        if variance.shape != (6,) or np.any(variance <= 0):
            raise ValueError(f"axis_variance must be 6 positive values, got {variance}")
        return np.stack(
            [self.window_operator(indices, correlation_lambda / v, length_scale) for v in variance]
        )

    # -- task conditioning -----------------------------------------------------------------
    def nearest_via_index(self, tau: float) -> int:
        """Index of the via-point nearest to normalised time ``tau``."""
        return int(np.argmin(np.abs(self.via_times - tau)))

    def condition_on_offset(
        self,
        offset: np.ndarray,
        first_index: int,
        last_index: int | None = None,
        via_points: np.ndarray | None = None,
    ) -> np.ndarray:
        """Via-points conditioned on a task configuration (DESIGN §2).

        The interaction via-point ``first_index`` and its successors up to ``last_index``
        (inclusive; default the last via-point) are translated by the object offset.

        Args:
            offset: shape (3,) position offset in m (or (6,) to also offset rotation).
            first_index: index of the interaction via-point.
            last_index: last shifted index (inclusive), default N - 1.
            via_points: via-points to condition, default the demonstration's.

        Returns:
            Conditioned via-points, shape (N, 6).
        """
        gamma = (self.via_points if via_points is None else via_points).copy()
        last = self.n_via_points - 1 if last_index is None else last_index
        if not 0 <= first_index <= last < self.n_via_points:
            raise ValueError(f"invalid via-point range {first_index}..{last}")
        offset = np.asarray(offset, dtype=float)
        gamma[first_index : last + 1, : offset.shape[0]] += offset
        return gamma

    # -- serialisation ---------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kernel": {
                "length_scale": self.kernel.length_scale,
                "signal_variance": self.kernel.signal_variance,
                "noise_variance": self.kernel.noise_variance,
            },
            "duration_s": self.duration,
            "via_times": self.via_times.tolist(),
            "via_points": self.via_points.tolist(),
            "prior_mean": self.prior_mean.tolist(),
            **(
                {}
                if self.axis_scale is None
                else {"axis_scale": np.asarray(self.axis_scale).tolist()}
            ),
            **(
                {}
                if self.axis_kernels is None
                else {"axis_kernels": [asdict(k) for k in self.axis_kernels]}
            ),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GPSkill:
        return cls(
            kernel=KernelParams(**data["kernel"]),
            via_times=np.asarray(data["via_times"], dtype=float),
            via_points=np.asarray(data["via_points"], dtype=float),
            prior_mean=np.asarray(data["prior_mean"], dtype=float),
            duration=float(data["duration_s"]),
            name=data.get("name", "skill"),
            axis_scale=(
                None if "axis_scale" not in data else np.asarray(data["axis_scale"], dtype=float)
            ),
            axis_kernels=(
                tuple(KernelParams(**k) for k in data["axis_kernels"])
                if "axis_kernels" in data
                else None
            ),
        )


@dataclass(frozen=True)
class TrajectoryMaps:
    """Precomputed maps at fixed query times; shapes (m, N). See `GPSkill.maps`."""

    tau: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    prior_mean: np.ndarray

    def positions(self, via_points: np.ndarray) -> np.ndarray:
        """(m, 6) poses for via-points (N, 6)."""
        poses: np.ndarray = self.prior_mean + self.position @ (via_points - self.prior_mean)
        return poses


def fit_skill(demo: Demonstration, config: FitConfig | None = None) -> GPSkill:
    """Fit the GP skill to a demonstration (DESIGN §2).

    1. Standardise each axis and fit the shared kernel by marginal likelihood on at most
       ``config.max_fit_samples`` evenly subsampled samples.
    2. Via-points Gamma_0 = GP posterior mean of the demonstration at N evenly spaced tau.
    3. Per axis, the zero-mean GP of Eq. 1 on the raw samples (``axis_kernels``, the K of
       Table I's S; `distgprl.skill.operator.fit_zero_mean_axes`).

    Raises:
        ValueError: if the demonstration has fewer samples than via-points.
    """
    config = config or FitConfig()
    n_via = config.n_via_points
    if n_via < 2:
        raise ValueError("n_via_points must be >= 2")
    if demo.poses.shape[0] < n_via:
        raise ValueError(
            f"demonstration has {demo.poses.shape[0]} samples, fewer than {n_via} via-points"
        )
    tau = demo.normalised_times
    poses = demo.poses
    step = max(1, int(np.ceil(len(tau) / config.max_fit_samples)))
    sub = np.unique(np.r_[np.arange(0, len(tau), step), len(tau) - 1])
    spacing = 1.0 / (n_via - 1)
    bounds = (config.min_length_scale_fraction * spacing, config.max_length_scale)
    kernel = fit_kernel(
        tau[sub],
        poses[sub],
        length_scale_bounds=bounds,
        min_noise_variance=config.min_noise_variance,
    )
    standardised, mean, std = standardise(poses[sub])
    via_times = np.linspace(0.0, 1.0, n_via)
    # Posterior mean of the dense (subsampled) demonstration at the via-point times.
    gram = se_kernel(tau[sub], tau[sub], kernel.length_scale, kernel.signal_variance)
    gram += kernel.noise_variance * np.eye(len(sub))
    cross = se_kernel(via_times, tau[sub], kernel.length_scale, kernel.signal_variance)
    via_standardised = cross @ cho_solve(cho_factor(gram, lower=True), standardised)
    via_points = mean + std * via_standardised
    # Pin the end via-points to the demonstration's start and end poses exactly.
    via_points[0] = poses[0]
    via_points[-1] = poses[-1]
    return GPSkill(
        kernel=kernel,
        via_times=via_times,
        via_points=via_points,
        prior_mean=poses.mean(axis=0),
        duration=demo.duration,
        name=demo.name,
        axis_scale=poses.std(axis=0),
        axis_kernels=fit_zero_mean_axes(tau[sub], poses[sub], bounds, kernel.length_scale),
    )


def reconstruction_error(skill: GPSkill, demo: Demonstration) -> dict[str, list[float]]:
    """Per-axis RMSE of the skill (at its demonstration via-points) against the demo.

    Returns ``{"position": [6 floats], "velocity": [6 floats]}`` (m, rad; m/s, rad/s).
    The demonstration's velocity is its central finite difference.
    """
    tau = demo.normalised_times
    position = skill.position(skill.via_points, tau)
    velocity = skill.velocity(skill.via_points, tau)
    demo_velocity = np.gradient(demo.poses, demo.times, axis=0)
    return {
        "position": np.sqrt(np.mean((position - demo.poses) ** 2, axis=0)).tolist(),
        "velocity": np.sqrt(np.mean((velocity - demo_velocity) ** 2, axis=0)).tolist(),
    }
