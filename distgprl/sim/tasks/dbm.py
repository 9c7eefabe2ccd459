"""DBM: dynamic bar manipulation with a hook (paper §V-A).

Scene (world = UR base frame, m). A roller conveyor runs along world +y at x = 0.55:

- rollers: static obstacles, 31 ``Cylinder`` (r = 15 mm, axis along x, pitch 40 mm,
  tops at z = 0.10).
- rails: static obstacles, 2 ``Box`` (side rails at x = 0.55 +- 0.13, tops at z = 0.12).
- target bar (manipulated object, 0.3 kg): a 16 x 5 x 2 cm bar across the conveyor with
  an arch handle on top (opening 5 cm wide, 3.5 cm tall, 2 cm deep); conveyed at
  ``belt_speed`` along +y until the tool touches it, then free under contact physics.
- other bar (dynamic obstacle, 4 ``Box``): the same bar, conveyed kinematically.

The hook's finger enters the target bar's handle from behind (-y), then lifts the bar by
the handle with contact physics and carries it off the conveyor towards the robot.

TC (scene revision 2): ``object_offset = (dx, dy)`` and
``obstacle_offset = (dx', dy')`` shift the bars in the xy-plane of the conveyor: along the
belt (y) each uniform in [-0.20, 0.20] m, across it (x) each uniform in
[-``lateral_range``, ``lateral_range``] = [-0.035, 0.035] m — as far as the conveyor allows:
the rails' inner faces are 12 cm from the belt's centre line, a bar reaches 8 cm to each
side, and ``rail_margin`` (5 mm) is kept free. Draws in which the bars would start closer
than ``min_bar_gap`` (1 cm between faces, along the belt) are redrawn. (Revisions 0-1
shifted the bars along the belt only.) The bars start 16 cm
apart (faces) in the nominal TC; the hook lowers its finger to handle height 12 cm
behind the target's handle and slides it in, so it sweeps the space between the bars.

Success: the target bar's centre is at least ``lift_height`` (0.12 m) above its resting
height (it hangs from the hook clear of rails and rollers). Progress: the lifted fraction
of that height. Goal point: the bar centre's resting position raised by ``lift_height``.

No robot link is exempt: every robot/tool contact with a roller, a rail or the other bar
is a collision.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from distgprl.data import DEMO_DIR, SCENE_REVISIONS
from distgprl.safety.shapes import Box, Cylinder, Shape
from distgprl.sim.bullet import create_compound_body
from distgprl.sim.profiles import minimum_jerk
from distgprl.sim.robot import HOOK
from distgprl.sim.tasks.base import TaskConfig, TaskSim, TaskSpec
from distgprl.sim.transforms import pose_to_matrix, rotation_y

IDENTITY = np.eye(3)
ROLLER_ROTATION = rotation_y(math.pi / 2.0)  # cylinder axis (local z) along world x
_UNIT = (0.0, 0.0, 0.0, 1.0)  # the identity quaternion (x, y, z, w)


@dataclass(frozen=True)
class DBMScene:
    """Geometry and motion constants of the DBM scene (m, s, kg)."""

    conveyor_x: float = 0.55
    roller_radius: float = 0.015
    roller_half_length: float = 0.12
    roller_top: float = 0.10
    roller_pitch: float = 0.04
    roller_count: int = 31
    rail_offset: float = 0.13
    rail_half_extents: tuple[float, float, float] = (0.01, 0.62, 0.025)
    rail_top: float = 0.12
    bar_half_extents: tuple[float, float, float] = (0.08, 0.025, 0.01)
    post_half_extents: tuple[float, float, float] = (0.005, 0.01, 0.0175)
    post_x: float = 0.03
    beam_half_extents: tuple[float, float, float] = (0.035, 0.01, 0.005)
    bar_mass: float = 0.3
    belt_speed: float = 0.04
    target_start_y: float = -0.10
    other_start_y: float = -0.31
    offset_range: float = 0.20
    rail_margin: float = 0.005
    min_bar_gap: float = 0.01
    lift_height: float = 0.12
    start_pose: tuple[float, ...] = (0.35, -0.30, 0.35, 0.0, 0.0, 0.0)

    @property
    def bar_centre_z(self) -> float:
        """Resting height (m) of a bar's base-box centre."""
        return self.roller_top + self.bar_half_extents[2]

    @property
    def lateral_range(self) -> float:
        """Largest offset (m) of a bar across the belt: its ends keep ``rail_margin`` from
        the rails' inner faces."""
        inner_face = self.rail_offset - self.rail_half_extents[0]
        return inner_face - self.bar_half_extents[0] - self.rail_margin

    @property
    def handle_opening(self) -> tuple[float, float]:
        """Bottom and top z (m) of the handle opening of a resting bar."""
        bottom = self.roller_top + 2.0 * self.bar_half_extents[2]
        return bottom, bottom + 2.0 * self.post_half_extents[2]


SCENE = DBMScene()
PRE_INSERTION_DISTANCE = 0.12
"""How far (m) behind the handle centre the expert's TCP waits before inserting the finger."""
HOME = np.array([2.2, -1.75, 1.6, -1.42, -1.571, -2.51])
"""Reference configuration (elbow up, wrist down) that picks the start IK branch."""


def bar_boxes(scene: DBMScene, centre: np.ndarray, prefix: str, dynamic: bool) -> tuple[Box, ...]:
    """The four boxes (base, two posts, beam) of a level bar whose base centre is ``centre``."""
    centre = np.asarray(centre, dtype=float)
    bar_half = np.asarray(scene.bar_half_extents)
    post_half = np.asarray(scene.post_half_extents)
    beam_half = np.asarray(scene.beam_half_extents)
    post_z = bar_half[2] + post_half[2]
    beam_z = bar_half[2] + 2.0 * post_half[2] + beam_half[2]
    return (
        Box(f"{prefix}_base", centre.copy(), IDENTITY, bar_half, dynamic),
        Box(
            f"{prefix}_post_left",
            centre + [-scene.post_x, 0.0, post_z],
            IDENTITY,
            post_half,
            dynamic,
        ),
        Box(
            f"{prefix}_post_right",
            centre + [scene.post_x, 0.0, post_z],
            IDENTITY,
            post_half,
            dynamic,
        ),
        Box(f"{prefix}_beam", centre + [0.0, 0.0, beam_z], IDENTITY, beam_half, dynamic),
    )


def sample_dbm_tc(rng: np.random.Generator) -> TaskConfig:
    """Both bars offset in the conveyor's xy-plane: along the belt uniform in [-0.2, 0.2] m,
    across it uniform in [-lateral_range, lateral_range]; overlapping draws redrawn."""
    scene = SCENE
    length = 2.0 * scene.bar_half_extents[1]
    lateral = scene.lateral_range
    while True:
        target, other = rng.uniform(-scene.offset_range, scene.offset_range, size=2)
        target_x, other_x = rng.uniform(-lateral, lateral, size=2)
        gap = (scene.target_start_y + target) - (scene.other_start_y + other) - length
        if gap >= scene.min_bar_gap:
            return TaskConfig(
                object_offset=(float(target_x), float(target)),
                obstacle_offset=(float(other_x), float(other)),
            )


def engagement_time() -> float:
    """Time (s) at which the DBM expert's hook reaches its pre-insertion pose behind the handle."""
    return 2.2


class DBMSim(TaskSim):
    """Dynamic bar manipulation simulation (see the module docstring for the scene)."""

    tool = HOOK
    demo_duration = 5.0
    camera_eye = (1.25, -0.75, 0.7)
    camera_target = (0.5, 0.0, 0.12)

    def __init__(self, scene: DBMScene = SCENE, **kwargs) -> None:
        self.scene = scene
        super().__init__(**kwargs)

    def _build_scene(self) -> None:
        scene = self.scene
        client = self.client
        start = self.robot.ik_nearest(pose_to_matrix(np.asarray(scene.start_pose)), HOME)
        assert start is not None, "the scene's start pose has no IK solution"
        self.start_joint_positions = start
        roller_z = scene.roller_top - scene.roller_radius
        first = -scene.roller_pitch * (scene.roller_count - 1) / 2.0
        self._rollers = tuple(
            Cylinder(
                f"roller_{k:02d}",
                np.array([scene.conveyor_x, first + k * scene.roller_pitch, roller_z]),
                ROLLER_ROTATION,
                scene.roller_radius,
                scene.roller_half_length,
            )
            for k in range(scene.roller_count)
        )
        rail_z = scene.rail_top - scene.rail_half_extents[2]
        self._rails = tuple(
            Box(
                f"rail_{side}",
                np.array([scene.conveyor_x + sign * scene.rail_offset, 0.0, rail_z]),
                IDENTITY,
                np.asarray(scene.rail_half_extents),
            )
            for side, sign in (("left", -1.0), ("right", 1.0))
        )
        self.roller_body = create_compound_body(
            client,
            self._rollers,
            (0.55, 0.55, 0.6, 1.0),
            origin=np.array([scene.conveyor_x, 0.0, roller_z]),
            lateral_friction=0.3,
        )
        self.rail_body = create_compound_body(
            client,
            self._rails,
            (0.35, 0.35, 0.4, 1.0),
            origin=np.array([scene.conveyor_x, 0.0, rail_z]),
        )
        self._rest_z = scene.bar_centre_z
        target_centre = np.array([scene.conveyor_x, scene.target_start_y, self._rest_z])
        other_centre = np.array([scene.conveyor_x, scene.other_start_y, self._rest_z])
        self.object_body = create_compound_body(
            client,
            bar_boxes(scene, target_centre, "target_bar", False),
            (0.2, 0.4, 0.9, 1.0),
            origin=target_centre,
            mass=scene.bar_mass,
            lateral_friction=0.6,
        )
        self.other_bar_body = create_compound_body(
            client,
            bar_boxes(scene, other_centre, "other_bar", True),
            (0.85, 0.2, 0.2, 1.0),
            origin=other_centre,
        )
        self.obstacle_bodies = (self.roller_body, self.rail_body, self.other_bar_body)
        self.dynamic_obstacle_bodies = (self.other_bar_body,)
        self.exempt_links = {}
        self._other_start = other_centre
        # (3,), m: an array here, plain floats from `move_kinematic`
        self._other_position: np.ndarray | tuple[float, float, float] = other_centre.copy()
        self._object_rest = target_centre

    def _place(self, tc: TaskConfig) -> None:
        scene = self.scene
        self._object_start = np.array(
            [
                scene.conveyor_x + tc.object_offset[0],
                scene.target_start_y + tc.object_offset[1],
                self._rest_z + 1e-4,
            ]
        )
        self._object_velocity = np.array([0.0, scene.belt_speed, 0.0])
        self._other_start = np.array(
            [
                scene.conveyor_x + tc.obstacle_offset[0],
                scene.other_start_y + tc.obstacle_offset[1],
                self._rest_z + 1e-4,
            ]
        )
        self._other_motion = (*self._other_start.tolist(), scene.belt_speed)

    def other_bar_position_at(self, time: float) -> np.ndarray:
        """Base-box centre (3,), m, of the other bar at ``time`` s for the current TC."""
        return self._other_start + np.array([0.0, self.scene.belt_speed * time, 0.0])

    def moving_obstacle_anchors_at(self, times: np.ndarray) -> np.ndarray:
        """`other_bar_position_at` at each of ``times`` (n,), s, at once, shape (n, 3), m."""
        anchors = np.tile(np.asarray(self._other_start, dtype=float), (np.size(times), 1))
        anchors[:, 1] += self.scene.belt_speed * np.asarray(times, dtype=float)
        return anchors

    def kinematic_moves(
        self, time: float
    ) -> tuple[tuple[int, tuple[float, float, float], tuple[float, float, float, float]], ...]:
        """The other bar where the belt carries it at ``time`` (s) (plain floats: asked for
        every physics step)."""
        x, y, z, speed = self._other_motion
        return ((self.other_bar_body, (x, y + speed * time, z), _UNIT),)

    def kinematic_reached(self, time: float) -> None:
        """The other bar stands where the belt carries it at ``time`` (s)."""
        self._other_position = self.kinematic_moves(time)[0][1]

    def obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """Rollers, rails and the other bar, as EDF primitives.

        The other bar is at its current pose, or where the belt carries it at episode time
        ``time`` (s).
        """
        return (*self._rollers, *self._rails, *self.moving_obstacle_shapes(time))

    def moving_obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """The other bar's four boxes, now or at episode time ``time`` (s)."""
        position = self._other_position if time is None else self.other_bar_position_at(time)
        return bar_boxes(self.scene, np.asarray(position, dtype=float), "other_bar", True)

    def goal_position(self) -> np.ndarray:
        """The target bar's current xy at its resting height raised by ``lift_height`` (3,), m."""
        position = self.object_position()
        return np.array([position[0], position[1], self._rest_z + self.scene.lift_height])

    def lifted_height(self) -> float:
        """Height (m) of the target bar's centre above its resting height."""
        return float(self.object_position()[2] - self._rest_z)

    def success(self) -> bool:
        """The target bar's centre is at least ``lift_height`` above its resting height."""
        return self.lifted_height() >= self.scene.lift_height

    def task_progress(self) -> float:
        """Lifted fraction of ``lift_height``, in [0, 1]."""
        return float(np.clip(self.lifted_height() / self.scene.lift_height, 0.0, 1.0))


def dbm_expert(tc: TaskConfig) -> tuple[np.ndarray, np.ndarray]:
    """Demonstration (times (n,), poses (n, 6)) hooking and lifting the conveyed target bar.

    Key poses: start -> above the pre-insertion point -> pre-insertion (finger level with
    the handle opening, 12 cm behind the handle centre) -> inserted (TCP under the handle beam)
    -> lifted 20 cm while following the belt -> carried 20 cm towards the robot.
    """
    scene = SCENE
    bottom, top = scene.handle_opening
    finger_thickness = 2.0 * HOOK.boxes[1].half_extents[2]
    insert_z = 0.5 * (bottom + top) + 0.5 * finger_thickness
    x = scene.conveyor_x + tc.object_offset[0]
    y0 = scene.target_start_y + tc.object_offset[1]

    def bar_y(time: float) -> float:
        return y0 + scene.belt_speed * time

    t_engage, t_inserted, t_lifted, t_end = engagement_time(), 3.0, 4.0, 5.0
    start = np.asarray(scene.start_pose, dtype=float)
    key_poses = np.array(
        [
            start,
            [x, bar_y(t_engage) - PRE_INSERTION_DISTANCE, insert_z + 0.10, 0.0, 0.0, 0.0],
            [x, bar_y(t_engage) - PRE_INSERTION_DISTANCE, insert_z, 0.0, 0.0, 0.0],
            [x, bar_y(t_inserted), insert_z, 0.0, 0.0, 0.0],
            [x, bar_y(t_lifted), insert_z + 0.20, 0.0, 0.0, 0.0],
            [x - 0.20, bar_y(t_lifted), insert_z + 0.25, 0.0, 0.0, 0.0],
        ]
    )
    key_times = np.array([0.0, 1.5, t_engage, t_inserted, t_lifted, t_end])
    return minimum_jerk(key_times, key_poses)


TASK = TaskSpec(
    name="dbm",
    title="Dynamic bar manipulation",
    demo_path=DEMO_DIR / "dbm.csv",
    varied_demo_dir=DEMO_DIR / "dbm_varied",
    nominal_tc=TaskConfig(),
    interaction_time=engagement_time() / DBMSim.demo_duration,
    goal="hook the conveyed target bar by its handle and lift it 12 cm clear of the conveyor",
    sampler=sample_dbm_tc,
    make_sim=DBMSim,
    expert=dbm_expert,
    scene_revision=SCENE_REVISIONS["dbm"],
    tc_range=(SCENE.lateral_range, SCENE.offset_range, 0.0),
    goal_fixed_in_world=False,
)
"""The DBM task's registration (`distgprl.sim.tasks.TASKS` reads it)."""
