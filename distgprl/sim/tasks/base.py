"""Task configurations, task specifications and the common task-simulation base class.

A *task configuration* (TC) is what varies between episodes: the manipulated object's
start offset and the dynamic obstacle's start offset (both xy, metres, world frame)
from the nominal scene. A :class:`TaskSpec` describes a task (demonstration, nominal TC,
TC sampler, expert, scene revision, fixed evaluation sets); each task module declares one
(``TASK``) and `distgprl.sim.tasks.TASKS` collects them. A :class:`TaskSim` subclass builds
its scene in its own PyBullet client around a robot it is given (a
`distgprl.sim.robot.Robot`, the UR5e by default) and executes Cartesian trajectories with
the control loop of `distgprl.sim.control`.

Time: the simulation clock starts at 0 on :meth:`TaskSim.reset` and advances by
``control_dt`` per executed pose; object and obstacle motion are functions of this clock
and continue across :meth:`TaskSim.execute` calls.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet

from distgprl.errors import UserInputError
from distgprl.safety.shapes import Shape
from distgprl.schema import EVALUATION_SEED, TRAINING_CURVE_SEED
from distgprl.sim.bullet import PhysicsConfig, make_client
from distgprl.sim.control import BulletCalls, ControlLoop, SegmentResult
from distgprl.sim.robot import Robot, RobotFactory, ToolSpec, UR5e
from distgprl.skill.conditioning import conditioning_weights


def _as_xy(value: object, name: str) -> tuple[float, float]:
    array = np.asarray(value, dtype=float).reshape(-1)
    if array.shape != (2,) or not np.all(np.isfinite(array)):
        raise UserInputError(f"{name} must be two finite numbers (x, y in metres), got {value!r}")
    return (float(array[0]), float(array[1]))


@dataclass(frozen=True)
class TaskConfig:
    """One task configuration.

    Attributes:
        object_offset: start offset (dx, dy) of the manipulated object from its nominal
            start, world frame, m. Stored as a tuple; ``np.asarray`` gives shape (2,).
        obstacle_offset: start offset (dx, dy) of the dynamic obstacle from its nominal
            start, world frame, m.
    """

    object_offset: tuple[float, float] = (0.0, 0.0)
    obstacle_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "object_offset", _as_xy(self.object_offset, "object_offset"))
        object.__setattr__(self, "obstacle_offset", _as_xy(self.obstacle_offset, "obstacle_offset"))

    def to_dict(self) -> dict[str, list[float]]:
        """JSON-friendly form."""
        return {
            "object_offset": list(self.object_offset),
            "obstacle_offset": list(self.obstacle_offset),
        }

    @classmethod
    def from_dict(cls, data: dict) -> TaskConfig:
        """Inverse of :meth:`to_dict`."""
        return cls(object_offset=data["object_offset"], obstacle_offset=data["obstacle_offset"])


@dataclass(frozen=True)
class TaskSpec:
    """A task: its demonstration, TC ranges and fixed evaluation sets.

    Attributes:
        name: registry key ("dcp", "dbm").
        title: human-readable name.
        demo_path: the shipped nominal demonstration CSV.
        varied_demo_dir: folder with 20 varied demonstrations and their ``tcs.json``.
        nominal_tc: the TC the demonstration was made for (zero offsets).
        interaction_time: normalised time tau in [0, 1] at which the demonstration engages
            the object (the tool reaches its pre-contact pose next to the object; the
            first physical contact follows within 0.1 in tau). The conditioned skill moves
            via-points from here on by the object offset.
        goal: one-line description of the goal and the success criterion.
        sampler: draws one TC from a generator (see :meth:`sample_tc`).
        make_sim: builds a fresh task simulation (keyword arguments go to its class, e.g.
            ``robot_factory``).
        expert: the scripted expert, TC -> (times (n,) s, poses (n, 6)), that wrote the
            shipped demonstrations (`distgprl.sim.experts`).
        scene_revision: the revision of the simulated scene (`distgprl.data.SCENE_REVISIONS`,
            the pybullet-free catalogue the config hashes read).
        tc_range: the largest object offset the TCs draw on each position axis (x, y, z), m
            (the reach rule: every adaptive method must be able to correct that far;
            docs/findings/protocol.md, rule 2).
        goal_fixed_in_world: whether the task's goal stays where it is when the object is
            offset (DCP's goal region) or moves with the object (DBM's lift above the bar):
            the TC conditioning then brings the post-interaction via-points back to the
            demonstration's end (`conditioning_weights`).
    """

    name: str
    title: str
    demo_path: Path
    varied_demo_dir: Path
    nominal_tc: TaskConfig
    interaction_time: float
    goal: str
    sampler: Callable[[np.random.Generator], TaskConfig]
    make_sim: Callable[..., TaskSim]
    expert: Callable[[TaskConfig], tuple[np.ndarray, np.ndarray]]
    scene_revision: int
    tc_range: tuple[float, float, float] = (0.2, 0.2, 0.0)
    goal_fixed_in_world: bool = False

    def sample_tc(self, rng: np.random.Generator) -> TaskConfig:
        """One random TC drawn with ``rng`` (task-specific ranges, see the task module)."""
        return self.sampler(rng)

    def evaluation_tcs(self, n: int = 100) -> tuple[TaskConfig, ...]:
        """The fixed evaluation TCs (first ``n`` draws from :data:`EVALUATION_SEED`)."""
        rng = np.random.default_rng(EVALUATION_SEED)
        return tuple(self.sampler(rng) for _ in range(n))

    def training_curve_tcs(self, n: int = 20) -> tuple[TaskConfig, ...]:
        """The fixed TCs for learning-curve evaluations (from :data:`TRAINING_CURVE_SEED`)."""
        rng = np.random.default_rng(TRAINING_CURVE_SEED)
        return tuple(self.sampler(rng) for _ in range(n))


class TaskSim:
    """Common machinery of the task simulations (robot + tool + scene in one client).

    Subclasses build the scene in :meth:`_build_scene`, place objects for a TC in
    :meth:`_place`, move the kinematic bodies in :meth:`move_kinematic` and define
    :meth:`task_progress`, :meth:`success`, :meth:`obstacle_shapes`.

    The manipulated object is *conveyed* (moved kinematically at a constant velocity)
    until the robot first touches it; from then on it is a free rigid body under contact
    physics, starting with the conveying velocity.

    Attributes:
        control_dt: control period, s (one pose of :meth:`execute` per period).
        demo_duration: duration of the task's demonstration, s.
        clearance_cutoff: distances above this (m) are reported as this value.
        robot: the robot carrying the task's ``tool`` (a `Robot`).
        calls: the client's per-step PyBullet functions (`BulletCalls`).
        control: the control loop (`ControlLoop`) :meth:`execute` runs.
        time: the world's clock, s.

    Args:
        physics: physics settings (default :class:`PhysicsConfig`: 25 Hz control,
            3 physics steps of 1/75 s per control period).
        clearance_cutoff: see above, m (default 0.10).
        robot_factory: builds the robot in the simulation's client (default `UR5e`).
    """

    tool: ToolSpec
    demo_duration: float
    start_joint_positions: np.ndarray

    def __init__(
        self,
        physics: PhysicsConfig | None = None,
        clearance_cutoff: float = 0.10,
        robot_factory: RobotFactory = UR5e,
    ) -> None:
        physics = physics if physics is not None else PhysicsConfig()
        self.physics = physics
        self.control_dt = physics.control_dt
        self.clearance_cutoff = clearance_cutoff
        self.client = make_client(physics)
        self.robot: Robot = robot_factory(self.client, self.tool)
        self.calls = BulletCalls(self.client)
        self.object_body = -1
        self.obstacle_bodies: tuple[int, ...] = ()
        self.exempt_links: dict[int, frozenset[int]] = {}
        self._build_scene()
        for body, links in self.exempt_links.items():
            for link in links:
                self.client.setCollisionFilterPair(self.robot.body, body, link, -1, 0)
        self.control = ControlLoop(
            self.robot,
            self.calls,
            physics,
            self.object_body,
            self.obstacle_bodies,
            self.exempt_links,
            clearance_cutoff,
        )
        self._initial_state = self.client.saveState()
        self.time = 0.0
        self.tc = TaskConfig()
        self._q_command = np.zeros(6)
        self._object_released = False
        self._object_start = np.zeros(3)
        self._object_velocity = np.zeros(3)
        self._object_quaternion = (0.0, 0.0, 0.0, 1.0)
        self._conveyor = (0.0, 0.0, 0.0, 0.0, 0.0)
        self.reset(TaskConfig())

    # ------------------------------------------------------------------ to implement
    def _build_scene(self) -> None:
        raise NotImplementedError

    def _place(self, tc: TaskConfig) -> None:
        """Set object start/velocity and the obstacles' paths for ``tc``."""
        raise NotImplementedError

    def kinematic_moves(
        self, time: float
    ) -> tuple[tuple[int, tuple[float, float, float], tuple[float, float, float, float]], ...]:
        """The resets (body, position (m), orientation (x, y, z, w)) that put the
        kinematically moved obstacles at their poses for ``time`` (s); pure (plain floats:
        the control loop asks for every physics step of a segment at once)."""
        raise NotImplementedError

    def kinematic_reached(self, time: float) -> None:
        """Record that the kinematic obstacles stand at their poses for ``time`` (s)
        (`moving_obstacle_shapes` of the current time reads it)."""
        raise NotImplementedError

    def move_kinematic(self, time: float) -> None:
        """Put the kinematically moved obstacles at their poses for ``time`` (s)."""
        reset_base_pose = self.calls.reset_base_pose
        for body, position, orientation in self.kinematic_moves(time):
            reset_base_pose(body, position, orientation)
        self.kinematic_reached(time)

    def kinematic_schedule(
        self, times: list[float]
    ) -> list[
        tuple[tuple[int, tuple[float, float, float], tuple[float, float, float, float]], ...]
    ]:
        """`kinematic_moves` at each of ``times`` (s)."""
        moves = self.kinematic_moves
        return [moves(time) for time in times]

    def obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """Every obstacle (static and moving) at its current pose (``time`` None), or
        predicted at episode time ``time`` (s) along the moving obstacles' known paths."""
        raise NotImplementedError

    def moving_obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """The moving (``dynamic``) obstacles of :meth:`obstacle_shapes` (same ``time``)."""
        return tuple(s for s in self.obstacle_shapes(time) if s.dynamic)

    def moving_obstacle_anchors_at(self, times: np.ndarray) -> np.ndarray:
        """The moving obstacles' anchor (the position of their first shape) at each of
        ``times`` (n,), s, shape (n, 3), m; the tasks override it with one vectorised
        formula (the observation's time-indexed clearances, issue 49)."""
        return np.stack(
            [np.asarray(self.moving_obstacle_shapes(float(t))[0].position, float) for t in times]
        )

    def task_progress(self) -> float:
        """Dense task progress in [0, 1]."""
        raise NotImplementedError

    def success(self) -> bool:
        """Whether the task is accomplished in the current state."""
        raise NotImplementedError

    def goal_position(self) -> np.ndarray:
        """Goal point (3,), m, world frame."""
        raise NotImplementedError

    # ------------------------------------------------------------------ public API
    def reset(self, tc: TaskConfig) -> None:
        """Restore the initial world, put the robot at the demo's start and place ``tc``.

        Deterministic: the same TC always gives the same state.
        """
        self.client.restoreState(self._initial_state)
        self.tc = tc
        self.time = 0.0
        self._object_released = False
        self.robot.reset_joints(self.start_joint_positions)
        self._q_command = np.array(self.start_joint_positions, dtype=float)
        self._place(tc)
        self._object_velocity_list = self._object_velocity.tolist()
        x0, y0, z0 = self._object_start.tolist()
        vx, vy = self._object_velocity_list[:2]
        self._conveyor = (x0, y0, z0, vx, vy)
        self.convey_object(0.0)
        self.move_kinematic(0.0)

    def tcp_pose(self) -> np.ndarray:
        """Current TCP pose (6,): x, y, z (m), rx, ry, rz (rad)."""
        return self.robot.tcp_pose()

    def joint_positions(self) -> np.ndarray:
        """Measured joint positions (6,), rad."""
        return self.robot.joint_positions()

    def object_position(self) -> np.ndarray:
        """Centre of the manipulated object (3,), m."""
        return np.asarray(self.client.getBasePositionAndOrientation(self.object_body)[0])

    def object_orientation(self) -> np.ndarray:
        """Quaternion (x, y, z, w) of the manipulated object."""
        return np.asarray(self.client.getBasePositionAndOrientation(self.object_body)[1])

    def tool_points(self) -> np.ndarray:
        """About 50 points (m, 3) on the tool surface, world frame, m."""
        return self.robot.tool_points()

    @property
    def object_released(self) -> bool:
        """True once the robot has touched the object (it then moves freely)."""
        return self._object_released

    def release_object(self) -> None:
        """The robot touched the object: it is no longer conveyed (contact physics only)."""
        self._object_released = True

    @property
    def q_command(self) -> np.ndarray:
        """The last joint target (6,), rad: the IK reference of the next pose."""
        return self._q_command

    @q_command.setter
    def q_command(self, q: np.ndarray) -> None:
        self._q_command = np.asarray(q, dtype=float)

    @property
    def conveying_velocity(self) -> np.ndarray:
        """Velocity (3,), m/s, at which the object is conveyed until it is released (the
        DBM belt, the DCP drift), for the current TC."""
        return np.array(self._object_velocity, dtype=float)

    def configuration_in_collision(
        self, q: np.ndarray, margin: float = 0.0, include_dynamic: bool = False
    ) -> bool:
        """Kinematic check: does the robot at joint positions ``q`` (6,), rad, touch an obstacle?

        True if any robot link or the tool is within ``margin`` (m) of a static obstacle (and
        of the moving ones if ``include_dynamic``). Self-collision is not checked. This moves
        the robot (no dynamics): use a sim instance dedicated to checking (e.g. for HAP).
        """
        self.robot.reset_joints(np.asarray(q, dtype=float))
        dynamic = () if include_dynamic else getattr(self, "dynamic_obstacle_bodies", ())
        robot_body = self.robot.body
        closest_points = self.calls.closest_points
        for body in self.obstacle_bodies:
            if body in dynamic:
                continue
            exempt = self.exempt_links.get(body)
            for point in closest_points(bodyA=robot_body, bodyB=body, distance=margin):
                if point[8] <= margin and (exempt is None or point[3] not in exempt):
                    return True
        return False

    def clearance(self) -> float:
        """Current minimum distance (m) robot/tool to obstacles, capped at the cutoff."""
        return self.control.clearance()

    def execute(
        self,
        poses: np.ndarray,
        stop_on_collision: bool = False,
        clearance_below: float | None = None,
    ) -> SegmentResult:
        """Track Cartesian TCP poses, one per control period, with dynamics
        (`ControlLoop.run`; ``clearance_below`` (m, > 0): only a lower clearance matters,
        ``min_clearance`` is capped there).

        Args:
            poses: shape (n, 6): x, y, z (m), rx, ry, rz (rad), world frame. Pose k is the
                target at the end of control period k of this segment.
            stop_on_collision: end execution after the control period in which a collision
                is detected, as a hardware protective stop ends a trial;
                the remaining poses are not executed (``SegmentResult.stopped``).

        Each pose is converted by IK (branch nearest the previous joint target) into a
        joint target; the joint position controllers move to it, linearly interpolated
        over ``physics.substeps`` physics steps, with feed-forward velocity. Object and
        obstacles keep moving. Collisions are checked after every physics step,
        clearance at every control step.
        """
        return self.control.run(self, poses, stop_on_collision, clearance_below)

    def render_rgb(self, width: int = 320, height: int = 240) -> np.ndarray:
        """An RGB image (height, width, 3) uint8 of the scene (headless TinyRenderer)."""
        view = self.client.computeViewMatrix(
            cameraEyePosition=self.camera_eye,
            cameraTargetPosition=self.camera_target,
            cameraUpVector=[0.0, 0.0, 1.0],
        )
        projection = self.client.computeProjectionMatrixFOV(
            fov=50.0, aspect=width / height, nearVal=0.05, farVal=5.0
        )
        image = self.client.getCameraImage(
            width, height, view, projection, renderer=pybullet.ER_TINY_RENDERER, shadow=0
        )
        rgba = np.asarray(image[2], dtype=np.uint8).reshape(height, width, 4)
        return np.ascontiguousarray(rgba[:, :, :3])

    camera_eye: tuple[float, float, float] = (1.4, -0.9, 0.9)
    camera_target: tuple[float, float, float] = (0.5, 0.0, 0.1)

    def close(self) -> None:
        """Disconnect the PyBullet client (idempotent)."""
        if getattr(self, "client", None) is not None:
            try:
                self.client.disconnect()
            except Exception:  # noqa: BLE001 - already disconnected
                pass
            self.client = None

    def __enter__(self) -> TaskSim:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def convey_object(self, time: float) -> None:
        """Put the conveyed object where the conveyor has it at ``time`` (s), with the
        conveying velocity; nothing once it is released."""
        if self._object_released:
            return
        ((body, position, orientation, linear),) = self.convey_schedule([time])
        self.calls.reset_base_pose(body, position, orientation)
        self.calls.reset_base_velocity(body, linear, (0.0, 0.0, 0.0))

    def convey_schedule(
        self, times: list[float]
    ) -> list[
        tuple[int, tuple[float, float, float], tuple[float, float, float, float], tuple[float, ...]]
    ]:
        """Per time of ``times`` (s), (body, position (m), orientation (x, y, z, w), linear
        velocity (m/s)) of the conveyed object where the conveyor has it then (pure)."""
        x0, y0, z0, vx, vy = self._conveyor  # plain floats of the start and velocity
        body, orientation = self.object_body, self._object_quaternion
        linear = tuple(self._object_velocity_list)
        return [(body, (x0 + vx * t, y0 + vy * t, z0), orientation, linear) for t in times]


def condition_by_translation(
    times: np.ndarray,
    poses: np.ndarray,
    object_offset: np.ndarray,
    interaction_time: float,
    blend: float = 0.15,
    goal_fixed_in_world: bool = False,
) -> np.ndarray:
    """TC conditioning of a dense demonstration by the rule of `distgprl.skill.conditioning`.

    Samples are translated by the object offset (dx, dy, 0) weighted by w(tau): 1 at
    ``interaction_time``, ramping in with a minimum-jerk blend over ``blend`` (in tau) before
    it (the start pose stays put), and after it falling linearly to 0 at the end if
    ``goal_fixed_in_world`` (the push ends at the goal), else staying 1.

    Args:
        times: (n,) s. poses: (n, 6). object_offset: (2,) m.
    Returns:
        The conditioned poses (n, 6).
    """
    tau = (times - times[0]) / (times[-1] - times[0])
    weight = conditioning_weights(tau, interaction_time, goal_fixed_in_world, ramp=blend)
    shifted = np.array(poses, dtype=float, copy=True)
    shifted[:, 0] += weight * float(object_offset[0])
    shifted[:, 1] += weight * float(object_offset[1])
    return shifted


def resample_to_control(times: np.ndarray, poses: np.ndarray, control_dt: float) -> np.ndarray:
    """Poses (k, 6) at the control instants dt, 2 dt, ... up to the end (linear interp.)."""
    count = int(math.floor((times[-1] - times[0]) / control_dt + 1e-9))
    query = times[0] + control_dt * np.arange(1, count + 1)
    return np.stack([np.interp(query, times, poses[:, j]) for j in range(6)], axis=1)


__all__ = [
    "TaskConfig",
    "TaskSim",
    "TaskSpec",
    "condition_by_translation",
    "resample_to_control",
]
