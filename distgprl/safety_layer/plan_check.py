"""The safety layer's pre-flight plan check, for hardware trials and simulated evaluations.

This project's own layer, run under the ``safety-layer`` protocol beside the paper's
(`distgprl.trial_protocol`), against its own :class:`SafetyLimits` (stricter than the
UR5e's, `distgprl.limits.UR5E_CONTROLLER`).

Before any motion, :func:`check_plan` converts the planned TCP poses to joint positions
(analytic IK, branch nearest the previous configuration, as the backends stream them) and
checks every control instant against :class:`SafetyLimits`:

- ``workspace``: TCP position inside the workspace box (robot base frame);
- ``ik``: every pose reachable within the joint limits;
- ``joint_limits``: joint positions inside the (tightened) joint limits;
- ``joint_speed`` / ``joint_acceleration``: finite differences at the control period;
- ``tcp_speed``: Cartesian TCP speed;
- ``clearance``: distance from the tool's surface points and the flange to the obstacles
  (distance field built from the perceived bars and the static cell geometry, with the
  moving bar predicted along the belt) at least ``min_clearance``.

A violated limit makes :func:`check_plan` raise :class:`UnsafePlanError`, whose message names
the limit, the offending value, the bound and the control instant, unless ``force=True``
(the violations are still returned and recorded). During motion, the robot backend's
`distgprl.hardware.watchdog.Watchdog` stops the robot.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from distgprl.errors import UserInputError
from distgprl.limits import SafetyLimits
from distgprl.sim.transforms import pose_to_matrix


@dataclass(frozen=True)
class Violation:
    """One violated limit.

    Attributes:
        limit: the limit's name (``workspace``, ``joint_speed``, ``clearance``, ...).
        value: the offending value (units of the limit).
        bound: the limit's value.
        index: control instant (row of the plan) where it is worst.
        detail: human-readable detail (joint, axis, ...).
    """

    limit: str
    value: float
    bound: float
    index: int
    detail: str = ""

    def message(self) -> str:
        extra = f" ({self.detail})" if self.detail else ""
        return (
            f"{self.limit}: {self.value:.4g} vs limit {self.bound:.4g} at control step "
            f"{self.index}{extra}"
        )


class UnsafePlanError(UserInputError):
    """A planned motion violates a safety limit (the message names it)."""

    def __init__(self, violations: list[Violation]) -> None:
        self.violations = violations
        names = ", ".join(dict.fromkeys(v.limit for v in violations))
        lines = "; ".join(v.message() for v in violations[:4])
        super().__init__(
            f"unsafe plan refused, violated limit(s): {names} -- {lines}; "
            "nothing was moved (use force=True / --force to override at your own risk)"
        )


@dataclass(frozen=True)
class PlanCheck:
    """Outcome of :func:`check_plan`.

    Attributes:
        joints: joint positions (n, 6), rad, for the plan's poses (IK chain).
        min_clearance: smallest predicted tool/flange clearance, m (inf if unchecked).
        violations: every violated limit (worst instance per limit).
        check_ms: wall time of the check, ms.
    """

    joints: np.ndarray
    min_clearance: float
    violations: list[Violation] = field(default_factory=list)
    check_ms: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.violations


def tool_check_points(robot, q: np.ndarray) -> np.ndarray:
    """Tool surface points plus the flange origin (m + 1, 3), m, for joints ``q`` (6,).

    ``robot`` is a :class:`~distgprl.sim.robot.UR5e` (only its analytic FK is used).
    """
    tool0 = robot.fk_tool0(q)
    local = robot.tool_points_local
    points = local @ tool0[:3, :3].T + tool0[:3, 3]
    return np.vstack([points, tool0[:3, 3]])


def ik_chain(poses: np.ndarray, q_start: np.ndarray, robot) -> tuple[np.ndarray, list[int]]:
    """The joint targets (n, 6), rad, a backend streams for TCP poses (n, 6): each pose's
    analytic IK branch nearest the previous target (``q_start`` (6,), rad, for the first),
    the previous one held where a pose is unreachable; and those poses' indices."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    joints = np.empty((len(poses), 6))
    q = np.asarray(q_start, dtype=float)
    unreachable = []
    for k, pose in enumerate(poses):
        solution = robot.ik_nearest(pose_to_matrix(pose), q)
        if solution is None:
            unreachable.append(k)
        else:
            q = solution
        joints[k] = q
    return joints, unreachable


def _worst(limit: str, excess: np.ndarray, values: np.ndarray, bound: float, detail) -> Violation:
    index = int(np.argmax(excess))
    return Violation(limit, float(values[index]), float(bound), index, detail(index))


def check_plan(
    poses: np.ndarray,
    q_start: np.ndarray,
    robot,
    limits: SafetyLimits,
    dt: float,
    clearance_at: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    force: bool = False,
    v_start: np.ndarray | None = None,
) -> PlanCheck:
    """Check a planned trajectory before it is executed.

    Args:
        poses: planned TCP poses (n, 6), one per control period, robot base frame.
        q_start: joint positions (6,), rad, the robot is at when the plan starts.
        robot: kinematic model (:class:`~distgprl.sim.robot.UR5e`).
        limits: the limits.
        dt: control period, s.
        clearance_at: ``(points (m, 3), step_indices (m,)) -> distances (m,)``, m: the
            obstacle distance of points at given control instants (e.g. the perceived field
            with the moving bar predicted). None skips the clearance check.
        force: return violations instead of raising.
        v_start: joint velocity (6,), rad/s, at the plan's start (for the acceleration
            check of the first step); default zero.

    Raises:
        UnsafePlanError: a limit is violated and ``force`` is False.
    """
    import time

    start = time.perf_counter()
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    n = len(poses)
    violations: list[Violation] = []
    lower = np.asarray(limits.workspace_lower)
    upper = np.asarray(limits.workspace_upper)
    positions = poses[:, :3]
    outside = np.maximum(lower - positions, positions - upper).max(axis=1)
    if n and outside.max() > 0:
        index = int(np.argmax(outside))
        violations.append(
            Violation(
                "workspace",
                float(outside[index]),
                0.0,
                index,
                f"TCP {np.round(positions[index], 3).tolist()} m outside box "
                f"{lower.tolist()}..{upper.tolist()}",
            )
        )
    joints, unreachable = ik_chain(poses, q_start, robot)
    if unreachable:
        violations.append(
            Violation("ik", float(len(unreachable)), 0.0, unreachable[0], "unreachable poses")
        )
    if n:
        j_lower = np.asarray(limits.joint_lower) + limits.joint_margin
        j_upper = np.asarray(limits.joint_upper) - limits.joint_margin
        excess = np.maximum(j_lower - joints, joints - j_upper)
        if excess.max() > 0:
            k, j = (int(i) for i in np.unravel_index(int(np.argmax(excess)), excess.shape))
            violations.append(
                Violation(
                    "joint_limits", float(joints[k, j]), float(j_upper[j]), int(k), f"joint {j}"
                )
            )
        full = np.vstack([np.asarray(q_start, dtype=float), joints])
        velocity = np.diff(full, axis=0) / dt
        speed = np.abs(velocity).max(axis=1)
        if speed.max() > limits.max_joint_speed:
            violations.append(
                _worst(
                    "joint_speed",
                    speed,
                    speed,
                    limits.max_joint_speed,
                    lambda i: f"joint {int(np.argmax(np.abs(velocity[i])))}, rad/s",
                )
            )
        previous = np.zeros(6) if v_start is None else np.asarray(v_start, dtype=float)
        acceleration = np.abs(np.diff(np.vstack([previous, velocity]), axis=0) / dt).max(axis=1)
        if acceleration.max() > limits.max_joint_acceleration:
            violations.append(
                _worst(
                    "joint_acceleration",
                    acceleration,
                    acceleration,
                    limits.max_joint_acceleration,
                    lambda i: "rad/s^2",
                )
            )
        tcp = np.vstack([poses[:1, :3], positions])
        tcp_speed = np.linalg.norm(np.diff(tcp, axis=0), axis=1) / dt
        if tcp_speed.max() > limits.max_tcp_speed:
            violations.append(
                _worst("tcp_speed", tcp_speed, tcp_speed, limits.max_tcp_speed, lambda i: "m/s")
            )
    min_clearance = math.inf
    if clearance_at is not None and n:
        points = [tool_check_points(robot, q) for q in joints]
        counts = len(points[0])
        steps = np.repeat(np.arange(n), counts)
        distance = np.asarray(clearance_at(np.concatenate(points), steps)).reshape(n, counts)
        per_step = distance.min(axis=1)
        min_clearance = float(per_step.min())
        if min_clearance < limits.min_clearance:
            violations.append(
                _worst(
                    "clearance",
                    -per_step,
                    per_step,
                    limits.min_clearance,
                    lambda i: "m, tool/flange to obstacles",
                )
            )
    check = PlanCheck(joints, min_clearance, violations, 1000.0 * (time.perf_counter() - start))
    if violations and not force:
        raise UnsafePlanError(violations)
    return check


def check_calibration_limits(limits: SafetyLimits) -> None:
    """Reject inconsistent limits (raises :class:`UserInputError` naming the field)."""
    if np.any(np.asarray(limits.workspace_lower) >= np.asarray(limits.workspace_upper)):
        raise UserInputError("safety limits: workspace_lower must be below workspace_upper")
    for name in ("max_joint_speed", "max_joint_acceleration", "max_tcp_speed"):
        if getattr(limits, name) <= 0:
            raise UserInputError(f"safety limits: {name} must be positive")
