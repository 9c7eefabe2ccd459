"""Where a plan is executed: a *world* behind one small interface.

A world executes a segment of TCP poses (one per control period), reports what happened
(contacts, clearances, how far it got) and lets its state be read (TCP pose, object, goal,
obstacles). The episode loop (`distgprl.envs.episode`) drives every world the same way:

- :class:`SimWorld` — the task simulation (`TaskSim.execute`), what training and Table I's
  evaluation run in;
- the simulation behind the safety layer (`SimWorld` with a gate, `distgprl.envs.episode`);
- the digital twin and the robot (`distgprl.hardware.worlds`), behind the paper's protocol
  or the safety layer.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Callable

    from distgprl.safety.shapes import Shape
    from distgprl.sim.tasks.base import TaskSim

__all__ = ["SegmentReport", "SimWorld", "World", "WorldState"]


@dataclass(frozen=True)
class SegmentReport:
    """What a world reports after executing a segment.

    Attributes:
        steps: control periods executed (fewer than the segment's poses: it stopped).
        collision: a contact between the robot or tool and an obstacle.
        min_clearance: least robot/tool-obstacle distance over the executed periods, m
            (negative: penetration; inf where the world does not measure it).
        peak_joint_speed: largest commanded joint speed, rad/s (0 where not measured).
        stopped: execution ended before the segment's last pose (a contact or a stop).
        tool_clearances: the tool points' distances (k,), m, to the obstacles where they
            are after each of the segment's samples (`SimWorld` with a field; else empty).
        stop_reason: why it stopped ("" if it did not).
        protective_stop: the robot's controller stopped it (a contact or a limit).
        limit_stop: the controller's limit the command exceeded where the stop was at a
            limit, not a contact ("" otherwise).
        wall_s: wall-clock time the execution took, s (0 where not measured).
    """

    steps: int
    collision: bool = False
    min_clearance: float = float(np.inf)
    peak_joint_speed: float = 0.0
    stopped: bool = False
    tool_clearances: tuple[np.ndarray, ...] = ()
    stop_reason: str = ""
    protective_stop: bool = False
    limit_stop: str = ""
    wall_s: float = 0.0


class WorldState(Protocol):
    """What an episode reads of its world (the observation's inputs)."""

    def tcp_pose(self) -> np.ndarray:
        """The TCP pose (6,), m and rad."""
        ...

    def object_position(self) -> np.ndarray:
        """The object's position (3,), m."""
        ...

    def goal_position(self) -> np.ndarray:
        """The goal position (3,), m."""
        ...

    def moving_obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """The moving obstacles now (``time`` None) or predicted at episode time ``time`` (s)."""
        ...

    def tool_points(self) -> np.ndarray:
        """The tool's surface points (k, 3), m."""
        ...


class World(WorldState, Protocol):
    """What the episode loop needs of a world: its state, and execution."""

    @property
    def control_dt(self) -> float:
        """Control period, s (one pose per period)."""
        ...

    def execute(
        self, poses: np.ndarray, joints: np.ndarray | None = None, last: bool = True
    ) -> SegmentReport:
        """Execute ``poses`` (m, 6), m and rad, one per control period; ``joints`` (m, 6),
        rad, the safety layer's IK of them where it has one (a robot streams them; a
        simulation runs its own IK); ``last``: the robot may end its stream after them."""
        ...


class SimWorld:
    """The task simulation as a world: a segment runs in ``samples`` consecutive chunks
    (`TaskSim.execute`), stopping after the chunk of a contact with ``stop_on_collision``.

    Args:
        sim: the task simulation.
        stop_on_collision: a contact ends execution in its control period (a protective stop).
        samples: chunks per segment; with ``tool_clearance``, the tool's clearance is
            reported after each (`SegmentReport.tool_clearances`, what r_sd is computed from).
        tool_clearance: ``() -> distances (k,)``, m, of the tool points to the obstacles where
            they are now (the distance field the observation reads; None: not reported).
        cap_at_minimum: pass the episode's clearance minimum so far to the simulation
            (``clearance_below``): only a new minimum is searched for (same values).
    """

    def __init__(
        self,
        sim: TaskSim,
        stop_on_collision: bool = False,
        samples: int = 1,
        tool_clearance: Callable[[], np.ndarray] | None = None,
        cap_at_minimum: bool = False,
    ) -> None:
        self.sim = sim
        self.stop_on_collision = stop_on_collision
        self.samples = samples
        self.tool_clearance = tool_clearance
        self.cap_at_minimum = cap_at_minimum
        self.episode_min_clearance = float(np.inf)

    @property
    def control_dt(self) -> float:
        return float(self.sim.control_dt)

    def begin_episode(self) -> None:
        """Forget the clearance minimum (`cap_at_minimum`): a new episode starts."""
        self.episode_min_clearance = float(np.inf)

    def execute(
        self, poses: np.ndarray, joints: np.ndarray | None = None, last: bool = True
    ) -> SegmentReport:
        """Execute ``poses`` (m, 6) in the simulation (its own IK: ``joints`` and ``last``
        are for a robot)."""
        steps, collision, stopped = 0, False, False
        min_clearance, peak = float(np.inf), 0.0
        clearances: list[np.ndarray] = []
        for chunk in np.array_split(np.arange(len(poses)), self.samples):
            if len(chunk) == 0:
                continue
            cap = {"clearance_below": self._clearance_below()} if self.cap_at_minimum else {}
            result = self.sim.execute(poses[chunk], stop_on_collision=self.stop_on_collision, **cap)
            steps += result.steps
            collision |= result.collision
            stopped |= result.stopped
            min_clearance = min(min_clearance, result.min_clearance)
            self.episode_min_clearance = min(self.episode_min_clearance, result.min_clearance)
            peak = max(peak, result.peak_joint_speed)
            if self.tool_clearance is not None:
                clearances.append(self.tool_clearance())
            if self.stop_on_collision and result.collision:
                break
        return SegmentReport(
            steps,
            collision,
            min_clearance,
            peak,
            stopped=stopped or steps < len(poses),
            tool_clearances=tuple(clearances),
        )

    def _clearance_below(self) -> float | None:
        """Only a new episode minimum matters (the queries look no farther; same values)."""
        below = self.episode_min_clearance
        return below if 0.0 < below < np.inf else None

    # -- the state ----------------------------------------------------------------------------
    def tcp_pose(self) -> np.ndarray:
        return self.sim.tcp_pose()

    def object_position(self) -> np.ndarray:
        return self.sim.object_position()

    def goal_position(self) -> np.ndarray:
        return self.sim.goal_position()

    def moving_obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        return self.sim.moving_obstacle_shapes(time)

    def moving_obstacle_anchors_at(self, times: np.ndarray) -> np.ndarray:
        """The moving obstacles' anchor at each of ``times`` (n,), s, shape (n, 3), m."""
        return self.sim.moving_obstacle_anchors_at(times)

    def tool_points(self) -> np.ndarray:
        return self.sim.tool_points()
