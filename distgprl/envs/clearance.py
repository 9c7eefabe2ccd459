"""Time-indexed clearance of the adaptation env's window (DESIGN §3).

The observation's ``c`` and r_ga's gradients are taken at the window's poses against the
obstacles where they will be when the trajectory reaches each pose
(``clearance_timing == "predicted"``), or where they are now (``"current"``); L_hap's
moving-obstacle anchors likewise.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from distgprl.safety.edf import DistanceField
from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.shapes import Shape

__all__ = ["CLEARANCE_TIMINGS", "TimedClearance"]

CLEARANCE_TIMINGS = ("predicted", "current")
"""The values of `EnvConfig.clearance_timing`."""

MovingShapesAt = Callable[..., Sequence[Shape]]
"""``moving_obstacle_shapes(time=None)``: the moving obstacles at ``time`` (s; None: now)."""

AnchorsAt = Callable[[np.ndarray], np.ndarray]
"""``moving_obstacle_anchors_at(times)``: the moving obstacles' anchor (n, 3), m, at each of
``times`` (n,), s (the position of their first shape, `MovingObstacleFilter.anchor`)."""


class TimedClearance:
    """EDF clearance at poses reached at known times, against time-indexed obstacles.

    The moving obstacles move rigidly by translation (the DCP cube, DBM's other bar, the
    perceived bar of the hardware adapter; L_hap's `MovingObstacleFilter` relies on the same),
    so point p_j's clearance against them at time t_j is their clearance, as ``field`` holds
    them, at p_j - (anchor(t_j) - anchor now): one query of ``field`` for all points, the
    static obstacles included (`DistanceField.distance`'s ``dynamic_shift``; issue 49).

    Args:
        shapes: all obstacle shapes of the scene (static and dynamic).
        timing: ``"predicted"`` or ``"current"`` (`CLEARANCE_TIMINGS`).

    Attributes:
        field: the field of all obstacles at their current poses (``"current"`` timing, r_sd).
    """

    def __init__(self, shapes: Sequence[Shape], timing: str) -> None:
        if timing not in CLEARANCE_TIMINGS:
            raise ValueError(f"clearance_timing must be 'predicted' or 'current', got {timing!r}")
        self.timing = timing
        self.field = DistanceField(shapes)
        moving = [s.name for s in shapes if s.dynamic]
        # The anchor shape (`MovingObstacleFilter.anchor`: the first moving shape) in the field.
        self._anchor_index = self.field.names.index(moving[0]) if moving else None

    def distance(
        self,
        points: np.ndarray,
        times: np.ndarray,
        moving_shapes_at: MovingShapesAt,
        anchors_at: AnchorsAt | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """EDF distance (L,), m, and unit gradient (L, 3) at ``points`` (L, 3), m, each
        against the obstacles at its time ``times`` (L,), s (``"predicted"``), or against
        ``field`` as it stands (``"current"``). ``anchors_at`` (optional) gives the anchors
        at all times at once; without it they are read from ``moving_shapes_at`` per time."""
        if self.timing == "current" or self._anchor_index is None:
            return self.field.distance(points)
        now = np.asarray(self.field.shapes[self._anchor_index].position, dtype=float)
        shift = self.anchors(times, moving_shapes_at, anchors_at) - now
        return self.field.distance(points, dynamic_shift=shift)

    def anchors(
        self,
        times: np.ndarray,
        moving_shapes_at: MovingShapesAt,
        anchors_at: AnchorsAt | None = None,
    ) -> np.ndarray:
        """The moving obstacles' anchor (N, 3), m, at each of ``times`` (N,), s
        (``"predicted"``; from ``anchors_at`` in one call when given), or now for all
        (``"current"``)."""
        if self.timing == "current":
            anchor = MovingObstacleFilter.anchor(moving_shapes_at())
            return np.tile(anchor, (len(times), 1))
        if anchors_at is not None:
            return np.asarray(anchors_at(np.asarray(times, dtype=float)), dtype=float)
        return np.stack([MovingObstacleFilter.anchor(moving_shapes_at(float(t))) for t in times])
