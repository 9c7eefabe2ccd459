"""What stands between a plan and the world (`distgprl.envs.episode.Gate`), one class per
protocol:

- `UncheckedGate` — the paper's protocol: the poses go as made; only their IK is solved
  (the joints a robot streams), the robot's controller alone enforces its limits;
- `CheckGate` — the safety layer without repair: the pre-flight check
  (`distgprl.safety_layer.plan_check.check_plan`), an unsafe plan refused (or, with ``force``,
  executed with its violations recorded);
- `RepairGate` — the safety layer with repair (`distgprl.safety_layer.repair.repair_plan`):
  an unsafe plan retimed, its via-points pushed along the distance field's gradient (only
  with ``config.repair``), or refused; pushed via-points are written back into the plan.

Each gate tracks the joints the robot was commanded to (its IK of the executed poses) and
their speed, where the next decision's check starts, and keeps a `Review` of every decision.
The clearance it checks against comes from ``obstacle_shapes(time)``: the simulation's own
obstacles predicted along their known paths, or the perceived world's.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from distgprl.envs.episode import Reviewed
from distgprl.envs.world import SegmentReport
from distgprl.limits import SafetyLimits
from distgprl.safety_layer.plan_check import PlanCheck, UnsafePlanError, check_plan, ik_chain
from distgprl.safety_layer.repair import RepairResult, repair_plan
from distgprl.safety_layer.retime import RepairConfig
from distgprl.safety_layer.window_check import (
    clearance_function,
    gradient_function,
    movable_via_points,
)
from distgprl.trial_protocol import UNCHECKED

__all__ = ["CheckGate", "RepairGate", "Review", "UncheckedGate"]


@dataclass(frozen=True)
class Review:
    """What a gate decided for one decision.

    Attributes:
        decision: ``UNCHECKED`` (the paper's protocol), ``none``, ``retimed``, ``repaired``
            or ``refused`` (`distgprl.safety_layer.repair.DECISIONS`).
        check: the pre-flight check of the poses let through (None: refused by the check).
        refused: nothing of the decision moved.
        time_added: s the decision got longer (retiming).
        displacement: the largest via-point push, m.
        refused_limits: the limits a refused (or forced) plan violates, in order.
        reason: why it was refused ("" if it was not).
        repair: the repair's result (`RepairGate` only).
    """

    decision: str
    check: PlanCheck | None
    refused: bool = False
    time_added: float = 0.0
    displacement: float = 0.0
    refused_limits: tuple[str, ...] = ()
    reason: str = ""
    repair: RepairResult | None = None


class _JointTracking:
    """The commanded joints (6,), rad, and their speed (6,), rad/s, at the end of what was
    executed: where the next decision's check starts."""

    def __init__(self, robot, limits: SafetyLimits, dt: float, q: np.ndarray) -> None:
        self.robot = robot
        self.limits = limits
        self.dt = float(dt)
        self.q = np.asarray(q, dtype=float)
        self.velocity = np.zeros(6)
        self.reviews: list[Review] = []
        self.seconds = 0.0
        """Time spent checking (and repairing), s."""

    @property
    def last(self) -> Review:
        """The latest decision's review."""
        return self.reviews[-1]

    def executed(self, reviewed: Reviewed, report: SegmentReport) -> None:
        if report.steps:
            joints = reviewed.joints
            assert joints is not None  # every gate solves the IK of what it lets through
            previous = joints[report.steps - 2] if report.steps > 1 else self.q
            self.q = joints[report.steps - 1]
            self.velocity = (self.q - previous) / self.dt


class UncheckedGate(_JointTracking):
    """The paper's protocol: the poses go as made, with their IK from the commanded joints."""

    def review(self, step: int, poses: np.ndarray) -> Reviewed:
        check = PlanCheck(ik_chain(poses, self.q, self.robot)[0], np.inf)
        self.reviews.append(Review(UNCHECKED, check))
        return Reviewed(poses, poses, check.joints)


class _Clearance(_JointTracking):
    """A gate that predicts the clearance: ``field`` moved to ``obstacle_shapes(time)`` at
    each group of control instants from ``clock()`` (the decision's start time, s)."""

    def __init__(
        self,
        robot,
        limits: SafetyLimits,
        dt: float,
        q: np.ndarray,
        field,
        obstacle_shapes: Callable[[float], tuple],
        clock: Callable[[], float],
        force: bool = False,
    ) -> None:
        super().__init__(robot, limits, dt, q)
        self.field = field
        self.obstacle_shapes = obstacle_shapes
        self.clock = clock
        self.force = force


class CheckGate(_Clearance):
    """The safety layer's pre-flight check without repair: an unsafe plan is refused, or
    with ``force`` executed (its violations recorded in the review)."""

    def review(self, step: int, poses: np.ndarray) -> Reviewed:
        clearance_at = clearance_function(self.field, self.obstacle_shapes, self.clock(), self.dt)
        try:
            check = check_plan(
                poses,
                self.q,
                self.robot,
                self.limits,
                self.dt,
                clearance_at,
                force=self.force,
                v_start=self.velocity,
            )
        except UnsafePlanError as refused:
            limits = tuple(dict.fromkeys(v.limit for v in refused.violations))
            self.reviews.append(
                Review("refused", None, True, refused_limits=limits, reason=str(refused))
            )
            return Reviewed(poses, poses, refused=True)
        limits = tuple(dict.fromkeys(v.limit for v in check.violations))
        decision = "refused" if check.violations else "none"
        self.reviews.append(Review(decision, check, refused_limits=limits))
        self.seconds += check.check_ms / 1000.0
        return Reviewed(poses, poses, check.joints)


class RepairGate(_Clearance):
    """The safety layer with repair (`repair_plan`) of ``plan``'s decisions.

    Args (beyond `CheckGate`'s): ``plan`` the adapter whose via-points a push moves (its
    ``gamma`` and ``layout``), ``belt()`` the velocity (3,), m/s, the object is conveyed
    with now (None once it is not: lifted, or touched), ``config`` the repair settings. A
    plan retimed while the object is conveyed follows the belt (`distgprl.safety_layer.repair`,
    "belt frame"); the belt shift accumulates over the episode.
    """

    def __init__(
        self,
        plan,
        robot,
        limits: SafetyLimits,
        dt: float,
        q: np.ndarray,
        field,
        obstacle_shapes: Callable[[float], tuple],
        clock: Callable[[], float],
        belt: Callable[[], np.ndarray | None],
        config: RepairConfig,
        force: bool = False,
    ) -> None:
        super().__init__(robot, limits, dt, q, field, obstacle_shapes, clock, force)
        self.plan = plan
        self.belt = belt
        self.config = config
        self.shift = np.zeros(3)

    def review(self, step: int, poses: np.ndarray) -> Reviewed:
        started = time.perf_counter()
        now = self.clock()
        belt = self.belt()
        movable = movable_via_points(self.plan, step)
        result = repair_plan(
            poses,
            self.q,
            self.robot,
            self.limits,
            self.dt,
            clearance_function(self.field, self.obstacle_shapes, now, self.dt),
            gradient_function(self.field, self.obstacle_shapes, now, self.dt),
            None if movable is None else movable[0],
            v_start=self.velocity,
            shift=self.shift,
            belt_velocity=belt if belt is not None and self.config.follow_belt else None,
            config=self.config,
        )
        if result.decision == "repaired" and movable is not None:
            self.plan.gamma[movable[1], :3] += result.displacement
        self.seconds += time.perf_counter() - started
        refused = result.decision == "refused" and not self.force
        self.reviews.append(
            Review(
                result.decision,
                result.check,
                refused,
                result.time_added,
                result.max_displacement,
                tuple(result.refused_limits),
                result.reason,
                result,
            )
        )
        if refused:
            return Reviewed(poses, poses, refused=True)
        self.shift = result.shift_end
        return Reviewed(result.poses, result.path_poses, result.check.joints)
