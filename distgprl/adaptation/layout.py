"""Action layout and the ``aux`` observation contract (paper §IV-A; DESIGN §3).

:class:`ActionLayout` says which via-points each RL step adapts and how a raw action becomes
Delta Gamma (Eq. transformed_action); :func:`build_action_layout` derives it from the skill, the
env config and the method. :class:`AuxLayout` is the index contract of the ``aux`` vector that
the environment writes into every observation and the regularised actor loss reads back
(Gamma, the step's one-hot, optionally the moving obstacles' anchors).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from distgprl.config_types import EnvConfig
from distgprl.methods import MethodSpec
from distgprl.skill.gp import GPSkill
from distgprl.skill.operator import axis_operator, row_gain_diagonal, row_gains, row_normalised

__all__ = [
    "COVARIANCE_SCALES",
    "OBSERVATION_SCALE_FLOOR",
    "ActionLayout",
    "AuxLayout",
    "build_action_layout",
    "window_operators",
]

#: Minimum per-axis scale (m, m, m, rad, rad, rad) used to standardise observed via-points
#: (and the scale of an axis the demonstration keeps constant in S's K).
OBSERVATION_SCALE_FLOOR = np.array([0.05, 0.05, 0.05, 0.2, 0.2, 0.2])

COVARIANCE_SCALES = ("zero-mean", "signal", "unit", "correlation", "signal-uncoupled")
"""The readings of K in S (`EnvConfig.covariance_scale`): ``zero-mean`` is Table I's,
``signal``, ``unit`` and ``correlation`` the operator study's readings
(docs/findings/protocol.md, rule 3), ``signal-uncoupled`` its control (not a reading of the paper:
the signal reading's per-via-point reach without its coupling; docs/findings/operator.md)."""


@dataclass(frozen=True)
class ActionLayout:
    """Which via-points each RL step adapts and how raw actions map onto them.

    Attributes:
        indices: per step, the via-point indices its action covers, shape (n_steps, A_v).
        operators: per step and axis, the (A_v, A_v) matrix applied to that axis's
            column of the scaled raw action, shape (n_steps, 6, A_v, A_v) (S_W per axis
            for covariance-transformed windows, identity otherwise).
        segment_bounds: normalised times bounding the executed segments, shape (n_steps+1,).
        scale: per-axis scale of the raw action, shape (6,), m and rad.
        frozen: via-point indices whose update is forced to zero (e.g. GPRL's TC via-point).
    """

    indices: np.ndarray
    operators: np.ndarray
    segment_bounds: np.ndarray
    scale: np.ndarray
    frozen: tuple[int, ...] = ()

    @property
    def n_steps(self) -> int:
        return int(self.indices.shape[0])

    @property
    def points_per_step(self) -> int:
        return int(self.indices.shape[1])

    def delta(self, step: int, raw_action: np.ndarray) -> np.ndarray:
        """Delta Gamma for the step's via-points, shape (A_v, 6) (Eq. transformed_action)."""
        scaled = raw_action.reshape(self.points_per_step, 6) * self.scale
        # per axis a: S_W,a x_a
        delta: np.ndarray = np.einsum("aij,ja->ia", self.operators[step], scaled)
        for index in self.frozen:
            delta[self.indices[step] == index] = 0.0
        return delta


def window_operators(skill: GPSkill, config: EnvConfig, window: np.ndarray) -> np.ndarray:
    """S_W per axis for one window, shape (6, L, L) (Eq. global_S, Eq. transformed_action).

    ``config.covariance_scale``: ``"zero-mean"`` (Table I) — K_tt is the
    covariance matrix of the paper's zero-mean GP (Eq. 1), per axis (`GPSkill.axis_kernels`,
    `distgprl.skill.operator`); ``"correlation"`` — that operator with each row divided by its
    row sum (reach without shrink); ``"signal"`` — K_tt is the standardised GP's
    covariance in the via-points' units, axis a's ``sigma_f^2 s_a^2 R``
    (`GPSkill.signal_variance_per_axis`, s_a floored at `OBSERVATION_SCALE_FLOOR`); ``"unit"``
    — the unit-variance correlation matrix R for every axis; ``"signal-uncoupled"`` (the
    study's control) — the diagonal of the ``"signal"`` operator's row gains sum_j |S_ij|:
    each via-point as far as under ``"signal"``, moved by its own action only.
    """
    length_scale = config.correlation_length_scale or None  # 0: the fitted one
    scale = config.covariance_scale
    if scale not in COVARIANCE_SCALES:
        raise ValueError(f"covariance_scale must be one of {COVARIANCE_SCALES}, got {scale!r}")
    if scale == "unit":
        operator = skill.window_operator(window, config.correlation_lambda, length_scale)
        return np.tile(operator, (6, 1, 1))
    if scale in ("signal", "signal-uncoupled"):
        variance = skill.signal_variance_per_axis(OBSERVATION_SCALE_FLOOR)
        signal = skill.axis_window_operators(
            window, config.correlation_lambda, variance, length_scale
        )
        return row_gain_diagonal(signal) if scale == "signal-uncoupled" else signal
    if skill.axis_kernels is None:
        raise ValueError(
            f"skill {skill.name!r} has no axis_kernels (saved before S used the zero-mean GP); "
            "refit it"
        )
    index = np.ix_(np.asarray(window), np.asarray(window))
    blocks = np.stack(
        [
            axis_operator(skill.via_times, kernel, config.correlation_lambda)[index]
            for kernel in skill.axis_kernels
        ]
    )
    return row_normalised(blocks) if scale == "correlation" else blocks


def _windows(config: EnvConfig) -> np.ndarray:
    """The windows' via-point indices (n_windows, L): W_k = 1 + k (L - 1) + (0..L-1)."""
    length = config.window_size
    starts = [1 + k * (length - 1) for k in range(config.n_windows)]
    return np.array([np.arange(s, s + length) for s in starts])


def reach_scales(skill: GPSkill, config: EnvConfig, tc_range: np.ndarray) -> np.ndarray:
    """The per-axis raw-action scale of rule ``"reach"``, shape (6,), m and
    rad per unit action: scale_a = max(R_a, r_0) / min_i sum_j |S_W,ij| over every window's
    via-points i, S_W the Table I (``zero-mean``) operator whatever operator the run uses, so
    that every windowed via-point can move max(R_a, r_0) in the one step that adapts it.
    ``tc_range`` (3,) is the task's TC range per position axis (m; 0 where the TCs do not
    vary it); r_0 is ``minimum_position_reach`` / ``minimum_rotation_reach``."""
    table_one = EnvConfig(
        n_via_points=config.n_via_points,
        window_size=config.window_size,
        n_windows=config.n_windows,
        correlation_lambda=config.correlation_lambda,
        covariance_scale="zero-mean",
    )
    gains = np.stack([window_operators(skill, table_one, w) for w in _windows(config)])
    smallest = row_gains(gains).min(axis=(0, 2))  # (6,): over windows and rows
    reach = np.r_[
        np.maximum(np.asarray(tc_range, dtype=float), config.minimum_position_reach),
        [config.minimum_rotation_reach] * 3,
    ]
    scales: np.ndarray = reach / smallest
    return scales


def build_action_layout(
    skill: GPSkill,
    config: EnvConfig,
    method: MethodSpec,
    frozen: tuple[int, ...] = (),
    tc_range: np.ndarray | None = None,
) -> ActionLayout:
    """Windows W_k = {1 + k (L - 1), ..., 1 + k (L - 1) + L - 1} (one-point overlap).

    Windowed methods adapt W_k at step k; global methods adapt all interior via-points
    1..N-2 at every step (with ``episode_range``: at 1/steps of the scale, the same total
    range per episode). Segment k runs from the first via-point of W_k (0 for k = 0)
    to the first via-point of W_{k+1} (1 for the last). The raw action's scale is
    `reach_scales` for ``config.action_scale_rule == "reach"`` (``tc_range`` (3,), m, the
    task's TC range per position axis, required then), the configured constants for
    ``"fixed"``; every method of a task gets the same scales.
    """
    n, length, steps = config.n_via_points, config.window_size, config.n_windows
    if n != skill.n_via_points:
        raise ValueError(f"config n_via_points {n} != skill's {skill.n_via_points}")
    starts = [1 + k * (length - 1) for k in range(steps)]
    if starts[-1] + length - 1 > n - 2:
        raise ValueError(f"{steps} windows of {length} do not fit in {n} via-points")
    windows = np.array([np.arange(s, s + length) for s in starts])
    bounds = np.r_[0.0, skill.via_times[starts[1:]], 1.0]
    if method.action_mode == "global":  # residual/none: windows without S (below)
        interior = np.arange(1, n - 1)
        indices = np.tile(interior, (steps, 1))
        operators = np.tile(np.eye(len(interior)), (steps, 6, 1, 1))
    else:
        indices = windows
        if method.covariance_transform:
            operators = np.stack([window_operators(skill, config, w) for w in windows])
        else:
            operators = np.tile(np.eye(length), (steps, 6, 1, 1))
    if config.action_scale_rule == "reach":
        if tc_range is None:
            raise ValueError('action_scale_rule "reach" needs the task\'s tc_range')
        scale = reach_scales(skill, config, tc_range)
    elif config.action_scale_rule == "fixed":
        scale = np.array([config.position_action_scale] * 3 + [config.rotation_action_scale] * 3)
    else:
        raise ValueError(f"unknown action_scale_rule {config.action_scale_rule!r}")
    if method.action_mode == "global" and method.episode_range:
        scale = scale / steps  # the same per-episode range as a windowed via-point
    return ActionLayout(indices, operators, bounds, scale, tuple(frozen))


@dataclass(frozen=True)
class AuxLayout:
    """Index contract of the ``aux`` observation (not seen by the networks).

    ``aux`` = [Gamma (N x 6, m and rad, row-major (via-point, axis)) | one-hot of the step
    (n_steps) | moving obstacles' anchor positions at the N via-point times (N x 3, m; only
    with ``anchors``)], float32.

    Attributes:
        n_via_points: N.
        n_steps: RL steps per episode (``ActionLayout.n_steps``).
        anchors: whether the anchors block is present (methods with the HAP prior).
    """

    n_via_points: int
    n_steps: int
    anchors: bool = False

    @property
    def gamma(self) -> slice:
        """Entries of the flattened Gamma, N x 6."""
        return slice(0, self.n_via_points * 6)

    @property
    def step(self) -> slice:
        """Entries of the step's one-hot, n_steps."""
        start = self.n_via_points * 6
        return slice(start, start + self.n_steps)

    @property
    def anchor(self) -> slice:
        """Entries of the flattened anchors, N x 3 (empty without ``anchors``)."""
        start = self.n_via_points * 6 + self.n_steps
        return slice(start, start + (self.n_via_points * 3 if self.anchors else 0))

    @property
    def size(self) -> int:
        """Length of the ``aux`` vector."""
        return int(self.anchor.stop)

    def pack(self, gamma: np.ndarray, step: int, anchors: np.ndarray | None = None) -> np.ndarray:
        """The ``aux`` vector, shape (size,), float32.

        Args:
            gamma: current via-points, shape (N, 6), m and rad.
            step: the step index whose one-hot is set (clipped to the last step).
            anchors: shape (N, 3), m; required exactly when ``anchors`` is set.
        """
        if (anchors is not None) != self.anchors:
            raise ValueError(f"anchors {'missing' if self.anchors else 'not expected'}")
        one_hot = np.zeros(self.n_steps)
        one_hot[min(step, self.n_steps - 1)] = 1.0
        parts = [np.asarray(gamma).ravel(), one_hot]
        if anchors is not None:
            parts.append(np.asarray(anchors).ravel())
        return np.concatenate(parts).astype(np.float32)
