"""DCP: dynamic cube pushing with a shovel (paper §V-A).

Scene (world = UR base frame, m; the robot stands on the table at the origin):

- table: static obstacle, ``Box``, top face z = 0, x in [0.12, 1.2], y in [-0.8, 0.8].
- wall: static obstacle, ``Box``, face at x = 0.79, y in [-0.45, 0.45], 0.15 m tall.
- target cube (manipulated object): 5 cm, 0.2 kg, friction 0.5; drifts at
  ``drift_velocity`` until the tool touches it, then moves freely under contact physics.
- obstacle cube (dynamic obstacle, ``Box``): 6 cm, moved kinematically along
  x(t) = cx + A sin(2 pi t / T + phase) at a fixed y.
- goal: a rectangle on the table (visual only), ``goal_centre`` +- ``goal_half_extents``.

TC: ``object_offset`` shifts the target cube's start, uniform in a disk of radius 0.20 m;
``obstacle_offset`` shifts the obstacle's path (its centre line), uniform in a disk of
radius 0.10 m.

Success: the target cube's centre lies inside the goal rectangle (and the cube is on the
table). Progress: fraction of the initial cube-to-goal distance covered.

The robot stands on a pedestal at the table's edge (base at table height, the table
starts at x = 0.12 m), so no robot link is exempt: every robot/tool contact with the
table, the wall or the obstacle cube is a collision. The table is a box (not PyBullet's
infinite plane, whose single-point contact lets a pushed cube sink), described to the
distance field as the same box.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from distgprl.data import DEMO_DIR, SCENE_REVISIONS
from distgprl.safety.shapes import Box, Shape
from distgprl.sim.bullet import create_shape_body
from distgprl.sim.profiles import minimum_jerk
from distgprl.sim.robot import SHOVEL
from distgprl.sim.tasks.base import TaskConfig, TaskSim, TaskSpec
from distgprl.sim.transforms import pose_to_matrix

IDENTITY = np.eye(3)
_UNIT = (0.0, 0.0, 0.0, 1.0)  # the identity quaternion (x, y, z, w)


@dataclass(frozen=True)
class DCPScene:
    """Geometry and motion constants of the DCP scene (m, s, kg)."""

    table_centre: tuple[float, float, float] = (0.66, 0.0, -0.05)
    table_half_extents: tuple[float, float, float] = (0.54, 0.8, 0.05)
    wall_centre: tuple[float, float, float] = (0.80, 0.0, 0.075)
    wall_half_extents: tuple[float, float, float] = (0.01, 0.45, 0.075)
    cube_half: float = 0.025
    cube_mass: float = 0.2
    cube_start: tuple[float, float] = (0.56, -0.20)
    drift_velocity: tuple[float, float] = (0.0, -0.02)
    obstacle_half: float = 0.03
    obstacle_centre: tuple[float, float] = (0.50, 0.02)
    obstacle_amplitude: float = 0.15
    obstacle_period: float = 4.0
    obstacle_phase: float = -0.236
    goal_centre: tuple[float, float] = (0.56, 0.22)
    goal_half_extents: tuple[float, float] = (0.12, 0.10)
    object_offset_radius: float = 0.20
    obstacle_offset_radius: float = 0.10
    start_pose: tuple[float, ...] = (0.35, -0.25, 0.30, 0.0, 0.0, 0.0)


SCENE = DCPScene()
HOME = np.array([2.2, -1.75, 1.6, -1.42, -1.571, -2.51])
"""Reference configuration (elbow up, wrist down) that picks the start IK branch."""


def engagement_time() -> float:
    """Time (s) at which the DCP expert reaches its engage pose behind the cube."""
    return 2.0


def sample_dcp_tc(rng: np.random.Generator) -> TaskConfig:
    """Object offset uniform in a 0.20 m disk, obstacle offset uniform in a 0.10 m disk."""

    def disk(radius: float) -> tuple[float, float]:
        r = radius * math.sqrt(rng.uniform())
        angle = rng.uniform(0.0, 2.0 * math.pi)
        return (r * math.cos(angle), r * math.sin(angle))

    return TaskConfig(
        object_offset=disk(SCENE.object_offset_radius),
        obstacle_offset=disk(SCENE.obstacle_offset_radius),
    )


class DCPSim(TaskSim):
    """Dynamic cube pushing simulation (see the module docstring for the scene)."""

    tool = SHOVEL
    demo_duration = 4.8
    camera_eye = (1.35, -0.75, 0.75)
    camera_target = (0.55, 0.0, 0.05)

    def __init__(self, scene: DCPScene = SCENE, **kwargs) -> None:
        self.scene = scene
        super().__init__(**kwargs)

    def _build_scene(self) -> None:
        scene = self.scene
        start = self.robot.ik_nearest(pose_to_matrix(np.asarray(scene.start_pose)), HOME)
        assert start is not None, "the scene's start pose has no IK solution"
        self.start_joint_positions = start
        client = self.client
        self._table = Box(
            "table",
            np.asarray(scene.table_centre),
            IDENTITY,
            np.asarray(scene.table_half_extents),
        )
        self._wall = Box(
            "wall", np.asarray(scene.wall_centre), IDENTITY, np.asarray(scene.wall_half_extents)
        )
        self._obstacle_template = Box(
            "obstacle_cube",
            np.zeros(3),
            IDENTITY,
            np.full(3, scene.obstacle_half),
            dynamic=True,
        )
        self.table_body = create_shape_body(client, self._table, (0.82, 0.8, 0.75, 1.0))
        self.wall_body = create_shape_body(client, self._wall, (0.6, 0.45, 0.35, 1.0))
        obstacle_start = Box(
            "obstacle_cube",
            np.array([*scene.obstacle_centre, scene.obstacle_half]),
            IDENTITY,
            np.full(3, scene.obstacle_half),
        )
        self.obstacle_body = create_shape_body(client, obstacle_start, (0.85, 0.2, 0.2, 1.0))
        cube = Box(
            "target_cube",
            np.array([*scene.cube_start, scene.cube_half]),
            IDENTITY,
            np.full(3, scene.cube_half),
        )
        self.object_body = create_shape_body(
            client, cube, (0.2, 0.4, 0.9, 1.0), mass=scene.cube_mass, lateral_friction=0.5
        )
        goal_visual = client.createVisualShape(
            3,  # GEOM_BOX
            halfExtents=[*scene.goal_half_extents, 0.0008],
            rgbaColor=[0.2, 0.8, 0.3, 0.6],
        )
        client.createMultiBody(
            baseMass=0.0,
            baseVisualShapeIndex=goal_visual,
            basePosition=[*scene.goal_centre, 0.0008],
        )
        self.obstacle_bodies = (self.table_body, self.wall_body, self.obstacle_body)
        self.dynamic_obstacle_bodies = (self.obstacle_body,)
        self.exempt_links = {}
        # (3,), m: an array here, plain floats from `move_kinematic`
        self._obstacle_position: np.ndarray | tuple[float, float, float] = np.array(
            [*scene.obstacle_centre, scene.obstacle_half]
        )
        self._obstacle_line = np.array(scene.obstacle_centre)
        self._start_cube_xy = np.array(scene.cube_start)

    def _place(self, tc: TaskConfig) -> None:
        scene = self.scene
        start_xy = np.asarray(scene.cube_start) + np.asarray(tc.object_offset)
        # a hair above the table so the conveyed cube never starts in penetration
        self._object_start = np.array([start_xy[0], start_xy[1], scene.cube_half + 1e-4])
        self._object_velocity = np.array([*scene.drift_velocity, 0.0])
        self._obstacle_line = np.asarray(scene.obstacle_centre) + np.asarray(tc.obstacle_offset)
        line_x, line_y = self._obstacle_line.tolist()
        # 2.0 * math.pi * time is (2.0 * math.pi) * time: the same operations as
        # `obstacle_position_at`
        self._obstacle_motion = (
            line_x,
            line_y,
            scene.obstacle_half + 1e-4,
            scene.obstacle_amplitude,
            2.0 * math.pi,
            scene.obstacle_period,
            scene.obstacle_phase,
        )
        self._start_cube_xy = start_xy

    def obstacle_position_at(self, time: float) -> np.ndarray:
        """Centre (3,), m, of the obstacle cube at ``time`` s for the current TC."""
        scene = self.scene
        phase = 2.0 * math.pi * time / scene.obstacle_period + scene.obstacle_phase
        return np.array(
            [
                self._obstacle_line[0] + scene.obstacle_amplitude * math.sin(phase),
                self._obstacle_line[1],
                scene.obstacle_half + 1e-4,
            ]
        )

    def moving_obstacle_anchors_at(self, times: np.ndarray) -> np.ndarray:
        """`obstacle_position_at` at each of ``times`` (n,), s, at once, shape (n, 3), m."""
        scene = self.scene
        times = np.asarray(times, dtype=float)
        phase = 2.0 * math.pi * times / scene.obstacle_period + scene.obstacle_phase
        anchors = np.empty((phase.size, 3))
        anchors[:, 0] = self._obstacle_line[0] + scene.obstacle_amplitude * np.sin(phase)
        anchors[:, 1] = self._obstacle_line[1]
        anchors[:, 2] = scene.obstacle_half + 1e-4
        return anchors

    def kinematic_moves(
        self, time: float
    ) -> tuple[tuple[int, tuple[float, float, float], tuple[float, float, float, float]], ...]:
        """The obstacle cube at `obstacle_position_at` ``time`` (s) (plain floats: asked for
        every physics step)."""
        line_x, line_y, height, amplitude, angular, period, phase0 = self._obstacle_motion
        phase = angular * time / period + phase0
        return (
            (self.obstacle_body, (line_x + amplitude * math.sin(phase), line_y, height), _UNIT),
        )

    def kinematic_reached(self, time: float) -> None:
        """The obstacle cube stands at `obstacle_position_at` ``time`` (s)."""
        self._obstacle_position = self.kinematic_moves(time)[0][1]

    def obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """Table (box), wall and obstacle cube, as EDF primitives.

        The cube is at its current pose, or on its known path at episode time ``time`` (s).
        """
        return (self._table, self._wall, *self.moving_obstacle_shapes(time))

    def moving_obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """The obstacle cube, now or at episode time ``time`` (s)."""
        position = self._obstacle_position if time is None else self.obstacle_position_at(time)
        half = np.full(3, self.scene.obstacle_half)
        return (Box("obstacle_cube", np.array(position, dtype=float), IDENTITY, half, True),)

    def goal_position(self) -> np.ndarray:
        """Centre of the goal region at cube-centre height (3,), m."""
        return np.array([*self.scene.goal_centre, self.scene.cube_half])

    def in_goal(self, position: np.ndarray) -> bool:
        """Whether a cube centre (3,) counts as inside the goal region (and on the table)."""
        centre = np.asarray(self.scene.goal_centre)
        half = np.asarray(self.scene.goal_half_extents)
        inside = bool(np.all(np.abs(np.asarray(position[:2]) - centre) <= half))
        return inside and float(position[2]) < 2.0 * self.scene.cube_half

    def success(self) -> bool:
        """The target cube's centre is inside the goal region, on the table."""
        return self.in_goal(self.object_position())

    def task_progress(self) -> float:
        """1 - (cube-goal distance) / (initial cube-goal distance), in [0, 1]; 1 in the goal."""
        position = self.object_position()
        if self.in_goal(position):
            return 1.0
        goal = np.asarray(self.scene.goal_centre)
        initial = float(np.linalg.norm(self._start_cube_xy - goal))
        now = float(np.linalg.norm(position[:2] - goal))
        return float(np.clip(1.0 - now / max(initial, 1e-9), 0.0, 1.0))


def dcp_expert(tc: TaskConfig) -> tuple[np.ndarray, np.ndarray]:
    """Demonstration (times (n,), poses (n, 6)) pushing the drifting cube into the goal.

    Key poses: start -> above and behind the cube -> engage (blade 2 cm behind the cube,
    8 mm above the table, square to the cube-to-goal direction) -> push the cube centre
    onto the goal centre -> retreat up and back.
    """
    scene = SCENE
    t_engage = engagement_time()
    cube = np.asarray(scene.cube_start) + np.asarray(tc.object_offset)
    cube_engage = cube + np.asarray(scene.drift_velocity) * t_engage
    goal = np.asarray(scene.goal_centre)
    direction = goal - cube_engage
    direction /= np.linalg.norm(direction)
    yaw = math.atan2(direction[1], direction[0]) - math.pi / 2.0
    start = np.asarray(scene.start_pose, dtype=float)

    def pose(xy: np.ndarray, z: float) -> np.ndarray:
        return np.array([xy[0], xy[1], z, 0.0, 0.0, yaw])

    back = scene.cube_half + 0.02
    key_poses = np.stack(
        [
            start,
            pose(cube_engage - direction * (back + 0.05), 0.10),
            pose(cube_engage - direction * back, 0.008),
            pose(goal - direction * scene.cube_half, 0.008),
            pose(goal - direction * (scene.cube_half + 0.10), 0.15),
        ]
    )
    key_times = np.array([0.0, 1.4, t_engage, 4.0, 4.8])
    return minimum_jerk(key_times, key_poses)


TASK = TaskSpec(
    name="dcp",
    title="Dynamic cube pushing",
    demo_path=DEMO_DIR / "dcp.csv",
    varied_demo_dir=DEMO_DIR / "dcp_varied",
    nominal_tc=TaskConfig(),
    interaction_time=engagement_time() / DCPSim.demo_duration,
    goal="push the drifting cube with the shovel until its centre lies in the goal rectangle",
    sampler=sample_dcp_tc,
    make_sim=DCPSim,
    expert=dcp_expert,
    scene_revision=SCENE_REVISIONS["dcp"],
    tc_range=(SCENE.object_offset_radius, SCENE.object_offset_radius, 0.0),
    goal_fixed_in_world=True,
)
"""The DCP task's registration (`distgprl.sim.tasks.TASKS` reads it)."""
