"""Plan repair between a window's plan and the pre-flight check: retime, push, or refuse.

A window plan that fails :func:`~distgprl.hardware.safety.check_plan` is not refused at
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

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from distgprl.hardware.safety import (
    PlanCheck,
    SafetyLimits,
    Violation,
    check_plan,
    tool_check_points,
)
from distgprl.sim.transforms import matrix_to_pose, pose_to_matrix
from distgprl.skill.rotations import nearest_equivalent_rotvec

DECISIONS = ("none", "retimed", "repaired", "refused")
"""Per-window outcomes: passed as planned, re-timed, via-points pushed (and possibly
re-timed), refused."""

KINEMATIC_LIMITS = frozenset({"joint_speed", "joint_acceleration", "tcp_speed"})
"""Limits a new timing can fix."""

REPAIRABLE_LIMITS = KINEMATIC_LIMITS | {"clearance"}
"""Limits :func:`repair_plan` tries to fix; any other violation (workspace, IK, joint
limits) is refused at once."""

ClearanceAt = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``(points (m, 3) m, control instants (m,)) -> distance (m,)``, m."""

GradientAt = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``(points (m, 3) m, control instants (m,)) -> (distance (m,) m, unit gradient (m, 3))``."""


@dataclass(frozen=True)
class RepairConfig:
    """Settings of :func:`repair_plan`.

    Attributes:
        retime: re-time plans that are too fast.
        repair: push via-points out of the clearance margin. Off by default: in the twin
            (session of 2026-12-01, `--method demo`, 10 trials) both trials it pushed (by
            3.6-3.9 mm, predicted clearance raised to 5.7 mm) still collided, at the same
            depth as with ``--force``: the predicted clearance it acts on was 7-12 mm off
            the actual contact, so a pushed plan is not known to be safer than the refused
            one. ``distgprl hardware --repair-push`` turns it on.
        limit_scales: fractions of the safety limits handed to TOPP-RA, tried in order until
            the sampled plan passes the discrete check.
        grid_per_step: TOPP-RA grid points per control period of the original plan.
        max_added_s: largest time (s) a window may be lengthened by.
        clearance_margin: the push aims at ``min_clearance + clearance_margin``, m.
        step_size: largest via-point move per push, m.
        max_displacement: largest total displacement of a via-point, m.
        iterations: largest number of pushes.
        follow_belt: keep re-timed plans in the belt's frame while the target bar is on
            the belt (module docstring); False keeps them in the robot base frame.
    """

    retime: bool = True
    repair: bool = False
    limit_scales: tuple[float, ...] = (0.95, 0.85, 0.7, 0.55, 0.4)
    grid_per_step: int = 4
    max_added_s: float = 6.0
    clearance_margin: float = 0.002
    step_size: float = 0.01
    max_displacement: float = 0.03
    iterations: int = 10
    follow_belt: bool = True


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


@dataclass(frozen=True)
class _Candidate:
    poses: np.ndarray
    path_poses: np.ndarray
    parameter: np.ndarray
    check: PlanCheck
    added: float
    shift_end: np.ndarray


def _names(check: PlanCheck) -> set[str]:
    return {v.limit for v in check.violations}


def _reason(violations: list[Violation]) -> str:
    return "; ".join(v.message() for v in violations)


def _shifted(poses: np.ndarray, shift: np.ndarray) -> np.ndarray:
    out = np.array(poses, dtype=float, copy=True)
    out[:, :3] += shift
    return out


def _time_of(s: np.ndarray, sd: np.ndarray, t_grid: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Invert a constant-acceleration-per-interval parameterisation: s at ``times``."""
    index = np.clip(np.searchsorted(t_grid, times, side="right") - 1, 0, len(s) - 2)
    tau = times - t_grid[index]
    ds = s[index + 1] - s[index]
    accel = (sd[index + 1] ** 2 - sd[index] ** 2) / (2.0 * np.maximum(ds, 1e-300))
    value = s[index] + sd[index] * tau + 0.5 * accel * tau**2
    # numerical safety: stay inside the interval, monotone
    return np.clip(value, s[index], s[index + 1])


def retime_plan(
    path_poses: np.ndarray,
    q_start: np.ndarray,
    robot,
    limits: SafetyLimits,
    dt: float,
    clearance_at: ClearanceAt | None = None,
    v_start: np.ndarray | None = None,
    shift: np.ndarray | None = None,
    belt_velocity: np.ndarray | None = None,
    config: RepairConfig = RepairConfig(),
) -> _Candidate | None:
    """Re-time a plan along its path within ``limits`` (module docstring, step 1).

    Args:
        path_poses: plan (n, 6), one pose per control period ``dt`` (s), plan frame.
        q_start: joints (6,), rad, at the window's start; the robot's TCP there is the
            path's start.
        robot: kinematic model (``fk``, ``ik_nearest``, tool points).
        limits: the safety limits.
        dt: control period, s.
        clearance_at: clearance oracle for the final check (control instants of the
            returned plan).
        v_start: joint velocity (6,), rad/s, at the start (default zero).
        shift: belt shift (3,), m, added to every pose (default zero).
        belt_velocity: belt velocity (3,), m/s, while the plan follows the belt, or None.

    Returns:
        The re-timed candidate whose discrete check has no kinematic violation, or None
        if none was found (unreachable path, TOPP-RA failure, more than ``max_added_s``).
    """
    import toppra
    import toppra.algorithm
    import toppra.constraint
    from scipy.interpolate import CubicSpline

    path_poses = np.asarray(path_poses, dtype=float).reshape(-1, 6)
    n = len(path_poses)
    if n == 0:
        return None
    shift = np.zeros(3) if shift is None else np.asarray(shift, dtype=float)
    velocity0 = np.zeros(6) if v_start is None else np.asarray(v_start, dtype=float)
    q_start = np.asarray(q_start, dtype=float)
    start = matrix_to_pose(robot.fk(q_start))
    start[:3] -= shift
    start[3:] = nearest_equivalent_rotvec(start[3:], path_poses[0, 3:])
    knots = np.vstack([start, path_poses])
    s_knots = np.arange(n + 1) * dt
    spline = CubicSpline(s_knots, knots, axis=0)
    s_grid = np.linspace(0.0, n * dt, n * max(1, int(config.grid_per_step)) + 1)
    dense = spline(s_grid)
    tcp_rate = np.linalg.norm(spline(s_grid, 1)[:, :3], axis=1)  # |dp/ds|, m per s of plan
    belt = None if belt_velocity is None else np.asarray(belt_velocity, dtype=float)

    def joint_path(offset: np.ndarray):
        """TOPP-RA path through the IK chain of the spline + shift + ``offset`` (grid, 3)."""
        joints = np.empty((len(s_grid), 6))
        q = joints[0] = q_start
        for i in range(1, len(s_grid)):
            pose = dense[i].copy()
            pose[:3] += shift + offset[i]
            solution = robot.ik_nearest(pose_to_matrix(pose), q)
            if solution is None:
                return None
            q = joints[i] = solution
        # joints + virtual coordinate q_7(s) = s (carries ds/dt <= 1 and the TCP bound)
        return toppra.SplineInterpolator(s_grid, np.hstack([joints, s_grid[:, None]]))

    def parameterise(path, scale: float):
        """(path speeds ds/dt on the grid, times on the grid) within ``scale`` x the limits."""
        v_joint = scale * limits.max_joint_speed
        a_joint = scale * limits.max_joint_acceleration
        v_tcp = scale * limits.max_tcp_speed

        def velocity_limits(s: float) -> np.ndarray:
            rate = float(np.interp(s, s_grid, tcp_rate))
            bound = min(1.0, v_tcp / rate) if rate > 1e-12 else 1.0
            upper = np.array([v_joint] * 6 + [bound])
            return np.stack([-upper, upper], axis=1)

        accel = np.array([a_joint] * 6 + [1e4])
        constraints = [
            toppra.constraint.JointVelocityConstraintVarying(velocity_limits),
            toppra.constraint.JointAccelerationConstraint(np.stack([-accel, accel], axis=1)),
        ]
        instance = toppra.algorithm.TOPPRA(
            constraints, path, gridpoints=s_grid, parametrizer="ParametrizeConstAccel"
        )
        tangent0 = path(0.0, 1)[:6]
        speed0 = float(tangent0 @ velocity0 / max(float(tangent0 @ tangent0), 1e-12))
        for sd_start in dict.fromkeys((min(max(speed0, 0.0), 1.0), 0.0)):
            try:
                _, sd, *_ = instance.compute_parameterization(sd_start, 0.0)
            except Exception:  # toppra raises on some infeasible boundary values
                sd = None
            if sd is None or not np.all(np.isfinite(sd)):
                continue
            sd = np.maximum(np.asarray(sd, dtype=float), 0.0)
            mean = sd[:-1] + sd[1:]
            if np.any(mean <= 0.0):
                continue
            return sd, np.concatenate([[0.0], np.cumsum(2.0 * np.diff(s_grid) / mean)])
        return None

    for scale in config.limit_scales:
        # On a belt the shift v (t(s) - s) depends on the timing being sought: fixed-point
        # iteration (the belt is slow, two or three rounds agree to well under a mm).
        offset = np.zeros((len(s_grid), 3))
        solved = None
        for _ in range(4 if belt is not None else 1):
            path = joint_path(offset)
            if path is None:
                return None
            solved = parameterise(path, scale)
            if solved is None or belt is None:
                break
            update = (solved[1] - s_grid)[:, None] * belt
            converged = float(np.abs(update - offset).max()) < 1e-4
            offset = update
            if converged:
                break
        if solved is None:
            continue
        sd, t_grid = solved
        total = float(t_grid[-1])
        steps = max(1, math.ceil(total / dt - 1e-9))
        added = steps * dt - n * dt
        if added > config.max_added_s:
            continue
        times = np.minimum(np.arange(1, steps + 1) * dt, total)
        parameter = _time_of(s_grid, sd, t_grid, times)
        parameter[-1] = s_grid[-1]
        new_path = spline(parameter)
        lag = np.arange(1, steps + 1) * dt - parameter  # t - s(t) >= 0
        offsets = np.tile(shift, (steps, 1))
        if belt_velocity is not None:
            offsets = offsets + lag[:, None] * np.asarray(belt_velocity, dtype=float)
        poses = new_path.copy()
        poses[:, :3] += offsets
        check = check_plan(
            poses, q_start, robot, limits, dt, clearance_at, force=True, v_start=velocity0
        )
        if not (_names(check) & KINEMATIC_LIMITS):
            return _Candidate(poses, new_path, parameter, check, added, offsets[-1].copy())
    return None


def _as_candidate(path_poses, shift, q_start, robot, limits, dt, clearance_at, v_start):
    """The plan as given (shifted), checked: no new timing."""
    poses = _shifted(path_poses, shift)
    check = check_plan(poses, q_start, robot, limits, dt, clearance_at, force=True, v_start=v_start)
    parameter = np.arange(1, len(poses) + 1) * dt
    return _Candidate(poses, np.asarray(path_poses, float), parameter, check, 0.0, shift.copy())


def _push_step(current, rows, robot, gradient_at, target, dt) -> np.ndarray | None:
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
    config: RepairConfig = RepairConfig(),
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
    original = _as_candidate(np.asarray(poses, dtype=float), shift, *args)

    def result(decision: str, chosen: _Candidate, displacement, remaining=()):
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

    def refuse(candidate: _Candidate) -> RepairResult:
        # the plan as given is returned (what --force executes); the reason is what the
        # best attempt still violates
        return result("refused", original, zero, candidate.check.violations)

    if _names(original.check) - REPAIRABLE_LIMITS:
        return refuse(original)

    def timed(path_poses: np.ndarray) -> _Candidate:
        candidate = _as_candidate(path_poses, shift, *args)
        if config.retime and _names(candidate.check) & KINEMATIC_LIMITS:
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

    current = timed(np.asarray(poses, dtype=float))
    total = zero.copy()
    can_push = (
        config.repair and via_points is not None and k > 0 and gradient_at is not None
    ) and clearance_at is not None
    if can_push and "clearance" in _names(current.check):
        base = np.asarray(via_points.replan(zero), dtype=float)
        influence_base = via_points.influence(base)  # (n, k), rows at plan instants 1..n
        rows = np.vstack([np.zeros((1, k)), influence_base])  # row 0: the fixed start
        target = limits.min_clearance + config.clearance_margin
        step = None
        scale = 1.0
        for _ in range(config.iterations):
            names = _names(current.check)
            if "clearance" not in names or names - REPAIRABLE_LIMITS:
                break
            if step is None:
                step = _push_step(current, rows, robot, gradient_at, target, dt)
                if step is None:
                    break  # nothing close depends on the movable via-points
                largest = float(np.linalg.norm(step, axis=1).max())
                step = step * min(1.0, config.step_size / max(largest, 1e-12))  # same direction
            trial = total + scale * step
            norms = np.linalg.norm(trial, axis=1, keepdims=True)
            trial = trial * np.minimum(1.0, config.max_displacement / np.maximum(norms, 1e-12))
            candidate = timed(np.asarray(via_points.replan(trial), dtype=float))
            history.append(float(candidate.check.min_clearance))
            improved = not (_names(candidate.check) - {"clearance"}) and (
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
