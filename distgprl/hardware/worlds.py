"""The twin and the robot as worlds of the episode loop (`distgprl.envs.world.World`).

`RobotWorld` executes on a robot backend (`distgprl.hardware.backends`: the digital twin or
the UR5e) the joints the gate solved for; `DryRunWorld` executes nothing and predicts where
the robot would be. Both read their state from the perceived scene
(`distgprl.hardware.adapter.PerceivedScene`), which perception and the backend fill.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from distgprl.envs.world import SegmentReport

__all__ = ["DryRunWorld", "RobotWorld"]


class _PerceivedState:
    """The state of a hardware world: the perceived scene's."""

    def __init__(self, scene: Any, control_dt: float) -> None:
        self.scene = scene
        self._control_dt = float(control_dt)

    @property
    def control_dt(self) -> float:
        return self._control_dt

    def tcp_pose(self) -> np.ndarray:
        return self.scene.tcp_pose()

    def object_position(self) -> np.ndarray:
        return self.scene.object_position()

    def goal_position(self) -> np.ndarray:
        return self.scene.goal_position()

    def moving_obstacle_shapes(self, time: float | None = None) -> tuple:
        return self.scene.moving_obstacle_shapes(time)

    def tool_points(self) -> np.ndarray:
        return self.scene.tool_points()


class RobotWorld(_PerceivedState):
    """A robot backend (twin or UR5e) as a world; its state is the perceived ``scene``."""

    def __init__(self, backend: Any, scene: Any, control_dt: float) -> None:
        super().__init__(scene, control_dt)
        self.backend = backend

    def now(self) -> float:
        """The backend's clock, s."""
        return float(self.backend.now())

    def sync_robot(self) -> None:
        """Tell the scene the robot's actual TCP pose, the time and its joints."""
        backend = self.backend
        self.scene.set_robot(backend.tcp_pose(), backend.now(), backend.joint_positions())

    def execute(
        self, poses: np.ndarray, joints: np.ndarray | None = None, last: bool = True
    ) -> SegmentReport:
        """Stream ``joints`` (the gate's IK of ``poses``) to the backend, up to a stop; a
        protective stop counts as a contact unless the twin knows there was none."""
        result = self.backend.execute(joints, poses, last=last)
        return SegmentReport(
            int(result.steps),
            collision=bool(result.protective_stop and result.collision is not False),
            min_clearance=np.inf if result.min_clearance is None else result.min_clearance,
            stopped=bool(result.stopped),
            stop_reason=result.stop_reason,
            protective_stop=bool(result.protective_stop),
            limit_stop=result.limit_stop,
            wall_s=float(result.wall_s),
        )


class DryRunWorld(_PerceivedState):
    """Executes nothing: every pose counts as commanded, and the clock (s) runs on by the
    poses' control periods from ``start`` (what the robot's would read)."""

    def __init__(self, scene: Any, control_dt: float, start: float) -> None:
        super().__init__(scene, control_dt)
        self.clock = float(start)
        self.last_pose: np.ndarray | None = None

    def now(self) -> float:
        """The predicted clock, s."""
        return self.clock

    def sync_robot(self, planned_start: np.ndarray, joints: np.ndarray) -> None:
        """Tell the scene the robot is where the plan left it: the last pose executed (else
        ``planned_start``, the plan's start) at the predicted time, at ``joints``."""
        pose = planned_start if self.last_pose is None else self.last_pose
        self.scene.set_robot(pose, self.clock, joints)

    def execute(
        self, poses: np.ndarray, joints: np.ndarray | None = None, last: bool = True
    ) -> SegmentReport:
        if len(poses):
            self.last_pose = np.asarray(poses[-1], dtype=float).copy()
        self.clock += len(poses) * self.control_dt
        return SegmentReport(len(poses))
