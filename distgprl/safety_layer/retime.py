"""Stage 1 of plan repair: re-time a window plan along its path (TOPP-RA).

The plan keeps its *path* and gets a new *timing* within a fraction of the safety limits,
never faster than the plan itself, ending at rest, kept in the belt's frame while the
target bar rides the belt (:mod:`distgprl.safety_layer.repair` describes the method and the
belt frame; :func:`~distgprl.safety_layer.repair.repair_plan` orchestrates the stages).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from distgprl.limits import SafetyLimits
from distgprl.safety_layer.plan_check import PlanCheck, check_plan
from distgprl.sim.transforms import matrix_to_pose, pose_to_matrix
from distgprl.skill.rotations import nearest_equivalent_rotvec

KINEMATIC_LIMITS = frozenset({"joint_speed", "joint_acceleration", "tcp_speed"})
"""Limits a new timing can fix."""

ClearanceAt = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``(points (m, 3) m, control instants (m,)) -> distance (m,)``, m."""


@dataclass(frozen=True)
class RepairConfig:
    """Settings of :func:`repair_plan`.

    Attributes:
        retime: re-time plans that are too fast.
        repair: push via-points out of the clearance margin. Off by default: in the twin
            (2026-12-01, `--method demo`, 10 trials) both trials it pushed (by
            3.6-3.9 mm, predicted clearance raised to 5.7 mm) still collided, at the same
            depth as with ``--force``: the predicted clearance it acts on was 7-12 mm off
            the actual contact, so a pushed plan is not known to be safer than the refused
            one. ``distgprl hardware --protocol safety-layer --repair-push`` turns it on.
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
class Candidate:
    """A plan the repair may return, checked.

    Attributes:
        poses: TCP poses (n, 6) to execute, one per control period (belt shift included).
        path_poses: the same instants in the plan's own frame (without the shift), (n, 6).
        parameter: plan time (s, original timing) of each instant, (n,).
        check: the check of ``poses``.
        added: s the window got longer (0 unless re-timed).
        shift_end: belt shift (3,), m, in force at the window's end.
    """

    poses: np.ndarray
    path_poses: np.ndarray
    parameter: np.ndarray
    check: PlanCheck
    added: float
    shift_end: np.ndarray


def violated_limits(check: PlanCheck) -> set[str]:
    """Names of the limits ``check`` found violated."""
    return {v.limit for v in check.violations}


def shifted(poses: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``poses`` (n, 6) with the belt shift (3,), m, added to their positions (a copy)."""
    out = np.array(poses, dtype=float, copy=True)
    out[:, :3] += shift
    return out


def as_candidate(path_poses, shift, q_start, robot, limits, dt, clearance_at, v_start):
    """The plan as given (shifted), checked: no new timing."""
    poses = shifted(path_poses, shift)
    check = check_plan(poses, q_start, robot, limits, dt, clearance_at, force=True, v_start=v_start)
    parameter = np.arange(1, len(poses) + 1) * dt
    return Candidate(poses, np.asarray(path_poses, float), parameter, check, 0.0, shift.copy())


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
) -> Candidate | None:
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
    grid = _PathGrid(s_grid, spline(s_grid), np.linalg.norm(spline(s_grid, 1)[:, :3], axis=1))
    belt = None if belt_velocity is None else np.asarray(belt_velocity, dtype=float)

    for scale in config.limit_scales:
        solved = _solve_timing(grid, robot, q_start, shift, belt, limits, scale, velocity0)
        if solved is _UNREACHABLE:
            return None
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
        if not (violated_limits(check) & KINEMATIC_LIMITS):
            return Candidate(poses, new_path, parameter, check, added, offsets[-1].copy())
    return None


@dataclass(frozen=True)
class _PathGrid:
    """The plan's spline sampled on the re-timing grid: path parameter s (g,), s; the
    poses there (g, 6), plan frame; the TCP's rate |dp/ds| (g,), m per s of plan."""

    s: np.ndarray
    poses: np.ndarray
    tcp_rate: np.ndarray


_UNREACHABLE = ("unreachable",)
"""`_solve_timing`'s answer when the path has no IK chain (no limit scale can help)."""


def _solve_timing(grid, robot, q_start, shift, belt, limits, scale, velocity0):
    """Path speeds and grid times within ``scale`` x the limits, or None (infeasible at this
    scale), or `_UNREACHABLE`. On a belt the shift v (t(s) - s) depends on the timing being
    sought: fixed-point iteration (the belt is slow, two or three rounds agree to well
    under a mm)."""
    offset = np.zeros((len(grid.s), 3))
    solved = None
    for _ in range(4 if belt is not None else 1):
        path = _joint_path(grid, robot, q_start, shift + offset)
        if path is None:
            return _UNREACHABLE
        solved = _parameterise(path, grid, limits, scale, velocity0)
        if solved is None or belt is None:
            break
        update = (solved[1] - grid.s)[:, None] * belt
        converged = float(np.abs(update - offset).max()) < 1e-4
        offset = update
        if converged:
            break
    return solved


def _joint_path(grid: _PathGrid, robot, q_start: np.ndarray, offset: np.ndarray):
    """TOPP-RA path through the IK chain of the grid's poses + ``offset`` (g, 3), or None
    where a pose has no IK solution."""
    import toppra

    joints = np.empty((len(grid.s), 6))
    q = joints[0] = q_start
    for i in range(1, len(grid.s)):
        pose = grid.poses[i].copy()
        pose[:3] += offset[i]
        solution = robot.ik_nearest(pose_to_matrix(pose), q)
        if solution is None:
            return None
        q = joints[i] = solution
    # joints + virtual coordinate q_7(s) = s (carries ds/dt <= 1 and the TCP bound)
    return toppra.SplineInterpolator(grid.s, np.hstack([joints, grid.s[:, None]]))


def _parameterise(path, grid: _PathGrid, limits: SafetyLimits, scale: float, velocity0):
    """(path speeds ds/dt on the grid, times on the grid) within ``scale`` x the limits,
    or None."""
    import toppra.algorithm
    import toppra.constraint

    v_joint = scale * limits.max_joint_speed
    a_joint = scale * limits.max_joint_acceleration
    v_tcp = scale * limits.max_tcp_speed

    def velocity_limits(s: float) -> np.ndarray:
        rate = float(np.interp(s, grid.s, grid.tcp_rate))
        bound = min(1.0, v_tcp / rate) if rate > 1e-12 else 1.0
        upper = np.array([v_joint] * 6 + [bound])
        return np.stack([-upper, upper], axis=1)

    accel = np.array([a_joint] * 6 + [1e4])
    constraints = [
        toppra.constraint.JointVelocityConstraintVarying(velocity_limits),
        toppra.constraint.JointAccelerationConstraint(np.stack([-accel, accel], axis=1)),
    ]
    instance = toppra.algorithm.TOPPRA(
        constraints, path, gridpoints=grid.s, parametrizer="ParametrizeConstAccel"
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
        return sd, np.concatenate([[0.0], np.cumsum(2.0 * np.diff(grid.s) / mean)])
    return None
