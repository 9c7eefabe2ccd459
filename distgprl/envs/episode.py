"""One decision of an episode, written once: apply the action, plan the segment, let the
safety layer review it, execute it in the world, record what was commanded.

Every episode runs its decisions through `plan_segment` and `execute_segment`: training and
Table I's evaluation (`AdaptationEnv.step`, `ResidualRLEnv.step` in a `SimWorld`), the
evaluation with the safety layer (`distgprl.experiments.safety_layer_evaluation`: a `SimWorld`
behind a gate) and the hardware trials (`distgprl.hardware.trials`: the twin or the robot,
behind the paper's protocol or the safety layer).

The *plan* is the policy-facing adapter (`PlanAdapter`: an `AdaptationEnv` or a
`ResidualRLEnv`); the *world* executes (`distgprl.envs.world.World`); a *gate* stands
between them (`Gate`: the safety layer's review, or the paper's protocol, which only
solves the IK the robot streams).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from distgprl.envs.world import SegmentReport, World

__all__ = [
    "Decision",
    "EpisodeTally",
    "Gate",
    "PlanAdapter",
    "Reviewed",
    "commit_segment",
    "execute_segment",
    "plan_segment",
]


class PlanAdapter(Protocol):
    """The policy-facing side of an episode: what an action changes and what it commands."""

    step_index: int

    def apply_action(self, step: int, action: np.ndarray) -> np.ndarray:
        """Update the plan for decision ``step`` from a raw action; the parameter change."""
        ...

    def segment_poses(self, step: int) -> np.ndarray:
        """The poses (m, 6), m and rad, decision ``step`` commands, one per control period."""
        ...

    def mark_commanded(self, step: int, poses: np.ndarray) -> None:
        """Record that ``poses`` (the executed part of decision ``step``'s path) were
        commanded: the next decision starts from them."""
        ...


@dataclass(frozen=True)
class Reviewed:
    """What a gate lets through of a segment.

    Attributes:
        poses: the poses (n, 6) to execute (retimed, belt-shifted: the safety layer's).
        path_poses: the same instants in the plan's own frame (n, 6): what was commanded.
        joints: the joint targets (n, 6), rad, of ``poses`` (None: the world solves its IK).
        refused: nothing of the segment moves (a protective refusal).
    """

    poses: np.ndarray
    path_poses: np.ndarray
    joints: np.ndarray | None = None
    refused: bool = False


class Gate(Protocol):
    """What stands between a plan and the world (the safety layer, or the paper's protocol)."""

    def review(self, step: int, poses: np.ndarray) -> Reviewed:
        """Check (and where it may, repair) decision ``step``'s ``poses`` (m, 6)."""
        ...

    def executed(self, reviewed: Reviewed, report: SegmentReport) -> None:
        """Track what of ``reviewed`` the world executed (joints and speed at its end)."""
        ...


@dataclass(frozen=True)
class Decision:
    """One decision's outcome: what the gate let through and what the world reported
    (``report`` None: refused, nothing moved)."""

    reviewed: Reviewed
    report: SegmentReport | None

    @property
    def refused(self) -> bool:
        return self.report is None


def plan_segment(plan: PlanAdapter, step: int, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Apply ``action`` to decision ``step`` of ``plan``: (the parameter change, the
    segment's poses (m, 6) to command)."""
    change = plan.apply_action(step, action)
    return change, plan.segment_poses(step)


def commit_segment(plan: PlanAdapter, step: int, path_poses: np.ndarray) -> None:
    """Mark ``path_poses`` (m, 6), what decision ``step`` executed, commanded and move the
    plan on to the next decision."""
    plan.mark_commanded(step, path_poses)
    plan.step_index += 1


def execute_segment(
    plan: PlanAdapter,
    world: World,
    step: int,
    poses: np.ndarray,
    gate: Gate | None = None,
    last: bool = True,
) -> Decision:
    """Pass decision ``step``'s ``poses`` (m, 6) through ``gate`` (None: as they are) and
    execute them in ``world``; the executed part is marked commanded and the plan moves on
    to the next decision. A refused segment moves nothing and the plan stays at ``step``.

    ``last``: the world may end its motion stream after the segment (residual control
    streams its 0.1 s decisions back to back on a robot).
    """
    reviewed = Reviewed(poses, poses) if gate is None else gate.review(step, poses)
    if reviewed.refused:
        return Decision(reviewed, None)
    report = world.execute(reviewed.poses, reviewed.joints, last)
    commit_segment(plan, step, reviewed.path_poses[: report.steps])
    if gate is not None:
        gate.executed(reviewed, report)
    return Decision(reviewed, report)


@dataclass
class EpisodeTally:
    """What an episode's executed segments add up to (`add` each `SegmentReport`).

    Attributes:
        collision: any segment had a contact.
        min_clearance: the least robot/tool-obstacle distance, m (inf before any).
        peak_joint_speed: the largest commanded joint speed, rad/s.
        steps: control periods executed.
    """

    collision: bool = False
    min_clearance: float = field(default=float(np.inf))
    peak_joint_speed: float = 0.0
    steps: int = 0

    def add(self, report: SegmentReport) -> None:
        self.collision |= report.collision
        self.min_clearance = min(self.min_clearance, report.min_clearance)
        self.peak_joint_speed = max(self.peak_joint_speed, report.peak_joint_speed)
        self.steps += report.steps
