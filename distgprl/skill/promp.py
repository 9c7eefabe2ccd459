"""Object-centric probabilistic movement primitive (ProMP) for the ProMP-RRL baseline.

A ProMP (Paraschos et al., NeurIPS 2013) represents a distribution over trajectories
``y(z) = Ψ(z)ᵀ w``, ``w ~ N(μ_w, Σ_w)``, where ``z ∈ [0, 1]`` is the phase and ``Ψ`` holds
normalised Gaussian radial basis functions. Following Carvalho et al. (Humanoids 2022,
"Adapting object-centric probabilistic movement primitives with residual reinforcement
learning"), the demonstrations are expressed in the object's frame before fitting, and the
mean is mapped back to the world with the observed object pose.

Conventions used here (and by the ProMP-RRL environment):

- Pose channels ``x, y, z, rx, ry, rz``: position in metres, rotation vector in radians
  (UR convention), world = robot base frame.
- Object frame: the object's *start position* ``p ∈ R³`` is subtracted from the positions
  of each demonstration; orientation channels are left as they are (the tasks only vary the
  object's position). Rotation vectors are averaged linearly, which is valid when the
  demonstrations' orientations are close and continuous (no ±π flips); callers must pass
  unwrapped rotation vectors.
- Phase: each demonstration's times are mapped to ``z = (t − t_0) / (t_end − t_0)``, so
  demonstrations of different durations are aligned by phase. ``duration`` (s) is the mean
  demonstration duration, used to turn phase derivatives into velocities.
- Basis (per channel, shared by all six): ``n_basis`` Gaussians with centres evenly spaced on
  [0, 1] and standard deviation ``basis_width`` (phase units, default = the centre spacing
  ``1 / (n_basis − 1)``), normalised to sum to 1 at every phase (so constants, and hence the
  object shift, are represented exactly). Default ``n_basis = 20``.
- Weights: vector of length ``6 · n_basis``, channel-major (all basis weights of ``x``, then
  ``y``, ...), the layout of ``movement_primitives.promp.ProMP``.
- Fit: per demonstration, ridge regression ``w = (ΦᵀΦ / n + ridge · I)⁻¹ Φᵀ Y / n`` (the
  ``1 / n`` makes ``ridge`` independent of the sampling rate); then ``μ_w`` = mean and
  ``Σ_w`` = unbiased sample covariance of the demonstration weights plus
  ``covariance_jitter · I`` (keeps ``Σ_w`` positive definite with fewer demonstrations than
  weights; units m² or rad² per weight).

Why not ``movement_primitives.promp.ProMP`` directly (version 0.9.1 was inspected): its basis
evaluation divides the caller's time array in place (``T /= np.max(T)``), it can only
condition on all channels at once (we need position-only conditioning), its learning routine
is an EM fit rather than the per-demonstration ridge fit, and the basis width is fixed by an
internal overlap constant. The maths here is the same (same basis family, weight layout and
Gaussian conditioning, Eqs. (5)-(6) of Paraschos et al. 2013); the tests check agreement with
that package when the basis width is set to its value.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

POSE_CHANNELS: int = 6
"""x, y, z (m), rx, ry, rz (rad)."""

POSITION_CHANNELS: int = 3

DICT_FORMAT: str = "distgprl.ObjectCentricProMP"
DICT_VERSION: int = 1


@dataclass(frozen=True)
class ProMPConfig:
    """Settings of the basis and of the weight fit.

    Attributes:
        n_basis: Gaussian basis functions per channel (>= 2).
        basis_width: standard deviation of each Gaussian, phase units; ``None`` means the
            centre spacing ``1 / (n_basis − 1)``.
        ridge: ridge coefficient of the per-demonstration weight fit (dimensionless, relative
            to the sample-averaged Gram matrix ``ΦᵀΦ / n``).
        covariance_jitter: added to the diagonal of the weight covariance (m² / rad²).
    """

    n_basis: int = 20
    basis_width: float | None = None
    ridge: float = 1e-6
    covariance_jitter: float = 1e-10

    def __post_init__(self) -> None:
        if int(self.n_basis) != self.n_basis or self.n_basis < 2:
            raise ValueError(f"n_basis must be an integer >= 2, got {self.n_basis}")
        if self.basis_width is not None and not (
            np.isfinite(self.basis_width) and self.basis_width > 0
        ):
            raise ValueError(f"basis_width must be positive, got {self.basis_width}")
        if not (np.isfinite(self.ridge) and self.ridge >= 0):
            raise ValueError(f"ridge must be >= 0, got {self.ridge}")
        if not (np.isfinite(self.covariance_jitter) and self.covariance_jitter >= 0):
            raise ValueError(f"covariance_jitter must be >= 0, got {self.covariance_jitter}")

    @property
    def width(self) -> float:
        """The basis standard deviation actually used (phase units)."""
        if self.basis_width is None:
            return 1.0 / (self.n_basis - 1)
        return float(self.basis_width)


class ObjectCentricProMP:
    """A ProMP over 6-D tool poses, stored in the object's frame.

    Build it with :meth:`fit` (from demonstrations) or :meth:`from_dict`. Instances are not
    modified by any method: :meth:`conditioned` returns a new ProMP.

    Attributes:
        config: basis and fit settings.
        weight_mean: shape (6 · n_basis,), object-frame weights (m, rad).
        weight_covariance: shape (6 · n_basis, 6 · n_basis), symmetric positive definite.
        duration: mean demonstration duration, seconds.
        demonstration_count: number of demonstrations the ProMP was fitted to.
    """

    def __init__(
        self,
        config: ProMPConfig,
        weight_mean: np.ndarray,
        weight_covariance: np.ndarray,
        duration: float,
        demonstration_count: int,
    ) -> None:
        size = POSE_CHANNELS * config.n_basis
        weight_mean = np.array(weight_mean, dtype=np.float64)
        weight_covariance = np.array(weight_covariance, dtype=np.float64)
        if weight_mean.shape != (size,):
            raise ValueError(f"weight_mean must have shape ({size},), got {weight_mean.shape}")
        if weight_covariance.shape != (size, size):
            raise ValueError(
                f"weight_covariance must have shape ({size}, {size}), got {weight_covariance.shape}"
            )
        if not (np.all(np.isfinite(weight_mean)) and np.all(np.isfinite(weight_covariance))):
            raise ValueError("weights must be finite")
        if not (np.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be positive, got {duration}")
        self.config = config
        self.weight_mean = weight_mean
        self.weight_covariance = 0.5 * (weight_covariance + weight_covariance.T)
        self.duration = float(duration)
        self.demonstration_count = int(demonstration_count)
        self.weight_mean.setflags(write=False)
        self.weight_covariance.setflags(write=False)

    # ------------------------------------------------------------------ construction

    @classmethod
    def fit(
        cls,
        demos: Sequence[tuple[np.ndarray, np.ndarray]],
        object_positions: np.ndarray,
        config: ProMPConfig | None = None,
        *,
        n_basis: int | None = None,
        ridge: float | None = None,
    ) -> ObjectCentricProMP:
        """Fit to K demonstrations, each expressed in its object's frame.

        Args:
            demos: K pairs ``(times, poses)``: times shape (n_k,), seconds, strictly
                increasing, n_k >= 2; poses shape (n_k, 6), world frame, m and rad.
                Durations and sample counts may differ.
            object_positions: shape (K, 3), metres: the object's start position in each
                demonstration (subtracted from that demonstration's positions).
            config: basis and fit settings (default ``ProMPConfig()``).
            n_basis: overrides ``config.n_basis``.
            ridge: overrides ``config.ridge``.

        Returns:
            The fitted ProMP.
        """
        config = config or ProMPConfig()
        config = dataclasses.replace(
            config,
            n_basis=config.n_basis if n_basis is None else n_basis,
            ridge=config.ridge if ridge is None else ridge,
        )
        object_positions = np.asarray(object_positions, dtype=np.float64)
        if len(demos) < 1:
            raise ValueError("need at least one demonstration")
        if object_positions.shape != (len(demos), POSITION_CHANNELS):
            raise ValueError(
                f"object_positions must have shape ({len(demos)}, 3), got {object_positions.shape}"
            )
        if not np.all(np.isfinite(object_positions)):
            raise ValueError("object_positions must be finite")
        weights = np.empty((len(demos), POSE_CHANNELS * config.n_basis))
        durations = np.empty(len(demos))
        for index, (times, poses) in enumerate(demos):
            times, poses = _validated_demo(times, poses, index)
            durations[index] = times[-1] - times[0]
            phase = (times - times[0]) / durations[index]
            frame_poses = poses.copy()
            frame_poses[:, :POSITION_CHANNELS] -= object_positions[index]
            basis = _basis(phase, config)  # (n_k, N)
            gram = basis.T @ basis / len(phase) + config.ridge * np.eye(config.n_basis)
            channel_weights = scipy.linalg.solve(
                gram, basis.T @ frame_poses / len(phase), assume_a="pos"
            )  # (N, 6)
            weights[index] = channel_weights.T.ravel()
        weight_mean = weights.mean(axis=0)
        if len(demos) > 1:
            weight_covariance = np.cov(weights, rowvar=False, ddof=1)
        else:
            weight_covariance = np.zeros((weights.shape[1], weights.shape[1]))
        weight_covariance = weight_covariance + config.covariance_jitter * np.eye(weights.shape[1])
        return cls(config, weight_mean, weight_covariance, float(durations.mean()), len(demos))

    # ------------------------------------------------------------------ queries

    def basis(self, phase: np.ndarray) -> np.ndarray:
        """Normalised basis values, shape (m, n_basis), for phases (m,) in [0, 1]."""
        return _basis(_validated_phase(phase), self.config)

    def mean_trajectory(
        self, phase: np.ndarray, object_position: np.ndarray | None = None
    ) -> np.ndarray:
        """Mean poses at the given phases.

        Args:
            phase: shape (m,), in [0, 1].
            object_position: shape (3,), metres: the observed object start position; the
                result is in the world frame. ``None``: the result is in the object frame.

        Returns:
            shape (m, 6), m and rad.
        """
        basis = self.basis(phase)
        poses = basis @ self._channel_weights(self.weight_mean)
        world: np.ndarray = poses + _position_offset(object_position)
        return world

    def mean_velocity(self, phase: np.ndarray, duration: float | None = None) -> np.ndarray:
        """Mean pose rates at the given phases, shape (m, 6), m/s and rad/s.

        Args:
            phase: shape (m,), in [0, 1].
            duration: execution duration in seconds (default: the mean demonstration
                duration); the phase advances at ``1 / duration`` per second.
        """
        duration = self.duration if duration is None else float(duration)
        if not (np.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be positive, got {duration}")
        derivative = _basis_derivative(_validated_phase(phase), self.config)
        rates: np.ndarray = derivative @ self._channel_weights(self.weight_mean) / duration
        return rates

    def trajectory_std(self, phase: np.ndarray) -> np.ndarray:
        """Marginal standard deviation of each pose channel, shape (m, 6), m and rad."""
        basis = self.basis(phase)  # (m, N)
        count = self.config.n_basis
        variances = np.empty((basis.shape[0], POSE_CHANNELS))
        for channel in range(POSE_CHANNELS):
            block = self.weight_covariance[
                channel * count : (channel + 1) * count, channel * count : (channel + 1) * count
            ]
            variances[:, channel] = np.einsum("mi,ij,mj->m", basis, block, basis)
        return np.sqrt(np.maximum(variances, 0.0))

    def conditioned(
        self,
        phase: float,
        target: np.ndarray,
        noise: float = 1e-4,
        object_position: np.ndarray | None = None,
    ) -> ObjectCentricProMP:
        """Condition the weight distribution on passing through a pose or position.

        Standard Gaussian conditioning (Paraschos et al. 2013, Eqs. (5)-(6)) on the
        observation ``target = Ψ(phase)ᵀ w + ε``, ``ε ~ N(0, noise² I)``::

            K   = Σ_w Ψ (noise² I + Ψᵀ Σ_w Ψ)⁻¹
            μ_w ← μ_w + K (target − Ψᵀ μ_w),    Σ_w ← Σ_w − K Ψᵀ Σ_w.

        Args:
            phase: the phase in [0, 1] at which the mean should pass through ``target``.
            target: shape (3,) (position only, m; orientation stays free) or (6,) (full
                pose, m and rad).
            noise: observation standard deviation (m for positions, rad for angles), >= 0;
                small values pin the mean to the target, large ones barely move it.
            object_position: shape (3,), metres. If given, ``target`` is in the world frame
                and is converted to the object frame with it; if ``None``, ``target`` is
                already in the object frame.

        Returns:
            A new ProMP (same basis and duration).
        """
        phase_array = _validated_phase(np.array([phase], dtype=np.float64))
        target = np.asarray(target, dtype=np.float64)
        if target.shape not in ((POSITION_CHANNELS,), (POSE_CHANNELS,)):
            raise ValueError(f"target must have shape (3,) or (6,), got {target.shape}")
        if not np.all(np.isfinite(target)):
            raise ValueError("target must be finite")
        if not (np.isfinite(noise) and noise >= 0):
            raise ValueError(f"noise must be >= 0, got {noise}")
        frame_target = target - _position_offset(object_position)[0, : target.shape[0]]
        observed_channels = target.shape[0]
        count = self.config.n_basis
        basis_row = _basis(phase_array, self.config)[0]  # (N,)
        observation_map = np.zeros((POSE_CHANNELS * count, observed_channels))  # Ψ
        for channel in range(observed_channels):
            observation_map[channel * count : (channel + 1) * count, channel] = basis_row
        covariance_times_map = self.weight_covariance @ observation_map  # Σ_w Ψ
        innovation_covariance = observation_map.T @ covariance_times_map + noise**2 * np.eye(
            observed_channels
        )
        gain = scipy.linalg.solve(
            innovation_covariance, covariance_times_map.T, assume_a="pos"
        ).T  # K, (6N, q)
        # Eq. (5)
        residual = frame_target - observation_map.T @ self.weight_mean
        weight_mean = self.weight_mean + gain @ residual
        # Eq. (6)
        weight_covariance = self.weight_covariance - gain @ covariance_times_map.T
        return ObjectCentricProMP(
            self.config, weight_mean, weight_covariance, self.duration, self.demonstration_count
        )

    def start_conditioned_mean(
        self,
        phase: np.ndarray,
        object_position: np.ndarray,
        start_pose: np.ndarray,
        noise: float = 1e-4,
    ) -> np.ndarray:
        """The nominal for an observed object: the mean offset by the object's position,
        conditioned (:meth:`conditioned`) on passing through ``start_pose`` at phase 0.

        The start's rotation vector is first replaced by its equivalent nearest the mean's
        (rotation vectors are averaged linearly), so a 2 pi wrap does not move the mean.

        Args:
            phase: shape (m,), in [0, 1].
            object_position: shape (3,), metres: the observed object start position.
            start_pose: shape (6,), world frame, m and rad: where the robot starts.
            noise: the conditioning's observation standard deviation (m and rad).

        Returns:
            shape (m, 6), world frame, m and rad.
        """
        from distgprl.skill.rotations import nearest_equivalent_rotvec

        start = np.array(start_pose, dtype=np.float64)
        if start.shape != (POSE_CHANNELS,):
            raise ValueError(f"start_pose must have shape (6,), got {start.shape}")
        mean_start = self.mean_trajectory(np.zeros(1), object_position)[0]
        start[POSITION_CHANNELS:] = nearest_equivalent_rotvec(
            start[POSITION_CHANNELS:], mean_start[POSITION_CHANNELS:]
        )
        conditioned = self.conditioned(0.0, start, noise, object_position=object_position)
        return conditioned.mean_trajectory(phase, object_position)

    def sample(
        self,
        rng: np.random.Generator,
        phase: np.ndarray,
        n_samples: int = 1,
        object_position: np.ndarray | None = None,
    ) -> np.ndarray:
        """Draw trajectories from the ProMP.

        Args:
            rng: the random generator (the only source of randomness).
            phase: shape (m,), in [0, 1].
            n_samples: number of trajectories.
            object_position: shape (3,) for world-frame samples; ``None`` for object frame.

        Returns:
            shape (n_samples, m, 6), m and rad.
        """
        if n_samples < 1:
            raise ValueError(f"n_samples must be >= 1, got {n_samples}")
        weights = rng.multivariate_normal(
            self.weight_mean, self.weight_covariance, size=n_samples, method="eigh"
        )  # (S, 6N)
        basis = self.basis(phase)  # (m, N)
        channel_weights = weights.reshape(n_samples, POSE_CHANNELS, self.config.n_basis)
        poses = np.einsum("mn,scn->smc", basis, channel_weights)
        world: np.ndarray = poses + _position_offset(object_position)
        return world

    # ------------------------------------------------------------------ persistence

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable description (plain lists and numbers); see :meth:`from_dict`."""
        return {
            "format": DICT_FORMAT,
            "version": DICT_VERSION,
            "config": dataclasses.asdict(self.config),
            "duration": self.duration,
            "demonstration_count": self.demonstration_count,
            "weight_mean": self.weight_mean.tolist(),
            "weight_covariance": self.weight_covariance.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ObjectCentricProMP:
        """Rebuild a ProMP saved with :meth:`to_dict` (validates format, version, shapes)."""
        if data.get("format") != DICT_FORMAT:
            raise ValueError(f"not a saved ObjectCentricProMP (format {data.get('format')!r})")
        if data.get("version") != DICT_VERSION:
            raise ValueError(
                f"unsupported ObjectCentricProMP version {data.get('version')!r}, "
                f"expected {DICT_VERSION}"
            )
        return cls(
            ProMPConfig(**data["config"]),
            np.asarray(data["weight_mean"], dtype=np.float64),
            np.asarray(data["weight_covariance"], dtype=np.float64),
            float(data["duration"]),
            int(data["demonstration_count"]),
        )

    # ------------------------------------------------------------------ internals

    def _channel_weights(self, weights: np.ndarray) -> np.ndarray:
        """(6 N,) channel-major -> (N, 6)."""
        return weights.reshape(POSE_CHANNELS, self.config.n_basis).T


def _basis_centres(config: ProMPConfig) -> np.ndarray:
    return np.linspace(0.0, 1.0, config.n_basis)


def _unnormalised_basis(phase: np.ndarray, config: ProMPConfig) -> np.ndarray:
    offsets = phase[:, None] - _basis_centres(config)[None, :]
    values: np.ndarray = np.exp(-0.5 * (offsets / config.width) ** 2)
    return values


def _basis(phase: np.ndarray, config: ProMPConfig) -> np.ndarray:
    """Normalised Gaussian basis, (m,) -> (m, N); rows sum to 1."""
    values = _unnormalised_basis(phase, config)
    normalised: np.ndarray = values / values.sum(axis=1, keepdims=True)
    return normalised


def _basis_derivative(phase: np.ndarray, config: ProMPConfig) -> np.ndarray:
    """d/dphase of the normalised basis, (m,) -> (m, N) (quotient rule)."""
    values = _unnormalised_basis(phase, config)
    offsets = phase[:, None] - _basis_centres(config)[None, :]
    derivatives = -offsets / config.width**2 * values
    total = values.sum(axis=1, keepdims=True)
    total_derivative = derivatives.sum(axis=1, keepdims=True)
    quotient: np.ndarray = (derivatives * total - values * total_derivative) / total**2
    return quotient


def _validated_phase(phase: np.ndarray) -> np.ndarray:
    phase = np.asarray(phase, dtype=np.float64)
    if phase.ndim != 1:
        raise ValueError(f"phase must have shape (m,), got {phase.shape}")
    if not np.all(np.isfinite(phase)) or np.any(phase < 0.0) or np.any(phase > 1.0):
        raise ValueError("phase values must lie in [0, 1]")
    return phase


def _position_offset(object_position: np.ndarray | None) -> np.ndarray:
    """(3,) object position -> (1, 6) pose offset (zeros for ``None``)."""
    offset = np.zeros((1, POSE_CHANNELS))
    if object_position is not None:
        position = np.asarray(object_position, dtype=np.float64)
        if position.shape != (POSITION_CHANNELS,) or not np.all(np.isfinite(position)):
            raise ValueError(f"object_position must be 3 finite numbers, got {position}")
        offset[0, :POSITION_CHANNELS] = position
    return offset


def _validated_demo(
    times: np.ndarray, poses: np.ndarray, index: int
) -> tuple[np.ndarray, np.ndarray]:
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    if times.ndim != 1 or times.shape[0] < 2:
        raise ValueError(f"demo {index}: times must have shape (n,), n >= 2, got {times.shape}")
    if poses.shape != (times.shape[0], POSE_CHANNELS):
        raise ValueError(
            f"demo {index}: poses must have shape ({times.shape[0]}, 6), got {poses.shape}"
        )
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(poses))):
        raise ValueError(f"demo {index}: times and poses must be finite")
    if np.any(np.diff(times) <= 0):
        raise ValueError(f"demo {index}: times must be strictly increasing")
    return times, poses
