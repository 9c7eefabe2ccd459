"""The time-indexed clearance of environment v5 (`distgprl.envs.clearance.TimedClearance`
before issue 49), kept verbatim as the reference `tests/envs/test_batched_clearance.py` checks
the batched one against: a field update and a one-point query per window pose."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from distgprl.safety.edf import DistanceField
from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.shapes import Shape

__all__ = ["ReferenceTimedClearance"]

MovingShapesAt = Callable[..., Sequence[Shape]]
CLEARANCE_TIMINGS = ("predicted", "current")


class ReferenceTimedClearance:
    """EDF clearance at poses reached at known times, against time-indexed obstacles.

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
        # The static obstacles once for all window points, the (few) moving ones in a small
        # field moved to each pose's time.
        self._static_field = DistanceField([s for s in shapes if not s.dynamic])
        self._moving_field = DistanceField([s for s in shapes if s.dynamic])

    def distance(
        self, points: np.ndarray, times: np.ndarray, moving_shapes_at: MovingShapesAt
    ) -> tuple[np.ndarray, np.ndarray]:
        """EDF distance (L,), m, and unit gradient (L, 3) at ``points`` (L, 3), m, each
        against the obstacles at its time ``times`` (L,), s (``"predicted"``), or against
        ``field`` as it stands (``"current"``)."""
        if self.timing == "current":
            return self.field.distance(points)
        distance, gradient = self._static_field.distance(points)
        field = self._moving_field
        for j, when in enumerate(times):
            field.update(moving_shapes_at(float(when)))
            d, g = field.distance(points[j : j + 1])
            if d[0] < distance[j]:
                distance[j], gradient[j] = d[0], g[0]
        return distance, gradient

    def anchors(self, times: np.ndarray, moving_shapes_at: MovingShapesAt) -> np.ndarray:
        """The moving obstacles' anchor (N, 3), m, at each of ``times`` (N,), s
        (``"predicted"``), or now for all (``"current"``)."""
        if self.timing == "current":
            anchor = MovingObstacleFilter.anchor(moving_shapes_at())
            return np.tile(anchor, (len(times), 1))
        return np.stack([MovingObstacleFilter.anchor(moving_shapes_at(float(t))) for t in times])
