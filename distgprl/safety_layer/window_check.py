"""The pre-flight handling of one window's plan: the clearance and the distance-field gradient
along the plan with the obstacles predicted to each step's time, the window's movable
via-points, what a trial file says of the safety layer, and a line for each repair decision
(the gates of `distgprl.safety_layer.gates` use them).

The same handling checks one 0.1 s RL step of residual control (ProMP-RRL) as a plan of its
own: retiming applies to it, the push does not (`pushes_via_points`); `safety_layer` says
which ran, in the trial file's meta."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from distgprl.safety_layer.repair import RepairResult, ViaPoints
from distgprl.safety_layer.retime import RepairConfig


def clearance_function(
    field, obstacle_shapes: Callable[[float], tuple], now: float, dt: float, chunk: int = 5
):
    """The clearance oracle of the safety check: ``(points (m, 3) m, control instants (m,))
    -> distance (m,)``, m, with the obstacles predicted at each instant's time.

    Control instant ``k`` is at ``now + k * dt`` (s); the instants are taken in groups of
    ``chunk``, each against the obstacles at the group's middle time.

    Args:
        field: the :class:`~distgprl.safety.edf.DistanceField` to move (left at ``now``).
        obstacle_shapes: ``time (s) -> shapes``, every obstacle predicted at that time (the
            perceived world's, or a simulation's ``obstacle_shapes``).
        now: time (s) of the window's start; dt: control period, s.
    """

    def clearance_at(points: np.ndarray, steps: np.ndarray) -> np.ndarray:
        out = np.empty(len(points))
        groups = steps // chunk
        for group in np.unique(groups):
            mask = groups == group
            field.update(obstacle_shapes(now + (group * chunk + chunk / 2.0) * dt))
            out[mask] = field.clearance(points[mask])
        field.update(obstacle_shapes(now))
        return out

    return clearance_at


def gradient_function(
    field, obstacle_shapes: Callable[[float], tuple], now: float, dt: float, chunk: int = 5
):
    """The repair's field oracle: ``(points (m, 3) m, control instants (m,)) -> (distance
    (m,) m, unit gradient (m, 3))``, obstacles predicted as in :func:`clearance_function`."""

    def gradient_at(points: np.ndarray, steps: np.ndarray):
        distance = np.empty(len(points))
        gradient = np.empty((len(points), 3))
        groups = steps // chunk
        for group in np.unique(groups):
            mask = groups == group
            field.update(obstacle_shapes(now + (group * chunk + chunk / 2.0) * dt))
            distance[mask], gradient[mask] = field.distance(points[mask])
        field.update(obstacle_shapes(now))
        return distance, gradient

    return gradient_at


NO_VIA_POINTS = (
    "not applicable: the method's plan has no via-points to push (residual ProMP weights, "
    "or ProMP-RRL's 10 Hz residual)"
)
"""Why the via-point push never runs for the residual ProMP methods (`safety_layer`)."""


def pushes_via_points(plan) -> bool:
    """Whether the repair's push applies to ``plan``'s segments (an env with its ``method``):
    the via-point methods; not the residual ProMP methods (their parameters are weights or a
    residual, not via-points: `NO_VIA_POINTS`)."""
    return plan.method.action_mode not in ("residual", "residual-control")


def safety_layer(
    plan, decision_unit: str, config: RepairConfig | None, force: bool = False
) -> dict[str, str]:
    """What a trial's safety layer does before each decision's poses move, for its file's
    meta (nothing skipped silently): what one check covers (``checked_unit``: a ``window``
    plan, or one ``RL step`` of residual control, 0.1 s), the pre-flight check, and whether
    retiming and the via-point push ran (``on``, ``off`` or `NO_VIA_POINTS`).

    Args:
        plan: the trial's environment (its ``method``).
        decision_unit: what one decision covers (``window`` or ``RL step``).
        config: the repair settings, None with repair off (refused at once).
        force: unsafe poses execute anyway (the violations recorded).
    """
    push = "off" if config is None or not config.repair else "on"
    return {
        "checked_unit": decision_unit,
        "check": (
            "pre-flight, every control instant before it moves (safety.check_plan: workspace, "
            "IK and joint margins, joint speed and acceleration, TCP speed, predicted "
            "clearance of tool and flange)"
        ),
        "unsafe": "executed anyway (force), violations recorded" if force else "refused",
        "retime": "on" if config is not None and config.retime else "off",
        "push": push if pushes_via_points(plan) or push == "off" else NO_VIA_POINTS,
    }


def movable_via_points(plan, step: int) -> tuple[ViaPoints, np.ndarray] | None:
    """The window's movable via-points (not frozen ones) and how its plan depends on them;
    None for the residual ProMP methods (`pushes_via_points`)."""
    if not pushes_via_points(plan):
        return None
    frozen = set(plan.layout.frozen)
    movable = np.array([i for i in plan.layout.indices[step] if int(i) not in frozen], int)
    if not len(movable):
        return None

    def replan(displacement: np.ndarray) -> np.ndarray:
        saved = plan.gamma.copy()
        try:
            plan.gamma[movable, :3] += np.asarray(displacement, dtype=float)
            return plan.segment_poses(step)
        finally:
            plan.gamma = saved

    return ViaPoints(replan, len(movable)), movable


def describe_repair(result: RepairResult) -> str:
    """One line for a window's repair decision."""
    if result.decision == "refused":
        pushes = ", ".join(f"{1000 * d:.1f}" for d in result.pushes)
        tried = f" (clearance after each push, mm: {pushes})" if pushes else ""
        return f"refused after retiming and repair{tried} -- {result.reason}"
    if result.decision == "none":
        return "none (plan passes the pre-flight check)"
    text = f"{result.decision}: +{result.time_added:.2f} s"
    if result.decision == "repaired":
        text += f", via-points moved up to {1000.0 * result.max_displacement:.1f} mm"
    assert result.original is not None  # a retimed or repaired window keeps its original check
    original = ", ".join(f"{v.limit} {v.value:.4g}" for v in result.original.violations)
    return f"{text} (was: {original}; now min clearance {result.check.min_clearance:.4f} m)"
