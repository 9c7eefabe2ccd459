"""Residual control on a nominal trajectory: ProMP-RRL as residual RL (issue 48, item 4).

The numerics of `distgprl.envs.residual_control_env.ResidualRLEnv` (numpy and scipy only, no
simulator): when the RL steps fall (`control_schedule`), how far the residual may reach per
axis (`residual_range`) and how fast it may move there (`slew_limited`), how much of it
passes at each control instant (`variance_gate`), how it moves from one RL step's value to
the next (`hold_residual`) and how it is added to the nominal pose (`compose`).

Poses are ``x, y, z`` (m) and a rotation vector ``rx, ry, rz`` (rad, UR convention), world
frame; a residual is ``(dx, dy, dz)`` (m) and a rotation vector (rad) applied in the world
frame on the left of the nominal orientation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from distgprl.skill.rotations import nearest_equivalent_rotvec

__all__ = [
    "GATE_MODES",
    "RL_RATE_HZ",
    "SLEW_TIME_S",
    "ControlSchedule",
    "GateMode",
    "compose",
    "control_schedule",
    "hold_residual",
    "residual_range",
    "rotation_error",
    "slew_limited",
    "variance_gate",
]

RL_RATE_HZ = 10.0
"""RL steps per second of ProMP-RRL's residual policy (at least 10 Hz: docs/findings/protocol.md,
rule 4).

Why at least 10 Hz: a residual policy corrects the nominal *during* execution (Johannink et
al. 2018; Carvalho et al. 2022), so it must decide faster than the scene changes on the scale
of its margins. The fastest moving obstacle, DCP's cube (amplitude 0.15 m, period 4 s), moves
at most 2 pi 0.15 / 4 = 0.24 m/s, i.e. 24 mm per 0.1 s: less than the clearance margin d_min
of r_sd (30 mm) and the obstacle's half size (30 mm), so at 10 Hz no approach closes a margin
between two decisions (DBM's belt: 4 mm per step). 10 Hz is the lowest rate the protocol
allows, which keeps the episodes as short as possible (48 RL steps on DCP, 50 on DBM) on the
same RL-step budget as the windowed methods; it divides both demonstrations' durations (4.8
s, 5.0 s) into whole RL steps, and the 25 Hz control loop into 2 and 3 control periods per
RL step alternately.
"""

SLEW_TIME_S = 0.4
"""The least time (s) in which the residual may cross its range on an axis: per RL step of
duration dt the residual moves at most ``range * dt / SLEW_TIME_S`` towards the policy's
target (`slew_limited`). On the largest position range, 0.2 m, that is 0.5 m/s: half the
hardware safety layer's TCP speed bound (`distgprl.limits.SafetyLimits.max_tcp_speed`,
1 m/s), the nominal (the demonstration, at most 0.45 m/s) keeping the other half. Without it
a target drawn anew at each step (SAC's exploration) jumps by up to twice the range within
two control periods: uniform random targets (8 episodes per task) collided in 15 of 16
episodes within 1.5 s, at peak commanded joint speeds of 7-16 rad/s (the UR5e's limit is
pi); with the limit, 12 of 16 collided, after 1.8-3.8 s (DCP past the interaction), at
1.7-3.5 rad/s."""

GateMode = Literal["uncertain", "certain"]

GATE_MODES: tuple[str, ...] = ("uncertain", "certain")
"""The two readings of the variance gate (`variance_gate`): ``uncertain`` — the residual
passes where the ProMP's variance is high (where the ProMP is certain, the residual
is scaled down); ``certain`` — where it is low (the common reading of Carvalho et al.: the
residual acts in the precise, low-variance part)."""


@dataclass(frozen=True)
class ControlSchedule:
    """The control instants of an episode, grouped by RL step.

    Attributes:
        times: end times of the control periods, shape (n,), s: ``k control_dt``,
            k = 1..n, n = round(duration / control_dt).
        tau: the same as normalised times ``times / duration``, shape (n,), in (0, 1].
        steps: per RL step j, the indices (m_j,) into ``times`` of the control instants it
            executes: those in (j / rate, (j + 1) / rate] s.
        step_duration: per RL step, the time (s) from the previous step's last control
            instant (0 for the first) to its own last one, shape (n_steps,).
        fraction: per control instant, how far through its RL step it lies, shape (n,), in
            (0, 1]: (t - t_prev) / (t_last - t_prev), t_last the step's last control instant
            and t_prev the previous step's (0 for the first step); 1 at the step's last
            instant (e.g. 1/2, 1 for a step of two periods; 1/3, 2/3, 1 for three).
        rate_hz: RL steps per second.
    """

    times: np.ndarray
    tau: np.ndarray
    steps: tuple[np.ndarray, ...]
    step_duration: np.ndarray
    fraction: np.ndarray
    rate_hz: float

    @property
    def n_steps(self) -> int:
        """RL steps per episode: ceil(duration x rate)."""
        return len(self.steps)


def control_schedule(duration: float, control_dt: float, rate_hz: float) -> ControlSchedule:
    """The `ControlSchedule` of a trajectory of ``duration`` s executed at ``control_dt`` s
    per control period, with RL steps at ``rate_hz`` (at most one per control period)."""
    if not (duration > 0 and control_dt > 0 and rate_hz > 0):
        raise ValueError("duration, control_dt and rate_hz must be positive")
    if rate_hz * control_dt > 1.0 + 1e-9:
        raise ValueError(f"rate {rate_hz} Hz is faster than the control loop ({control_dt} s)")
    count = int(round(duration / control_dt))
    times = (np.arange(count) + 1) * control_dt
    n_steps = max(1, math.ceil(duration * rate_hz - 1e-9))
    step_of = np.clip(np.ceil(times * rate_hz - 1e-9).astype(int) - 1, 0, n_steps - 1)
    steps = tuple(np.flatnonzero(step_of == j) for j in range(n_steps))
    if any(len(s) == 0 for s in steps):
        raise ValueError("an RL step would execute no control period")
    # Each step moves from the previous step's last control instant (t = 0 for the first) to
    # its own last one, in equal parts per control period.
    last = np.array([times[s[-1]] for s in steps])
    before = np.r_[0.0, last[:-1]]
    fraction = (times - before[step_of]) / (last - before)[step_of]
    tau = np.clip(times / duration, 0.0, 1.0)
    return ControlSchedule(times, tau, steps, last - before, fraction, float(rate_hz))


def residual_range(
    tc_range: np.ndarray, minimum_position: float, minimum_rotation: float
) -> np.ndarray:
    """The residual's range per axis, shape (6,), m and rad: a raw action a in [-1, 1]^6
    becomes the residual ``a * residual_range``.

    Positions: max(TC range on the axis, ``minimum_position``); rotations:
    ``minimum_rotation`` (no TC varies an orientation) — the reach rule every method's action
    scale follows (docs/findings/protocol.md, rule 2), applied to the residual's one output.
    Args: the task's TC range per position axis ``tc_range`` (3,), m; the minimum reaches, m
    and rad.
    """
    tc_range = np.asarray(tc_range, dtype=float)
    if tc_range.shape != (3,) or np.any(tc_range < 0):
        raise ValueError(f"tc_range must be 3 non-negative numbers, got {tc_range}")
    position = np.maximum(tc_range, float(minimum_position))
    scale: np.ndarray = np.r_[position, np.full(3, float(minimum_rotation))]
    return scale


def variance_gate(std: np.ndarray, mode: GateMode = "uncertain") -> np.ndarray:
    """How much of the residual passes at each control instant, shape (m,), in [0, 1].

    ``std`` (m, 3) (or (m,)): the ProMP's marginal positional standard deviation (m) at the
    episode's control instants, in the object frame; sigma(t) is its mean over x, y, z. The
    gate is normalised by the largest sigma over those instants:

    - ``uncertain``: g(t) = sigma(t) / max_k sigma(t_k) — 0 where the ProMP has no variance,
      1 where it is most uncertain;
    - ``certain``: g(t) = 1 - sigma(t) / max_k sigma(t_k).

    A ProMP with no variance at all (max sigma = 0) passes nothing with ``uncertain`` and
    everything with ``certain``.
    """
    if mode not in GATE_MODES:
        raise ValueError(f"gate mode must be one of {GATE_MODES}, got {mode!r}")
    std = np.asarray(std, dtype=float)
    sigma = std.mean(axis=1) if std.ndim == 2 else std
    if np.any(sigma < 0) or not np.all(np.isfinite(sigma)):
        raise ValueError("standard deviations must be finite and non-negative")
    top = float(sigma.max()) if len(sigma) else 0.0
    ratio = sigma / top if top > 0.0 else np.zeros_like(sigma)
    gate: np.ndarray = ratio if mode == "uncertain" else 1.0 - ratio
    return gate


def slew_limited(
    previous: np.ndarray, target: np.ndarray, scale: np.ndarray, duration: float
) -> np.ndarray:
    """The residual (6,) at the end of an RL step of ``duration`` s: ``previous`` (6,) moved
    towards the policy's ``target`` (6,) by at most ``scale * duration / SLEW_TIME_S`` per
    axis (``scale`` (6,): the residual range, m and rad)."""
    previous = np.asarray(previous, dtype=float)
    step = np.asarray(scale, dtype=float) * float(duration) / SLEW_TIME_S
    limited: np.ndarray = previous + np.clip(
        np.asarray(target, dtype=float) - previous, -step, step
    )
    return limited


def hold_residual(previous: np.ndarray, target: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """The residual commanded at an RL step's control instants, shape (m, 6): a first-order
    hold from ``previous`` (6,) (the last step's target, in force at the step's start) to
    ``target`` (6,) (this step's), linear in the instants' ``fraction`` (m,) of the step, so
    the step's last instant commands ``target`` exactly and the commanded pose never jumps."""
    previous = np.asarray(previous, dtype=float)
    target = np.asarray(target, dtype=float)
    fraction = np.asarray(fraction, dtype=float)[:, None]
    held: np.ndarray = previous[None, :] + fraction * (target - previous)[None, :]
    return held


def compose(nominal: np.ndarray, residual: np.ndarray, gate: np.ndarray) -> np.ndarray:
    """Nominal poses (m, 6) with the gated residual (m, 6) added, shape (m, 6).

    Position: p = p_nominal + g dp. Orientation: R = Exp(g dr) R_nominal (the residual
    rotation applied in the world frame), returned as the rotation vector equivalent-nearest
    the nominal's (no 2 pi jumps); where g dr = 0 the nominal's rotation vector is kept
    exactly. ``gate`` (m,) in [0, 1].
    """
    nominal = np.asarray(nominal, dtype=float)
    scaled = np.asarray(gate, dtype=float)[:, None] * np.asarray(residual, dtype=float)
    poses = nominal.copy()
    poses[:, :3] += scaled[:, :3]
    turn = np.flatnonzero(np.any(scaled[:, 3:] != 0.0, axis=1))
    if len(turn):
        rotated = (
            Rotation.from_rotvec(scaled[turn, 3:]) * Rotation.from_rotvec(nominal[turn, 3:])
        ).as_rotvec()
        for row, rotvec in zip(turn, rotated, strict=True):
            poses[row, 3:] = nearest_equivalent_rotvec(rotvec, nominal[row, 3:])
    return poses


def rotation_error(pose: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The rotation (3,), rad, that takes ``reference``'s orientation to ``pose``'s in the
    world frame: the rotation vector of R_pose R_reference^T (poses (6,))."""
    error = (
        Rotation.from_rotvec(np.asarray(pose, dtype=float)[3:])
        * Rotation.from_rotvec(np.asarray(reference, dtype=float)[3:]).inv()
    )
    rotvec: np.ndarray = error.as_rotvec()
    return rotvec
