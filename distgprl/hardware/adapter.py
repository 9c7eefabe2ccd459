"""Online window-by-window adaptation from perceived poses (the policy side of a trial).

A trial runs the environment the policy trained in (`AdaptationEnv`, the windowed residual's
`ResidualEnv` or ProMP-RRL's `ResidualRLEnv`), built as in training, with one difference:
its ``world`` (what the observation reads: TCP pose, object position, goal, obstacles, tool
points) is a :class:`PerceivedScene` filled by the perception and the robot backend. Its
skill, action layout, TC conditioning, segment maps (control rate), continuity blending (or
the residual's nominal, gate, slew limit and hold) and observation builder are used
unchanged; its simulation is kept as a *kinematic model* only (IK, tool geometry, static cell
geometry). :class:`TrialAdapter` holds that env and what a trial needs to know of it; the
trial's steps are free functions: `begin_trial` (condition on the perceived bars),
`observe`, `adapt` (the decision's poses, `distgprl.envs.episode.plan_segment`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from distgprl.envs.episode import plan_segment
from distgprl.envs.residual_control_env import ResidualRLEnv
from distgprl.envs.via_point_env import AdaptationEnv
from distgprl.envs.windowed_residual_env import ResidualEnv
from distgprl.hardware.perception import OBJECTS, Percept
from distgprl.methods import get_method
from distgprl.safety.shapes import Box, Shape
from distgprl.safety_layer.plan_check import tool_check_points
from distgprl.sim.tasks.base import TaskConfig, TaskSim
from distgprl.sim.tasks.dbm import SCENE, DBMScene, bar_boxes

__all__ = [
    "PerceivedScene",
    "TrackedObject",
    "TrialAdapter",
    "adapt",
    "bar_shapes",
    "begin_trial",
    "observe",
    "perceived_env",
    "perceived_tc",
]


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


TrialEnv = AdaptationEnv | ResidualRLEnv
"""The environment a trial's policy trained in (`ResidualEnv` is an `AdaptationEnv`)."""


@dataclass
class TrialAdapter:
    """A trial's policy side: the training environment of the method, its ``world`` the
    perceived scene (`perceived_env` builds it).

    Attributes:
        env: the environment, built as in training; ``env.world`` is ``world``, ``env.sim``
            the kinematic model (a ``DBMSim``: IK, tool points, static obstacles).
        world: the :class:`PerceivedScene` the observation reads.
        decision_unit: what one decision of the policy (and one safety check) covers:
            ``window`` (a via-point plan or windowed residual weights) or ``RL step``
            (ProMP-RRL's 10 Hz residual control).
        streams_decisions: the robot streams consecutive decisions' poses without ending its
            stream between them (residual control's 0.1 s RL steps; a window plan ends it).
        image_steps: the decisions before which the trial takes a fresh image (every window;
            residual control: the first RL step of each window's span, `_window_start_steps`).
    """

    env: TrialEnv
    world: PerceivedScene
    decision_unit: str
    streams_decisions: bool
    image_steps: tuple[int, ...]

    @property
    def model(self) -> TaskSim:
        """The environment's simulation, kept as the kinematic model."""
        return self.env.sim

    @property
    def trial_steps(self) -> int:
        """Decisions per trial: the windows, or residual control's RL steps (10 Hz)."""
        if isinstance(self.env, ResidualRLEnv):
            return int(self.env.n_steps)
        return int(self.env.layout.n_steps)

    def close(self) -> None:
        self.env.close()


def perceived_env(method: str, config=None, conveyor_velocity=(0.0, 0.04, 0.0)) -> TrialAdapter:
    """The trial adapter for ``method`` (DBM only): residual RL for Table I's ProMP-RRL and
    its ``promp-nominal`` reference (action mode ``residual-control``), windowed residual
    weights for ``promp-rrl-windowed`` / ``promp-rrl-expert``, via-points otherwise; the
    conveyor's velocity (3,), m/s, predicts the perceived bars along the belt."""
    spec = get_method(method)
    env: TrialEnv
    if spec.action_mode == "residual-control":
        env = ResidualRLEnv("dbm", method, config)
    elif spec.action_mode == "residual":
        env = ResidualEnv("dbm", config, method=method)
    else:
        env = AdaptationEnv("dbm", method, config)
    world = _perceived_scene(env.sim, conveyor_velocity)
    env.world = world  # what the observation reads
    if isinstance(env, ResidualRLEnv):
        return TrialAdapter(env, world, "RL step", True, _window_start_steps(env))
    return TrialAdapter(env, world, "window", False, tuple(range(env.layout.n_steps)))


def _perceived_scene(model: TaskSim, conveyor_velocity: Any) -> PerceivedScene:
    """An empty perceived scene with the kinematic model's static cell geometry and tool."""
    static = tuple(s for s in model.obstacle_shapes() if not s.dynamic)
    robot = model.robot

    def tool_points_at(joints: np.ndarray) -> np.ndarray:
        return tool_check_points(robot, joints)[:-1]  # without the flange origin

    return PerceivedScene(
        static, np.asarray(conveyor_velocity, dtype=float), tool_points_at=tool_points_at
    )


def _window_start_steps(env: ResidualRLEnv) -> tuple[int, ...]:
    """The RL steps before which a residual-control trial takes a fresh image: the first step
    starting at or after each window start k T / n_windows — the images the via-point
    methods get (one per window), so that Table II compares the policies, not perception
    rates. Between images the tracks predict the bars along the belt; the robot's pose and
    joints are read before every step."""
    starts = np.concatenate([[0.0], np.cumsum(env.schedule.step_duration)[:-1]])
    windows = env.config.n_windows
    at = [k * env.duration / windows for k in range(windows)]
    return tuple(sorted({int(np.searchsorted(starts, t - 1e-9)) for t in at}))


def perceived_tc(scene: PerceivedScene, start_time: float) -> TaskConfig:
    """TC from the perceived bars predicted at the trial's start time (s)."""
    geometry = scene.scene
    target = scene.object_transform("target_bar", start_time)[:3, 3]
    other = scene.object_transform("other_bar", start_time)[:3, 3]
    return TaskConfig(
        object_offset=(
            float(target[0] - geometry.conveyor_x),
            float(target[1] - geometry.target_start_y),
        ),
        obstacle_offset=(
            float(other[0] - geometry.conveyor_x),
            float(other[1] - geometry.other_start_y),
        ),
    )


def begin_trial(adapter: TrialAdapter, tcp_pose: np.ndarray, start_time: float) -> TaskConfig:
    """Start an episode at the robot's TCP pose (6,) at ``start_time`` (s); the perceived TC.

    The environment's own plan start: the TC-conditioned via-points (GP methods), zero
    residual weights on the ProMP nominal, or (residual control) the conditioned nominal with
    the TCP pose blended in and residual 0, all from the robot's pose."""
    env, scene = adapter.env, adapter.world
    scene.set_robot(tcp_pose, start_time)
    tc = perceived_tc(scene, start_time)
    env.start_plan(tc, tcp_pose, start_time)
    env.field.update(scene.obstacle_shapes())
    return tc


def observe(adapter: TrialAdapter) -> dict[str, np.ndarray]:
    """The policy's observation from the perceived world (the layout it trained on)."""
    adapter.env.field.update(adapter.world.obstacle_shapes())
    return adapter.env.observation()


def adapt(adapter: TrialAdapter, action: np.ndarray | None) -> np.ndarray:
    """Apply the (raw) action to the current decision; its segment's poses (m, 6).

    The action updates what the environment adapts: the window's via-points (GP methods),
    its residual weights or the RL step's residual (ProMP-RRL), exactly as in training
    (`distgprl.envs.episode.plan_segment`). ``None`` (or a method that trains no policy:
    ``demo``, ``promp-nominal``) keeps the conditioned demonstration (the ProMP nominal).
    """
    env = adapter.env
    shape = cast("tuple[int, ...]", env.action_space.shape)  # a Box's
    raw = np.zeros(shape) if action is None else action
    return plan_segment(env, env.step_index, raw)[1]
