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

from distgprl.config import EnvConfig
from distgprl.methods import MethodSpec
from distgprl.skill.gp import GPSkill

__all__ = ["ActionLayout", "AuxLayout", "build_action_layout"]


@dataclass(frozen=True)
class ActionLayout:
    """Which via-points each RL step adapts and how raw actions map onto them.

    Attributes:
        indices: per step, the via-point indices its action covers, shape (n_steps, A_v).
        operators: per step, the (A_v, A_v) matrix applied to the raw action
            (S_W for covariance-transformed windows, identity otherwise).
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
        delta = self.operators[step] @ scaled
        for index in self.frozen:
            delta[self.indices[step] == index] = 0.0
        return delta


def build_action_layout(
    skill: GPSkill, config: EnvConfig, method: MethodSpec, frozen: tuple[int, ...] = ()
) -> ActionLayout:
    """Windows W_k = {1 + k (L - 1), ..., 1 + k (L - 1) + L - 1} (one-point overlap).

    Windowed methods adapt W_k at step k; global methods adapt all interior via-points
    1..N-2 at every step (with ``episode_range``: at 1/steps of the scale, the same total
    range per episode). Segment k runs from the first via-point of W_k (0 for k = 0)
    to the first via-point of W_{k+1} (1 for the last).
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
        operators = np.tile(np.eye(len(interior)), (steps, 1, 1))
    else:
        indices = windows
        if method.covariance_transform:
            length_scale = config.correlation_length_scale or None  # 0: the fitted one
            operators = np.stack(
                [skill.window_operator(w, config.correlation_lambda, length_scale) for w in windows]
            )
        else:
            operators = np.tile(np.eye(length), (steps, 1, 1))
    scale = np.array([config.position_action_scale] * 3 + [config.rotation_action_scale] * 3)
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
        return self.anchor.stop

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
