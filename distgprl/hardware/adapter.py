"""Online window-by-window adaptation from perceived poses (the policy side of a trial).

:class:`PerceivedAdaptation` reuses :class:`~distgprl.envs.adaptation.AdaptationEnv` (and
:class:`PerceivedResidual` the windowed-weights residual's
:class:`~distgprl.envs.residual.ResidualEnv`, :class:`PerceivedResidualControl` ProMP-RRL's
:class:`~distgprl.envs.residual_rl.ResidualRLEnv`) for everything but the world: its skill,
action layout, TC conditioning, segment maps (control rate), continuity blending (or the
residual's nominal, gate, slew limit and hold) and observation builder are used unchanged. The env's
simulation is kept as a *kinematic model* only (IK, tool geometry, static cell geometry);
what the observation reads of its world (``world``: TCP pose, object position, goal,
obstacles, tool points) is a :class:`PerceivedScene` filled by the perception and the robot
backend.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from distgprl.envs.adaptation import AdaptationEnv
from distgprl.envs.episode import commit_segment, plan_segment
from distgprl.envs.residual import ResidualEnv
from distgprl.envs.residual_rl import ResidualRLEnv
from distgprl.hardware.perception import OBJECTS, Percept
from distgprl.hardware.safety import tool_check_points
from distgprl.methods import get_method
from distgprl.safety.shapes import Box, Shape
from distgprl.sim.tasks.base import TaskConfig, TaskSim
from distgprl.sim.tasks.dbm import SCENE, DBMScene, bar_boxes


def bar_shapes(
    scene: DBMScene, transform: np.ndarray, prefix: str, dynamic: bool
) -> tuple[Box, ...]:
    """The four boxes of a bar at a perceived pose (4, 4) (tilt and yaw included)."""
    centre = np.asarray(transform[:3, 3], dtype=float)
    rotation = np.asarray(transform[:3, :3], dtype=float)
    level = bar_boxes(scene, np.zeros(3), prefix, dynamic)
    return tuple(
        Box(b.name, centre + rotation @ b.position, rotation, b.half_extents, dynamic)
        for b in level
    )


@dataclass
class TrackedObject:
    """Latest estimate of a conveyed object.

    Attributes:
        transform: robot-base-from-object (4, 4) at ``stamp``.
        stamp: time (s, backend clock) the estimate refers to.
        frames_since_seen: images since the object was last detected (0 = this one).
    """

    transform: np.ndarray
    stamp: float
    frames_since_seen: int = 0


class PerceivedScene:
    """The world as perceived: object tracks, obstacle shapes and the robot's TCP.

    A world's state (`distgprl.envs.world.WorldState`: what the observation reads), from
    perception instead of simulation state.

    Args:
        static_shapes: the cell's fixed obstacles (rollers, rails), robot base frame.
        conveyor_velocity: belt velocity (3,), m/s: a bar on the belt at time t0 is predicted
            at ``p + v (t - t0)``; a lifted bar (more than 2 cm above rest) is not predicted.
        scene: DBM geometry (bar size, resting height, lift height).
    """

    def __init__(
        self,
        static_shapes: tuple[Shape, ...],
        conveyor_velocity: np.ndarray,
        scene: DBMScene = SCENE,
        tool_points_at: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.static_shapes = tuple(static_shapes)
        self.velocity = np.asarray(conveyor_velocity, dtype=float)
        self.scene = scene
        self.tracks: dict[str, TrackedObject] = {}
        self.now = 0.0
        self._tcp = np.zeros(6)
        self._joints: np.ndarray | None = None
        self._tool_points_at = tool_points_at

    # -- updates ---------------------------------------------------------------------------
    def update(self, percept: Percept) -> None:
        """Fold in one image's detections; undetected objects keep their last track."""
        for name in OBJECTS:
            pose = percept.objects.get(name)
            if pose is not None:
                self.tracks[name] = TrackedObject(pose.transform.copy(), percept.stamp, 0)
            elif name in self.tracks:
                self.tracks[name].frames_since_seen += 1

    def set_robot(self, tcp_pose: np.ndarray, now: float, joints: np.ndarray | None = None) -> None:
        """The robot's actual TCP pose (6,), the current time (s) and, where known, its joint
        positions (6,), rad (what `tool_points` needs)."""
        self._tcp = np.asarray(tcp_pose, dtype=float).copy()
        self.now = float(now)
        if joints is not None:
            self._joints = np.asarray(joints, dtype=float).copy()

    # -- predictions -----------------------------------------------------------------------
    def on_belt(self, transform: np.ndarray) -> bool:
        """Whether a bar at ``transform`` (4, 4) still lies on the belt (its centre less than
        2 cm above the resting height), so that it is conveyed."""
        return bool(transform[2, 3] < self.scene.bar_centre_z + 0.02)

    def object_transform(self, name: str, time: float | None = None) -> np.ndarray:
        """Predicted pose (4, 4) of a tracked object at ``time`` (default: now)."""
        track = self.tracks[name]
        transform = track.transform.copy()
        if self.on_belt(transform):
            elapsed = (self.now if time is None else time) - track.stamp
            transform[:3, 3] += self.velocity * elapsed
        return transform

    def obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """Static cell geometry + the other bar predicted at ``time`` (default now)."""
        return (*self.static_shapes, *self.moving_obstacle_shapes(time))

    def moving_obstacle_shapes(self, time: float | None = None) -> tuple[Shape, ...]:
        """The other bar predicted at ``time`` (default now)."""
        return bar_shapes(self.scene, self.object_transform("other_bar", time), "other_bar", True)

    # -- the world state the observation reads (`WorldState`) -----------------------------
    def tcp_pose(self) -> np.ndarray:
        return self._tcp.copy()

    def object_position(self) -> np.ndarray:
        return self.object_transform("target_bar")[:3, 3].copy()

    def tool_points(self) -> np.ndarray:
        """The tool's surface points (m, 3), m, at the robot's last joint positions
        (`set_robot`), by the kinematic model's forward kinematics."""
        if self._tool_points_at is None or self._joints is None:
            raise RuntimeError(
                "the perceived world knows no tool points: build it with tool_points_at and "
                "pass the robot's joints to set_robot(tcp_pose, now, joints)"
            )
        return self._tool_points_at(self._joints)

    def goal_position(self) -> np.ndarray:
        position = self.object_position()
        return np.array(
            [position[0], position[1], self.scene.bar_centre_z + self.scene.lift_height]
        )


if TYPE_CHECKING:  # the mixin's host, for the type checker only (at run time: object)
    _Host = AdaptationEnv
else:
    _Host = object


class _PerceivedWorld(_Host):
    """The perceived-world half of a trial adapter, shared by the two environment kinds.

    Mixed into an environment class (:class:`AdaptationEnv` or its residual subclass) after
    that environment is built: :meth:`_attach_world` makes the observation read the
    perceived world (``world``); the environment's simulation is the kinematic model.
    """

    world: PerceivedScene  # after `_attach_world`: what the observation reads
    decision_unit = "window"
    """What one decision of the policy (and one safety check) covers."""
    streams_decisions = False
    """Whether the robot streams consecutive decisions' poses without ending its stream
    between them (residual control's 0.1 s RL steps; a window plan ends its stream)."""

    @property
    def model(self) -> TaskSim:
        """The environment's simulation, kept as the kinematic model (IK, tool geometry,
        static cell geometry)."""
        return self.sim

    def _attach_world(self, conveyor_velocity: Any) -> None:
        static = tuple(s for s in self.model.obstacle_shapes() if not s.dynamic)
        robot = self.model.robot

        def tool_points_at(joints: np.ndarray) -> np.ndarray:
            return tool_check_points(robot, joints)[:-1]  # without the flange origin

        self.world = PerceivedScene(
            static, np.asarray(conveyor_velocity, dtype=float), tool_points_at=tool_points_at
        )  # what the observation reads

    @property
    def control_dt(self) -> float:
        return float(self.model.control_dt)

    @property
    def trial_steps(self) -> int:
        """Decisions per trial: the windows (a via-point plan or windowed residual weights)."""
        return int(self.layout.n_steps)

    def takes_image(self, step: int) -> bool:
        """Whether the trial takes a fresh image before decision ``step``: before every
        window (between images the tracks predict the bars along the belt)."""
        return True

    def perceived_tc(self, start_time: float) -> TaskConfig:
        """TC from the perceived bars predicted at the trial's start time (s)."""
        scene = self.world.scene
        target = self.world.object_transform("target_bar", start_time)[:3, 3]
        other = self.world.object_transform("other_bar", start_time)[:3, 3]
        return TaskConfig(
            object_offset=(
                float(target[0] - scene.conveyor_x),
                float(target[1] - scene.target_start_y),
            ),
            obstacle_offset=(
                float(other[0] - scene.conveyor_x),
                float(other[1] - scene.other_start_y),
            ),
        )

    def begin(self, tcp_pose: np.ndarray, start_time: float) -> TaskConfig:
        """Start an episode at the robot's TCP pose (6,); returns the perceived TC."""
        self.world.set_robot(tcp_pose, start_time)
        tc = self.perceived_tc(start_time)
        # The environment's own plan start: the TC-conditioned via-points (GP methods) or
        # zero residual weights on the ProMP nominal (ProMP-RRL), from the robot's pose.
        self.start_plan(tc, tcp_pose, start_time)
        self.field.update(self.world.obstacle_shapes())
        return tc

    def observe(self) -> dict[str, np.ndarray]:
        """The policy's observation from the perceived world (same layout as in training)."""
        self.field.update(self.world.obstacle_shapes())
        return self.observation()

    def adapt(self, action: np.ndarray | None) -> np.ndarray:
        """Apply the (raw) action to the current window; return the segment's poses (m, 6).

        The action updates what the environment adapts: the window's via-points (GP methods)
        or its residual weights (ProMP-RRL), exactly as in training (`AdaptationEnv.apply_action`).

        ``None`` (or a method that trains no policy: ``demo``, ``promp-nominal``) keeps the
        conditioned demonstration (the ProMP nominal).
        """
        shape = cast("tuple[int, ...]", self.action_space.shape)  # a Box's
        raw = np.zeros(shape) if action is None else action
        return plan_segment(self, self.step_index, raw)[1]

    def segment_times(self, step: int) -> np.ndarray:
        """Trial times (s from the trial start) of the control instants of segment ``step``."""
        return self.segment_tau(step) * self.skill.duration

    def executed(self, poses: np.ndarray) -> None:
        """Record that ``poses`` (the segment of the current step) were commanded."""
        commit_segment(self, self.step_index, poses)


class PerceivedAdaptation(_PerceivedWorld, AdaptationEnv):
    """:class:`AdaptationEnv` whose world is a :class:`PerceivedScene` (DBM only).

    Use: :meth:`begin` (conditions the skill on the perceived target bar), then per window
    :meth:`observe` -> policy -> :meth:`adapt` (returns the segment's poses to check and
    execute) -> :meth:`executed`.

    Attributes:
        model: the kinematic model (a ``DBMSim``: IK, tool points, static obstacles).
        world: the :class:`PerceivedScene`.
    """

    def __init__(self, method: str, config=None, conveyor_velocity=(0.0, 0.04, 0.0)) -> None:
        AdaptationEnv.__init__(self, "dbm", method, config)
        self._attach_world(conveyor_velocity)


class PerceivedResidual(_PerceivedWorld, ResidualEnv):
    """ProMP-RRL's :class:`ResidualEnv` whose world is a :class:`PerceivedScene` (DBM only).

    The nominal trajectory is the object-centric ProMP's mean for the *perceived* target
    bar, conditioned on the robot's TCP pose; the policy sets residual weights window by
    window. Same use as :class:`PerceivedAdaptation`.
    """

    def __init__(
        self, method: str = "promp-rrl-windowed", config=None, conveyor_velocity=(0.0, 0.04, 0.0)
    ) -> None:
        ResidualEnv.__init__(self, "dbm", config, method=method)
        self._attach_world(conveyor_velocity)


# the mixin is typed against AdaptationEnv (its other two hosts); ResidualRLEnv is no subclass
class PerceivedResidualControl(_PerceivedWorld, ResidualRLEnv):  # type: ignore[misc]
    """ProMP-RRL's residual RL (:class:`ResidualRLEnv`) whose world is a
    :class:`PerceivedScene` (DBM only).

    One decision per RL step (10 Hz, 50 per DBM trial) instead of per window: :meth:`begin`
    conditions the nominal on the perceived target bar and blends the robot's TCP pose in;
    then per RL step :meth:`observe` (the training observation, from the perceived world and
    the robot's joints: the tool's clearance needs them; a fresh image before the steps of
    `image_steps`, one per window as the via-point methods get) -> policy -> :meth:`adapt` (the
    slew-limited residual and the step's 2-3 control-period poses, nominal + gated residual,
    exactly as `ResidualRLEnv.step` commands them) -> the trial checks the poses and streams
    them -> :meth:`executed`. The safety layer checks each 0.1 s segment before it moves (a
    plan of one RL step: what residual control knows ahead); retiming applies to it as to a
    window, pushing via-points does not (there are none).
    """

    def __init__(
        self, method: str = "promp-rrl", config=None, conveyor_velocity=(0.0, 0.04, 0.0)
    ) -> None:
        ResidualRLEnv.__init__(self, "dbm", method, config)
        self._attach_world(conveyor_velocity)
        self.image_steps = self._window_start_steps()

    decision_unit = "RL step"
    streams_decisions = True

    @property
    def trial_steps(self) -> int:
        """Decisions per trial: the RL steps (10 Hz)."""
        return int(self.n_steps)

    def _window_start_steps(self) -> tuple[int, ...]:
        """The RL steps before which the trial takes a fresh image (``image_steps``): the
        first step starting at or after each window start k T / n_windows — the images the
        via-point methods get (one per window), so that Table II compares the policies, not
        perception rates. Between images the tracks predict the bars along the belt; the
        robot's pose and joints are read before every step."""
        starts = np.concatenate([[0.0], np.cumsum(self.schedule.step_duration)[:-1]])
        windows = self.config.n_windows
        at = [k * self.duration / windows for k in range(windows)]
        return tuple(sorted({int(np.searchsorted(starts, t - 1e-9)) for t in at}))

    def takes_image(self, step: int) -> bool:
        """Whether the trial takes a fresh image before RL step ``step`` (`image_steps`)."""
        return step in self.image_steps

    def start_plan(self, tc: TaskConfig, tcp_pose: np.ndarray, start_time: float) -> None:
        """The conditioned nominal with the TCP pose (6,) blended in, residual 0."""
        self._start_episode(tc, tcp_pose)
        self._episode_over = False


TrialAdapter = PerceivedAdaptation | PerceivedResidual | PerceivedResidualControl
"""A trial's environment (`perceived_env`)."""


def perceived_env(method: str, config=None, conveyor_velocity=(0.0, 0.04, 0.0)) -> TrialAdapter:
    """The trial adapter for ``method``: residual RL for Table I's ProMP-RRL and its
    ``promp-nominal`` reference (action mode ``residual-control``), windowed residual weights
    for ``promp-rrl-windowed`` / ``promp-rrl-expert``, via-points otherwise."""
    spec = get_method(method)
    if spec.action_mode == "residual-control":
        return PerceivedResidualControl(method, config, conveyor_velocity)
    if spec.action_mode == "residual":
        return PerceivedResidual(method, config, conveyor_velocity)
    return PerceivedAdaptation(method, config, conveyor_velocity)
