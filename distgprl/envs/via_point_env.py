"""The windowed via-point adaptation MDP of Dist-GPRL (paper §IV; DESIGN §3).

Env ids: ``DistGPRL-DCP-v<N>`` and ``DistGPRL-DBM-v<N>``, N the environment version
(registered in `distgprl.envs`).
"""

from __future__ import annotations

import time

import numpy as np
from gymnasium import spaces

from distgprl.adaptation.layout import OBSERVATION_SCALE_FLOOR, AuxLayout, build_action_layout
from distgprl.adaptation.plan import TrajectoryModel, WindowPlan
from distgprl.adaptation.trajectories import GPSkillTrajectory
from distgprl.config_types import EnvConfig
from distgprl.envs.base import TaskEnv
from distgprl.envs.clearance import TimedClearance
from distgprl.envs.episode import EpisodeTally, execute_segment, plan_segment
from distgprl.envs.world import SimWorld, WorldState
from distgprl.methods import MethodSpec
from distgprl.safety.hap_filter import MovingObstacleFilter, tool_bounds
from distgprl.sim.transforms import rotvec_to_matrix
from distgprl.skill.gp import GPSkill

REWARD_TERMS = ("r_progress", "r_success", "r_collision", "r_sd", "r_ga", "r_signature")

__all__ = [
    "REWARD_TERMS",
    "AdaptationEnv",
    "cosine",
]


def cosine(a: np.ndarray, b: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """Row-wise cosine similarity of (n, d) arrays; 0 where either row is ~0."""
    na = np.linalg.norm(a, axis=-1)
    nb = np.linalg.norm(b, axis=-1)
    valid = (na > eps) & (nb > eps)
    out = np.zeros(na.shape)
    out[valid] = np.sum(a[valid] * b[valid], axis=-1) / (na[valid] * nb[valid])
    return out


class AdaptationEnv(TaskEnv):
    """Windowed, covariance-correlated via-point adaptation of a GP skill (Dist-GPRL).

    An episode adapts and executes the task's demonstrated skill, conditioned on a task
    configuration (TC), in ``n_windows`` = 3 steps: step t_s updates window t_s (L = 5 of
    the N = 15 via-points) and executes the trajectory's segment t_s. Global methods
    (``action_mode == "global"``) have L = 13, all interior via-points, at every step; the
    ``demo`` reference (``action_mode == "none"``) ignores the action.

    **Observation space**: ``Dict`` of float32 boxes; the networks see only ``state``, the
    concatenation of:

    - Gamma_W (L x 6, dimensionless): the window via-points (position, rotation vector)
      minus the demonstration via-points' mean, over their std floored at
      `OBSERVATION_SCALE_FLOOR` (0.05 m, 0.2 rad);
    - c (L, units of ``clearance_scale`` m): EDF clearance at each window via-point
      against the obstacles where they are at that via-point's time
      (``clearance_timing``), clipped to +-``clearance_clip`` m;
    - e_o, e_g (3 each, units of ``relative_position_scale`` m): object - TCP and
      goal - TCP position, clipped to +-0.8 m per axis;
    - phi (1, dimensionless): t_s / n_windows (1 only in the terminal observation).

    ``aux`` (the regularised actor loss only): Gamma (N x 6, m and rad), a one-hot of t_s
    and, with the HAP prior, the moving obstacles' anchor at each via-point's time
    (N x 3, m; `moving_obstacle_anchors`).

    **Action space**: ``Box(-1, 1, (L x 6,))``, row-major (via-point, axis). Scaled per
    axis by ``action_scale_rule`` (a third per step for methods with ``episode_range``),
    correlated Delta Gamma = S_W a (Eq. transformed_action; S_W from the K named by
    ``covariance_scale``, the identity for ``dist-gprl-nocov`` and the global methods) and
    added to the window (Eq. updated_via_points). Via-points 0 and N-1 never change; GPRL
    also holds the TC via-point.

    **Transition**: segment t_s (from the window's first via-point time to the next
    window's; the first from t = 0, the last to the end) runs in the simulator at its
    control rate while the object and the obstacles move; a jump of the planned pose at
    the segment start is blended out over ``blend_fraction`` of it (minimum jerk).

    **Reward** (Eq. total_reward): the sum of the terms below, each in ``info`` under its
    name (r_tc = r_progress + r_success + r_collision):

    - ``r_progress``: ``progress_weight`` x the change of task progress (in [0, 1]);
    - ``r_success``: ``success_bonus`` at the last step if ``success``;
    - ``r_collision``: -``collision_penalty`` if the segment had a collision;
    - ``r_sd``: -``sd_beta`` sum 1[d < d_min] / (d + eps) over the tool points at
      ``sd_samples_per_segment`` instants of the segment (Eq. safety_reward);
    - ``r_ga``: ``lambda_ga`` x mean_j cos(Delta Gamma_j[xyz], grad d(v_j)) over the window
      via-points before this step's update, grad d from the field of ``c``
      (Eq. grad_alignment_reward);
    - ``r_signature``: ``signature_weight`` x the signature similarity of the segment's
      planned path to the demonstration's (GPRL only).

    r_sd and r_ga are 0 for methods without distance rewards.

    **Starting state**: ``reset(seed, options={"tc": TaskConfig})``, else a TC drawn from
    the task's training distribution by the env's generator; the via-points are the
    demonstration's conditioned on the TC (the interaction via-point and its successors
    move by the object's offset; via-point 0 is the robot's start pose).

    **Episode end**: ``terminated`` after ``n_windows`` steps or, with
    ``collision_ends_episode``, at the step whose segment collides (execution stops at that
    control period, like a protective stop); never ``truncated``. The last step's ``info``
    adds ``success`` (completed, and no collision when collisions end the episode),
    ``completed`` (the task's success criterion at the end), ``collision``,
    ``stopped_at_step`` (-1 if none), ``min_clearance`` (m, >= 0), ``min_signed_clearance``
    (m, negative = penetration), ``peak_joint_speed`` (rad/s, the largest commanded; the
    hardware safety layer bounds it), ``kinematic_retention`` (mean velocity cosine to the
    demonstration), ``adaptation_time_s`` (s, per step) and ``final_parameters`` (Gamma,
    N x 6).

    How these rules read the paper's equations, with their arguments: protocol rule 4
    ("Equations as written"); what each replaced:
    CHANGELOG.md.

    Args:
        task: the task name (``"dcp"`` or ``"dbm"``).
        method: a method name or spec whose ``action_mode`` this MDP runs.
        config: the env's constants (`EnvConfig`; paper defaults if None).
        skill: the task's GP skill (the committed fit if None).
        render_mode: ``"rgb_array"`` or None.
    """

    def __init__(
        self,
        task: str,
        method: str | MethodSpec = "dist-gprl",
        config: EnvConfig | None = None,
        skill: GPSkill | None = None,
        render_mode: str | None = None,
    ) -> None:
        self.build(
            task,
            method,
            config,
            render_mode,
            ("window", "global", "none", "residual"),
            "method {name} does not use the via-point MDP",
            skill,
        )
        self.interaction_index = self.skill.nearest_via_index(self.spec_task.interaction_time)
        frozen = (self.interaction_index,) if self.method.hold_tc_via_point else ()
        self.layout = build_action_layout(
            self.skill, self.config, self.method, frozen, np.asarray(self.spec_task.tc_range)
        )
        # Time-indexed clearances (``clearance_timing``); ``field``: all obstacles as they are now.
        self.clearance = TimedClearance(self.sim.obstacle_shapes(), self.config.clearance_timing)
        self.field = self.clearance.field
        # Where the segments run: the simulation, r_sd's tool clearance after each sample.
        self.sim_world = SimWorld(
            self.sim,
            stop_on_collision=self.config.collision_ends_episode,
            samples=self.config.sd_samples_per_segment,
            tool_clearance=self._tool_clearance if self.method.distance_rewards else None,
            cap_at_minimum=True,
        )
        # What the observation reads (the hardware trials' adapter: the perceived scene).
        self.world: WorldState = self.sim_world
        # Demonstration reference: velocity samples for kinematic retention.
        self._retention_tau = np.linspace(0.0, 1.0, 100)
        self._demo_velocity = self.skill.velocity(self.skill.via_points, self._retention_tau)
        self._via_mean = self.skill.via_points.mean(axis=0)
        # Standardisation scale per axis: the demonstration's spread, floored at a physical
        # scale (OBSERVATION_SCALE_FLOOR) so that an axis the demonstration keeps constant
        # (e.g. the tool orientation) does not blow small adaptations up to huge inputs.
        self._via_std = np.maximum(self.skill.via_points.std(axis=0), OBSERVATION_SCALE_FLOOR)
        self.gp_trajectory = GPSkillTrajectory(
            self.skill, self.interaction_index, self.spec_task.goal_fixed_in_world
        )
        self.window_plan = WindowPlan(
            self.trajectory_model(),
            self.layout,
            self.skill.duration,
            self.sim.control_dt,
            self.config.blend_fraction,
            self.skill.via_points[0, 3:],
            self.skill.via_points,
            trainable=self.method.trainable,
        )
        if self.method.signature_reward:
            from distgprl.skill.signature import signature_similarity

            self._signature_similarity = signature_similarity
        n_points = self.layout.points_per_step
        state_dim = n_points * 6 + n_points + 3 + 3 + 1
        n = self.config.n_via_points
        # aux: Gamma, the step's one-hot and, for L_hap's moving-obstacle filter, the
        # moving obstacles' anchor at every via-point time.
        self.aux_layout = AuxLayout(n, self.layout.n_steps, self.method.hap_prior)
        aux_dim = self.aux_layout.size
        self.observation_space = spaces.Dict(
            {
                "state": spaces.Box(-np.inf, np.inf, (state_dim,), np.float32),
                "aux": spaces.Box(-np.inf, np.inf, (aux_dim,), np.float32),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, (n_points * 6,), np.float32)

    # -- the trajectory model (ProMP-RRL's env overrides it) -----------------------------
    def trajectory_model(self) -> TrajectoryModel:
        """The trajectory the plan adapts: the GP skill's via-points (`gp_trajectory`)."""
        return self.gp_trajectory

    def conditioned_via_points(self, tc) -> np.ndarray:
        """Demonstration via-points conditioned on a TC (DESIGN §2), shape (N, 6), via-point
        0 the current plan's start pose."""
        return self.gp_trajectory.condition(tc, self.window_plan.start_pose)

    def window_distance(self, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """EDF distance (L,), m, and unit gradient (L, 3) at the window's poses.

        With ``clearance_timing == "predicted"`` pose j is checked against the obstacles
        where they will be when the trajectory reaches it (episode time via_time_j * T);
        with ``"current"``, against the obstacles now.
        """
        points = self.window_plan.window_poses(indices)[:, :3]
        times = self.episode_start_time + self.skill.via_times[indices] * self.skill.duration
        return self.clearance.distance(
            points, times, self.world.moving_obstacle_shapes, self._anchors_at()
        )

    def moving_obstacle_anchors(self) -> np.ndarray:
        """The moving obstacles' anchor at every via-point time, shape (N, 3), m (as for
        ``c``: where they will be when the trajectory reaches via-point j, or now)."""
        times = self.episode_start_time + self.skill.via_times * self.skill.duration
        return self.clearance.anchors(times, self.world.moving_obstacle_shapes, self._anchors_at())

    def _anchors_at(self):
        """The simulator's vectorised ``moving_obstacle_anchors_at`` (None if it has none,
        e.g. a perceived scene: the anchors are then read shape by shape)."""
        return getattr(self.world, "moving_obstacle_anchors_at", None)

    def tool_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (centre relative to the TCP, half extents), each (3,), m, that
        holds the tool's surface points at every demonstration via-point orientation."""
        tcp = self.sim.robot.tcp_transform()
        tool = self.sim.robot.tool_points()
        in_tcp = (tool - tcp[:3, 3]) @ tcp[:3, :3]  # the tool points in the TCP frame
        rotations = np.stack([rotvec_to_matrix(v[3:]) for v in self.skill.via_points])
        return tool_bounds(in_tcp, rotations)

    def moving_obstacle_filter(self) -> MovingObstacleFilter:
        """Which C_safe points the moving obstacles block, given their anchor (for L_hap).

        A C_safe point is blocked when the `tool_box` held there would come within
        ``sd_d_min`` (the d_min of r_sd) of a moving obstacle.
        """
        offset, half_extents = self.tool_box()
        return MovingObstacleFilter(
            self.sim.moving_obstacle_shapes(), offset, half_extents, self.config.sd_d_min
        )

    def observation(self) -> dict[str, np.ndarray]:
        """The current observation (``state`` and ``aux``, as returned by `step`)."""
        indices = self.layout.indices[min(self.step_index, self.layout.n_steps - 1)]
        window = self.window_plan.window_poses(indices)
        clearance, _ = self.window_distance(indices)
        config = self.config
        clip = config.clearance_clip
        tcp = self.world.tcp_pose()[:3]
        state = np.concatenate(
            [
                ((window - self._via_mean) / self._via_std).ravel(),
                np.clip(clearance, -clip, clip) / config.clearance_scale,
                self.relative(self.world.object_position() - tcp),
                self.relative(self.world.goal_position() - tcp),
                [self.step_index / self.layout.n_steps],
            ]
        ).astype(np.float32)
        anchors = self.moving_obstacle_anchors() if self.method.hap_prior else None
        return {"state": state, "aux": self.aux_layout.pack(self.gamma, self.step_index, anchors)}

    def _refresh_field(self) -> None:
        """Move the EDF's moving obstacles to their current poses (static ones never move)."""
        self.field.update(self.world.moving_obstacle_shapes())

    def _tool_clearance(self) -> np.ndarray:
        """The tool points' distances (k,), m, to the obstacles where they are now."""
        self._refresh_field()
        return self.field.clearance(self.world.tool_points())  # the distances only (same values)

    def _clearance_penalty(self, distance: np.ndarray) -> float:
        """Eq. safety_reward at one instant from the tool points' distances (k,), m:
        -beta sum 1[d<d_min]/(d+eps)."""
        close = distance < self.config.sd_d_min
        return -self.config.sd_beta * float(
            np.sum(1.0 / (np.maximum(distance[close], 0.0) + self.config.sd_epsilon))
        )

    # -- the plan state's public API (delegated to `window_plan`; hardware adapter, bench) ----
    @property
    def gamma(self) -> np.ndarray:
        """The current parameters Gamma (N, 6): via-points (m, rad) or residual weights."""
        return self.window_plan.gamma

    @gamma.setter
    def gamma(self, value: np.ndarray) -> None:
        self.window_plan.gamma = value

    @property
    def gamma_initial(self) -> np.ndarray:
        """The parameters (N, 6) at the start of the episode."""
        return self.window_plan.gamma_initial

    def start_plan(self, tc, tcp_pose: np.ndarray, start_time: float) -> None:
        """`WindowPlan.start` on ``tc`` from the TCP pose (6,) at ``start_time`` (s); step 0."""
        self.tc = tc
        self.window_plan.start(tc, tcp_pose, start_time)
        self.step_index = 0

    def apply_action(self, step: int, action: np.ndarray) -> np.ndarray:
        """`WindowPlan.apply`: Delta Gamma (A_v, 6) of a raw action, added to Gamma's window
        (zero for the methods that train no policy, ``demo`` and ``promp-nominal``)."""
        return self.window_plan.apply(step, action)

    def segment_tau(self, step: int) -> np.ndarray:
        """Normalised times (m,) of segment ``step``'s control instants (x T for seconds)."""
        return self.window_plan.segment_tau(step)

    def segment_poses(self, step: int) -> np.ndarray:
        """Poses (m, 6) to command at `segment_tau`, continuity-blended (`WindowPlan`)."""
        return self.window_plan.segment_poses(step)

    def plan(self, tau: np.ndarray) -> np.ndarray:
        """Planned poses (m, 6), m and rad, at normalised times ``tau`` (m,) (no blend)."""
        return self.window_plan.poses(tau)

    def mark_commanded(self, step: int, poses: np.ndarray) -> None:
        """Record segment ``step``'s commanded ``poses`` (m, 6): the next blend starts there."""
        self.window_plan.mark_commanded(step, poses)

    @property
    def last_commanded(self) -> np.ndarray:
        """The last commanded pose (6,), m and rad (the start pose before the first segment)."""
        return self.window_plan.last_commanded

    @property
    def episode_start_time(self) -> float:
        """The world's time (s) at the start of the current episode's plan."""
        return self.window_plan.start_time

    # -- gymnasium API ---------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        tc = self.episode_tc(seed, options)
        self.tc = tc
        self.sim.reset(tc)
        self.start_plan(tc, self.sim.tcp_pose(), float(self.sim.time))
        self._episode_over = False
        self._refresh_field()
        self.sim_world.begin_episode()
        self._progress = self.sim.task_progress()
        self.tally = EpisodeTally()  # what the episode's segments add up to
        self._adaptation_times: list[float] = []
        return self.observation(), {"tc": tc}

    def step(self, action: np.ndarray):
        if self._episode_over:
            raise RuntimeError("episode is over; call reset()")
        config, step = self.config, self.step_index
        start = time.perf_counter()
        # Alg. 1 "update EDF using current obstacle state": already done at the end of the
        # previous step (or in reset), and the obstacles have not moved since.
        indices = self.layout.indices[step]
        terms = dict.fromkeys(REWARD_TERMS, 0.0)
        if self.method.distance_rewards:
            # Eq. grad_alignment_reward: grad d at the window's via-points *before* the update
            # (v_j in Gamma_{t_s}^W, not the updated ones).
            _, gradient = self.window_distance(indices)
        delta, poses = plan_segment(
            self, step, action
        )  # Eq. transformed_action, updated_via_points
        if self.method.distance_rewards:
            terms["r_ga"] = config.lambda_ga * float(np.mean(cosine(delta[:, :3], gradient)))
        self._adaptation_times.append(time.perf_counter() - start)

        # Execute the segment in chunks; r_sd from the tool's clearance after each chunk.
        report = execute_segment(self, self.sim_world, step, poses).report
        assert report is not None  # no gate: nothing is refused
        segment_collision = report.collision
        self.tally.add(report)
        for clearance in report.tool_clearances:
            terms["r_sd"] += self._clearance_penalty(clearance)
        progress = self.sim.task_progress()
        terms["r_progress"] = config.progress_weight * (progress - self._progress)
        self._progress = progress
        if segment_collision:
            terms["r_collision"] = -config.collision_penalty
        if self.method.signature_reward and len(poses) > 1:
            tau = self.window_plan.segments[step].tau
            reference = self.skill.position(self.skill.via_points, tau)[:, :3]
            terms["r_signature"] = config.signature_weight * float(
                self._signature_similarity(
                    poses[:, :3], reference, config.signature_depth, config.signature_scale
                )
            )
        stopped = config.collision_ends_episode and segment_collision
        terminated = self.step_index >= self.layout.n_steps or stopped
        info: dict = {"step": step}
        self._episode_over = terminated
        if terminated:
            completed = bool(self.sim.success())
            # Success is completion without collision (as on hardware, where a collision
            # is a protective stop); completion alone is ``completed``.
            success = completed and not (self.tally.collision and config.collision_ends_episode)
            if success:
                terms["r_success"] = config.success_bonus
            velocity = self.window_plan.velocity(self._retention_tau)
            info.update(
                success=success,
                completed=completed,
                collision=bool(self.tally.collision),
                stopped_at_step=step if stopped else -1,
                min_clearance=max(float(self.tally.min_clearance), 0.0),
                min_signed_clearance=float(self.tally.min_clearance),
                peak_joint_speed=float(self.tally.peak_joint_speed),
                kinematic_retention=float(np.mean(cosine(velocity, self._demo_velocity))),
                adaptation_time_s=list(self._adaptation_times),
                final_parameters=self.gamma.copy(),
            )
        if not self.method.distance_rewards:  # else r_sd refreshed it after the last chunk
            self._refresh_field()
        reward = float(sum(terms.values()))
        info.update(terms)
        return self.observation(), reward, terminated, False, info
