"""Plan repair between a window's plan and the pre-flight check: retime, push, or refuse.

A window plan that fails :func:`~distgprl.safety_layer.plan_check.check_plan` is not refused at
once. :func:`repair_plan` tries, in order:

1. **Retime** (joint speed, joint acceleration, TCP speed violated): the plan keeps its
   *path* and gets a new *timing*. The path is the not-a-knot cubic spline through the
   robot's TCP pose at the window's start and the plan's poses, in the plan's own timing
   ``s`` (s, one control period per pose). Time-optimal path parameterisation (TOPP-RA,
   the ``toppra`` package) finds the fastest ``s(t)`` within a fraction of the limits the
   safety layer enforces, *never faster than the plan itself* (``ds/dt <= 1``: a virtual
   seventh coordinate ``q_7(s) = s`` with speed limit 1 carries that bound, and the TCP
   speed bound ``ds/dt <= v_tcp / |dp/ds|`` on the same coordinate), starting at the path
   speed nearest the robot's current joint velocity and ending at rest (so that the next
   window, whatever its direction, can start from rest: a seam between a moving end and a
   plan that turns away is a joint-acceleration spike no timing of the next window can
   remove; stopping costs ``v / a``, ~0.1 s at the UR5e limits). The new timing is sampled at the
   control period; the fraction of the limits shrinks until the sampled plan passes the
   discrete check (finite differences, as the check measures them).
2. **Repair** (predicted clearance below the limit): the window's movable via-points are
   pushed along the distance field's gradient. At every control instant closer than
   ``min_clearance + margin`` the gradient at the worst tool point says where "away" is;
   the smallest via-point displacement that pushes those instants out by their deficit
   (linearised: least squares, truncated SVD, through the plan's linear dependence on its
   via-points) is scaled to at most ``step_size`` per via-point and the total is projected
   onto ``max_displacement`` per via-point; the plan is rebuilt and re-checked (and
   re-timed again if the push made it too fast); a push that does not raise the predicted
   clearance is halved from the last accepted plan (backtracking), for at most
   ``iterations`` re-checks. Instants pinned by the continuity blend to the previous
   window's end, or caught between two obstacles (opposite gradients), may not be
   repairable within the bound.
3. **Refuse** whatever is still unsafe after both (:attr:`RepairResult.remaining`).

Keeping the engagement with the conveyed bar (DBM). The bars ride the belt at a known
velocity ``v``; a retimed window ends later than planned, so the bars are ``v * delay``
further along when the hook gets there. The repaired plan is therefore kept in the
*belt's frame* while the target bar is on the belt: each retimed pose at time ``t`` whose
path parameter is ``s(t)`` is shifted by ``v * (t - s(t))`` (plus the shift accumulated by
earlier windows, ``shift``). Relative to both bars (the target and the other bar, which ride
the same belt) the hook follows exactly the planned path and meets the target bar at the
planned place; relative to the static cell (rollers, rails) it is displaced by the shift,
which the clearance check sees, since it predicts the bars at the *new* times (control
instant ``k`` of the returned plan is at ``k * dt`` after the window's start). Once the bar
is lifted off the belt the caller passes ``belt_velocity=None``: the shift stays constant
(the carried bar moves with the hook). Without a belt (``belt_velocity=None``, zero shift)
the retimed TCP positions lie on the original path.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from distgprl.limits import SafetyLimits
from distgprl.safety_layer.plan_check import PlanCheck, Violation
from distgprl.safety_layer.push import GradientAt, push_step
from distgprl.safety_layer.retime import (
    KINEMATIC_LIMITS,
    Candidate,
    ClearanceAt,
    RepairConfig,
    as_candidate,
    retime_plan,
    violated_limits,
)

__all__ = ["DECISIONS", "REPAIRABLE_LIMITS", "RepairResult", "ViaPoints", "repair_plan"]

DECISIONS = ("none", "retimed", "repaired", "refused")
"""Per-window outcomes: passed as planned, re-timed, via-points pushed (and possibly
re-timed), refused."""

REPAIRABLE_LIMITS = KINEMATIC_LIMITS | {"clearance"}
"""Limits :func:`repair_plan` tries to fix; any other violation (workspace, IK, joint
limits) is refused at once."""


@dataclass(frozen=True)
class ViaPoints:
    """How a window's plan depends on the via-points the repair may move.

    Attributes:
        replan: ``displacement (k, 3) m -> poses (n, 6)``: the window's plan (in the plan's
            own frame, without belt shift) with its ``k`` movable via-points moved. It must
            be affine in the displacement and act alike on x, y and z (as a GP or spline
            position map does); zero displacement gives the unrepaired plan.
        count: ``k``.
    """

    replan: Callable[[np.ndarray], np.ndarray]
    count: int

    def influence(self, base: np.ndarray) -> np.ndarray:
        """``d position_i / d via-point_j``, (n, k), from ``k`` unit moves along x."""
        columns = []
        for j in range(self.count):
            move = np.zeros((self.count, 3))
            move[j, 0] = 1.0
            columns.append(np.asarray(self.replan(move))[:, 0] - base[:, 0])
        return np.stack(columns, axis=1) if columns else np.zeros((len(base), 0))


@dataclass(frozen=True)
class RepairResult:
    """Outcome of :func:`repair_plan`.

    Attributes:
        decision: one of :data:`DECISIONS`.
        poses: TCP poses (n', 6) to execute, one per control period (belt shift included).
        path_poses: the same instants in the plan's own frame (without the shift), (n', 6).
        path_parameter: plan time (s, original timing) of each returned instant, (n',).
        check: the check of ``poses`` (joints to stream, clearance).
        time_added: s the window got longer (0 unless re-timed).
        displacement: via-point displacement (k, 3), m (zeros unless repaired).
        shift_end: belt shift (3,), m, in force at the window's end (the next window's
            ``shift``).
        remaining: what is still violated after retiming and repair (empty unless
            refused; a refused result returns the plan as given, for ``--force``).
        original: the check of the plan as given (what ``--no-repair`` would have judged).
        pushes: predicted min clearance (m) after each via-point push, in order.
    """

    decision: str
    poses: np.ndarray
    path_poses: np.ndarray
    path_parameter: np.ndarray
    check: PlanCheck
    time_added: float = 0.0
    displacement: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    shift_end: np.ndarray = field(default_factory=lambda: np.zeros(3))
    remaining: list[Violation] = field(default_factory=list)
    original: PlanCheck | None = None
    pushes: tuple[float, ...] = ()

    @property
    def reason(self) -> str:
        """Why the plan was refused (every remaining violation), "" otherwise."""
        return _reason(self.remaining)

    @property
    def refused_limits(self) -> list[str]:
        """Names of the remaining violated limits, in check order."""
        return list(dict.fromkeys(v.limit for v in self.remaining))

    @property
    def max_displacement(self) -> float:
        """Largest via-point displacement, m."""
        if not len(self.displacement):
            return 0.0
        return float(np.linalg.norm(self.displacement, axis=1).max())


def _reason(violations: list[Violation]) -> str:
    return "; ".join(v.message() for v in violations)


def repair_plan(
    poses: np.ndarray,
    q_start: np.ndarray,
    robot,
    limits: SafetyLimits,
    dt: float,
    clearance_at: ClearanceAt | None = None,
    gradient_at: GradientAt | None = None,
    via_points: ViaPoints | None = None,
    v_start: np.ndarray | None = None,
    shift: np.ndarray | None = None,
    belt_velocity: np.ndarray | None = None,
    config: RepairConfig = RepairConfig(),  # noqa: B008 (frozen, immutable)
) -> RepairResult:
    """Retime, repair or refuse a window plan (see the module docstring).

    Args:
        poses: the window's plan (n, 6), one TCP pose per control period, plan frame
            (robot base frame before any belt shift).
        q_start: joints (6,), rad, the robot is at when the window starts.
        robot: kinematic model (:class:`~distgprl.sim.robot.UR5e`).
        limits: the limits the safety layer enforces.
        dt: control period, s.
        clearance_at: the clearance oracle (obstacles predicted at each control instant's
            time ``k * dt`` after the window's start); None skips clearance.
        gradient_at: the field's distance and gradient, same convention; needed to repair.
        via_points: how the plan depends on its movable via-points; None: no repair.
        v_start: joint velocity (6,), rad/s, at the window's start (default zero).
        shift: belt shift (3,), m, accumulated by earlier re-timed windows (default zero).
        belt_velocity: belt velocity (3,), m/s, while the target is on the belt, else None.
        config: the repair settings.

    Returns:
        The decision, the plan to execute (the given one, shifted, if ``none`` or
        ``refused``) and its check. Never raises for an unsafe plan: the caller refuses
        (``decision == "refused"``) unless forced.
    """
    shift = np.zeros(3) if shift is None else np.asarray(shift, dtype=float)
    velocity0 = np.zeros(6) if v_start is None else np.asarray(v_start, dtype=float)
    args = (q_start, robot, limits, dt, clearance_at, velocity0)
    original = as_candidate(np.asarray(poses, dtype=float), shift, *args)

    def result(decision: str, chosen: Candidate, displacement, remaining=()):
        return RepairResult(
            decision,
            chosen.poses,
            chosen.path_poses,
            chosen.parameter,
            chosen.check,
            float(chosen.added),
            displacement,
            chosen.shift_end,
            list(remaining),
            original.check,
            tuple(history),
        )

    history: list[float] = []
    k = via_points.count if via_points is not None else 0
    zero = np.zeros((k, 3))
    if original.check.ok:
        return result("none", original, zero)

    def refuse(candidate: Candidate) -> RepairResult:
        # the plan as given is returned (what --force executes); the reason is what the
        # best attempt still violates
        return result("refused", original, zero, candidate.check.violations)

    if violated_limits(original.check) - REPAIRABLE_LIMITS:
        return refuse(original)

    def timed(path_poses: np.ndarray) -> Candidate:
        return _timed_candidate(path_poses, shift, args, belt_velocity, config)

    current = timed(np.asarray(poses, dtype=float))
    total = zero.copy()
    can_push = (
        config.repair and via_points is not None and k > 0 and gradient_at is not None
    ) and clearance_at is not None
    if can_push and "clearance" in violated_limits(current.check):
        assert via_points is not None and gradient_at is not None  # as can_push says
        base = np.asarray(via_points.replan(zero), dtype=float)
        influence_base = via_points.influence(base)  # (n, k), rows at plan instants 1..n
        rows = np.vstack([np.zeros((1, k)), influence_base])  # row 0: the fixed start
        target = limits.min_clearance + config.clearance_margin
        step = None
        scale = 1.0
        for _ in range(config.iterations):
            names = violated_limits(current.check)
            if "clearance" not in names or names - REPAIRABLE_LIMITS:
                break
            if step is None:
                step = push_step(current, rows, robot, gradient_at, target, dt)
                if step is None:
                    break  # nothing close depends on the movable via-points
                largest = float(np.linalg.norm(step, axis=1).max())
                step = step * min(1.0, config.step_size / max(largest, 1e-12))  # same direction
            trial = total + scale * step
            norms = np.linalg.norm(trial, axis=1, keepdims=True)
            trial = trial * np.minimum(1.0, config.max_displacement / np.maximum(norms, 1e-12))
            candidate = timed(np.asarray(via_points.replan(trial), dtype=float))
            history.append(float(candidate.check.min_clearance))
            improved = not (violated_limits(candidate.check) - {"clearance"}) and (
                candidate.check.min_clearance > current.check.min_clearance
            )
            if candidate.check.ok or improved:
                current, total, step, scale = candidate, trial, None, 1.0
            else:  # backtrack: half the step from the last accepted plan
                scale *= 0.5
    if not current.check.ok:
        return refuse(current)
    if np.any(total != 0.0):
        return result("repaired", current, total)
    return result("retimed", current, zero)


def _timed_candidate(
    path_poses: np.ndarray,
    shift: np.ndarray,
    args: tuple,
    belt_velocity: np.ndarray | None,
    config: RepairConfig,
) -> Candidate:
    """``path_poses`` as a candidate, re-timed (`retime_plan`) when its check violates a
    kinematic limit and the re-timing finds a plan; ``args`` are `as_candidate`'s (q_start,
    robot, limits, dt, clearance_at, v_start)."""
    candidate = as_candidate(path_poses, shift, *args)
    if config.retime and violated_limits(candidate.check) & KINEMATIC_LIMITS:
        q_start, robot, limits, dt, clearance_at, velocity0 = args
        retimed = retime_plan(
            path_poses,
            q_start,
            robot,
            limits,
            dt,
            clearance_at,
            velocity0,
            shift,
            belt_velocity,
            config,
        )
        if retimed is not None:
            return retimed
    return candidate
