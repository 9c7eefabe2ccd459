"""The plan state of an adaptation episode (paper §IV-A; DESIGN §3).

:class:`WindowPlan` holds what an episode adapts and executes: the parameters Gamma (N, 6)
(via-points for the GP skill, residual weights for ProMP-RRL), their TC conditioning, the
per-step segment maps (control instants and the linear map from Gamma to the poses there),
the window update ``apply(step, action)`` (Eq. transformed_action, Eq. updated_via_points) and
the continuity blend from the last commanded pose. The environment, the hardware adapter and
the bench all drive an episode through it.

What the plan needs from a trajectory representation is :class:`TrajectoryModel`, a protocol
implemented by the GP skill's adapter and by ProMP-RRL's residual
(:mod:`distgprl.adaptation.trajectories`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from distgprl.adaptation.layout import ActionLayout
from distgprl.skill.rotations import nearest_equivalent_rotvec

__all__ = [
    "Segment",
    "TaskConfigLike",
    "TrajectoryModel",
    "WindowPlan",
    "min_jerk",
    "segment_instants",
]


def min_jerk(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk blend 10u^3 - 15u^4 + 6u^5 on [0, 1] (clipped)."""
    u = np.clip(u, 0.0, 1.0)
    blend: np.ndarray = u**3 * (10 - 15 * u + 6 * u**2)
    return blend


class TaskConfigLike(Protocol):
    """What a trajectory model is conditioned on: a task configuration's start offset of the
    manipulated object, (dx, dy) in m (`distgprl.sim.tasks.base.TaskConfig`, which this layer
    does not import)."""

    @property
    def object_offset(self) -> tuple[float, float]: ...


class TrajectoryModel(Protocol):
    """A trajectory whose poses are affine in parameters Gamma (N, 6):
    ``pose(tau) = offset(tau) + parameter_map(tau) @ Gamma``, tau the normalised time in [0, 1].
    """

    def parameter_map(self, tau: np.ndarray) -> np.ndarray:
        """The linear map from Gamma (N, 6) to the poses at ``tau`` (m,): shape (m, N)."""
        ...

    def condition(self, tc: TaskConfigLike, start_pose: np.ndarray) -> np.ndarray:
        """Condition the model on a task configuration ``tc`` and the start pose (6,), m and
        rad; return the episode's initial Gamma (N, 6). TC-dependent parts of `offset` and
        `position` follow the last call."""
        ...

    def offset(self, tau: np.ndarray, parameter_map: np.ndarray) -> np.ndarray:
        """The pose part not carried by Gamma at ``tau`` (m,), shape (m, 6), given
        ``parameter_map`` = `parameter_map` (tau) (m, N)."""
        ...

    def position(self, parameters: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Poses (m, 6), m and rad, at ``tau`` (m,) for Gamma = ``parameters`` (N, 6)."""
        ...

    def velocity(self, parameters: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Velocities (m, 6), m/s and rad/s, at ``tau`` (m,) for ``parameters`` (N, 6)."""
        ...

    def window_poses(self, parameters: np.ndarray, indices: np.ndarray) -> np.ndarray:
        """The poses (L, 6) that stand for the adapted parameters ``indices`` (L,) (the
        window via-points for the GP skill)."""
        ...


@dataclass(frozen=True)
class Segment:
    """The control instants executed by one RL step.

    Attributes:
        tau: normalised times in (lo, hi] of the control instants (the end of each control
            period), shape (m,).
        parameter_map: the model's `TrajectoryModel.parameter_map` at ``tau``, shape (m, N).
        lo: normalised time of the segment's start.
        hi: normalised time of the segment's end.
    """

    tau: np.ndarray
    parameter_map: np.ndarray
    lo: float
    hi: float


def segment_instants(duration: float, control_dt: float, bounds: np.ndarray) -> list[np.ndarray]:
    """Normalised control-instant times tau of each segment between ``bounds`` (n_steps+1,):
    one array (m_k,) per step, for a trajectory of ``duration`` s at ``control_dt`` s."""
    n_total = int(round(duration / control_dt))
    times = (np.arange(n_total) + 1) * control_dt  # targets for the end of each control period
    tau_all = np.clip(times / duration, 0.0, 1.0)
    out = []
    for k in range(len(bounds) - 1):
        lo, hi = bounds[k], bounds[k + 1]
        out.append(tau_all[(tau_all > lo + 1e-12) & (tau_all <= hi + 1e-12)])
    return out


class WindowPlan:
    """Gamma, its conditioning, the segment maps and the window update of one episode.

    Args:
        model: the trajectory representation (:class:`TrajectoryModel`).
        layout: which parameters each step adapts and how an action maps onto them.
        duration: the trajectory's duration T, s.
        control_dt: the control period, s (one segment pose per period).
        blend_fraction: the fraction of a segment over which a start mismatch is blended out.
        reference_rotvec: rotation vector (3,) the start pose's is made equivalent-nearest
            to (the demonstration's first via-point's).
        parameters: Gamma (N, 6) before the first `start`.
        trainable: False for references that train no policy: `apply` leaves Gamma as is.

    Attributes:
        gamma: the current parameters (N, 6) (read and adapted in place by the callers).
        gamma_initial: the parameters at the start of the episode (N, 6).
        tc: the task configuration of the episode.
        start_pose: the episode's start pose (6,), m and rad.
        start_time: the world's time (s) at the start of the episode.
    """

    def __init__(
        self,
        model: TrajectoryModel,
        layout: ActionLayout,
        duration: float,
        control_dt: float,
        blend_fraction: float,
        reference_rotvec: np.ndarray,
        parameters: np.ndarray,
        trainable: bool = True,
    ) -> None:
        self.model = model
        self.layout = layout
        self.blend_fraction = float(blend_fraction)
        self.trainable = bool(trainable)
        self._reference_rotvec = np.asarray(reference_rotvec, dtype=float)
        bounds = layout.segment_bounds
        self.segments = [
            Segment(tau, model.parameter_map(tau), bounds[k], bounds[k + 1])
            for k, tau in enumerate(segment_instants(duration, control_dt, bounds))
        ]
        self._offsets: list[np.ndarray] | None = None  # per segment, set by start()
        self.gamma = np.array(parameters, dtype=float, copy=True)
        self.gamma_initial = self.gamma.copy()
        self.tc: TaskConfigLike | None = None
        self.start_pose = np.zeros(6)
        self.start_time = 0.0
        self._last_commanded = np.zeros(6)
        self._last_tau = 0.0

    def start(self, tc: TaskConfigLike, tcp_pose: np.ndarray, start_time: float) -> None:
        """Start an episode: condition on ``tc`` from the TCP pose (6,), m and rad, at the
        world's time ``start_time`` (s). The start pose's rotation vector is made the
        equivalent nearest ``reference_rotvec``; Gamma and ``gamma_initial`` are the model's
        conditioned parameters; the last commanded pose is the start pose."""
        self.tc = tc
        start = np.array(tcp_pose, dtype=float)
        start[3:] = nearest_equivalent_rotvec(start[3:], self._reference_rotvec)
        self.start_pose = start
        self.start_time = float(start_time)
        self.gamma = self.model.condition(tc, start)
        self.gamma_initial = self.gamma.copy()
        self._offsets = [self.model.offset(s.tau, s.parameter_map) for s in self.segments]
        self._last_commanded = start.copy()
        self._last_tau = 0.0

    def apply(self, step: int, action: np.ndarray) -> np.ndarray:
        """Apply a raw action (A_v x 6 entries, in [-1, 1]; clipped) to step ``step``'s
        parameters; return Delta Gamma (A_v, 6) = S_W a (Eq. transformed_action), added to
        Gamma's window rows (Eq. updated_via_points). Zero if not ``trainable``."""
        raw = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
        if not self.trainable:  # references: `demo` executes Gamma_0, `promp-nominal`
            raw = np.zeros_like(raw)  # the ProMP mean
        delta = self.layout.delta(step, raw)  # Eq. transformed_action
        self.gamma[self.layout.indices[step]] += delta  # Eq. updated_via_points
        return delta

    def segment_tau(self, step: int) -> np.ndarray:
        """Normalised times (m,) of segment ``step``'s control instants (a copy)."""
        return self.segments[step].tau.copy()

    def segment_poses(self, step: int) -> np.ndarray:
        """Poses (m, 6), m and rad, to command for segment ``step`` from the current Gamma,
        with the start mismatch to the last commanded pose blended out by a minimum-jerk
        weight over ``blend_fraction`` of the segment (continuity)."""
        if self._offsets is None:
            raise RuntimeError("start() the plan before asking for segment poses")
        segment = self.segments[step]
        tau, lo, hi = segment.tau, segment.lo, segment.hi
        poses: np.ndarray = self._offsets[step] + segment.parameter_map @ self.gamma
        if len(tau):
            # Where the re-planned trajectory puts the last commanded control instant.
            planned_start = self.poses(np.array([self._last_tau]))[0]
            jump = self._last_commanded - planned_start
            weight = 1.0 - min_jerk((tau - lo) / max(self.blend_fraction * (hi - lo), 1e-9))
            poses = poses + weight[:, None] * jump
        return poses

    def poses(self, tau: np.ndarray) -> np.ndarray:
        """Planned poses (m, 6) at ``tau`` (m,) from the current Gamma (no blend)."""
        return self.model.position(self.gamma, np.asarray(tau, dtype=float))

    def velocity(self, tau: np.ndarray) -> np.ndarray:
        """Planned velocities (m, 6), m/s and rad/s, at ``tau`` (m,) from the current Gamma."""
        return self.model.velocity(self.gamma, tau)

    def window_poses(self, indices: np.ndarray) -> np.ndarray:
        """The poses (L, 6) standing for parameters ``indices`` (L,) (the window's)."""
        return self.model.window_poses(self.gamma, indices)

    def mark_commanded(self, step: int, poses: np.ndarray) -> None:
        """Record that segment ``step``'s ``poses`` (m, 6) were commanded: the next segment's
        blend starts from the last of them (nothing happens if m = 0)."""
        if len(poses):
            self._last_commanded = np.array(poses[-1], dtype=float)
            self._last_tau = float(self.segments[step].tau[-1])

    @property
    def last_commanded(self) -> np.ndarray:
        """The last commanded pose (6,), m and rad (the start pose before the first segment)."""
        return self._last_commanded.copy()
