"""Stage 2 of plan repair: push a window's movable via-points out of the clearance margin.

One push is the least-norm via-point displacement that moves every control instant closer
than the target clearance out by its deficit along the distance field's gradient
(linearised through the plan's dependence on its via-points; :mod:`distgprl.safety_layer.repair`
describes the method, :func:`~distgprl.safety_layer.repair.repair_plan` iterates, bounds and
backtracks the pushes).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from distgprl.safety_layer.plan_check import tool_check_points
from distgprl.safety_layer.retime import Candidate

GradientAt = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``(points (m, 3) m, control instants (m,)) -> (distance (m,) m, unit gradient (m, 3))``."""


def push_step(
    current: Candidate, rows: np.ndarray, robot, gradient_at: GradientAt, target: float, dt: float
) -> np.ndarray | None:
    """Least-norm via-point displacement (k, 3), m, that moves every control instant closer
    than ``target`` (m) out by its deficit along the field's gradient at its worst tool
    point (linearised through ``rows``, the plan's dependence on its via-points at plan
    instants 0..n); None if no such instant depends on the via-points."""
    points = [tool_check_points(robot, q) for q in current.check.joints]
    count = len(points[0])
    steps = np.repeat(np.arange(len(points)), count)
    distance, gradient = gradient_at(np.concatenate(points), steps)
    distance = np.asarray(distance).reshape(len(points), count)
    gradient = np.asarray(gradient).reshape(len(points), count, 3)
    worst = distance.argmin(axis=1)
    per_step = distance[np.arange(len(points)), worst]
    close = np.flatnonzero(per_step < target)
    if not len(close):
        return None
    # influence at the (possibly re-timed) instants: interpolated in plan time
    index = current.parameter[close] / dt
    lower = np.clip(np.floor(index).astype(int), 0, len(rows) - 1)
    upper = np.clip(lower + 1, 0, len(rows) - 1)
    frac = (index - lower)[:, None]
    matrix = (1.0 - frac) * rows[lower] + frac * rows[upper]  # (c, k)
    if not np.any(np.abs(matrix) > 1e-9):
        return None
    push = (target - per_step[close])[:, None] * gradient[close, worst[close]]  # (c, 3)
    # truncated SVD: neighbouring via-points move the plan almost alike, and the exact
    # least-norm solution would play them against each other with huge opposite moves
    step, *_ = np.linalg.lstsq(matrix, push, rcond=0.1)
    return step
