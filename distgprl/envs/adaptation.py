"""The windowed via-point adaptation MDP of Dist-GPRL (paper §IV; DESIGN §3).

Env ids: ``DistGPRL-DCP-v8`` and ``DistGPRL-DBM-v8`` (registered in `distgprl.envs`).
"""

from __future__ import annotations

import time

import numpy as np
from gymnasium import spaces

from distgprl.adaptation.layout import OBSERVATION_SCALE_FLOOR, AuxLayout, build_action_layout
from distgprl.adaptation.plan import TrajectoryModel, WindowPlan, min_jerk
from distgprl.adaptation.trajectories import GPSkillTrajectory
from distgprl.config import EnvConfig
from distgprl.envs.base import TaskEnv
from distgprl.envs.clearance import TimedClearance
from distgprl.envs.episode import EpisodeTally, execute_segment, plan_segment
from distgprl.envs.world import SimWorld, WorldState
from distgprl.methods import MethodSpec
from distgprl.safety.hap import MovingObstacleFilter, tool_bounds
from distgprl.sim.transforms import rotvec_to_matrix
from distgprl.skill.gp import GPSkill

REWARD_TERMS = ("r_progress", "r_success", "r_collision", "r_sd", "r_ga", "r_signature")

__all__ = [
    "OBSERVATION_SCALE_FLOOR",
    "REWARD_TERMS",
    "AdaptationEnv",
    "build_action_layout",
    "cosine",
    "min_jerk",
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

    One episode adapts and executes the task's demonstrated skill, conditioned on a task
    configuration (TC), in ``n_windows`` = 3 RL steps. Everything below is for the
    windowed methods (L = 5, N = 15); global methods (``action_mode == "global"``) use
    the same steps and segments with all 13 interior via-points in state and action.

    **Observation** (``Dict``; networks see only ``state``):

    ========================  ========  ==================================================
    ``state`` slice           size      meaning (units)
    ========================  ========  ==================================================
    Gamma_W                   L x 6     window via-points, standardised per axis by the
                                        demonstration via-points' mean and std, the std
                                        floored at 0.05 m / 0.2 rad (dimensionless)
    c                         L         EDF clearance at the window via-point positions,
                                        each against the obstacles where they will be
                                        when the trajectory reaches that via-point
                                        (``clearance_timing``), clipped to
                                        [-clip, clip] m, in units of
                                        ``clearance_scale`` (dimensionless)
    e_o                       3         object position - TCP position, clipped to
                                        +-0.8 m, in units of
                                        ``relative_position_scale`` (dimensionless)
    e_g                       3         goal position - TCP position, likewise
    phi                       1         phase t_s / n_windows in [0, 1] (1 only in the
                                        terminal observation)
    ========================  ========  ==================================================

    ``aux`` (not seen by the networks; used by the regularised actor loss): the full
    current via-points Gamma (N x 6, m and rad, flattened), a one-hot of the step and, for
    methods with the HAP prior, the moving obstacles' anchor position at every via-point's
    time (N x 3, m; `moving_obstacle_anchors`), from which L_hap filters C_safe.

    **Action**: raw a in [-1, 1]^(L x 6), row-major (via-point, axis). It is scaled per
    axis (``position_action_scale`` m, ``rotation_action_scale`` rad; a third of that per
    step for the global methods, which set ``episode_range``), then correlated
    Delta Gamma = S_W a (Eq. transformed_action; identity for ``dist-gprl-nocov`` and
    global methods) and added to the window's via-points (Eq. updated_via_points).
    Via-points 0 (start) and N-1 (end) never change; GPRL also freezes the TC via-point.

    **Transition**: the adapted trajectory's segment for this step (from the window's
    first via-point time to the next window's, the first from t = 0 and the last to the
    end) is executed in the simulator at its control rate while the object and the
    obstacles keep moving. If updating the overlap via-point moved the planned pose at the
    segment start away from where the robot is, the difference is blended out with a
    minimum-jerk weight over ``blend_fraction`` of the segment (continuity).

    **Reward** (Eq. total_reward) r = r_tc + r_sd + lambda_ga r_ga (+ r_signature for
    GPRL), with r_tc = r_progress + r_success + r_collision. Each term is in ``info``
    under its name and they sum to the reward:

    - ``r_progress`` = progress_weight * (task progress after - before), progress in [0, 1];
    - ``r_success`` = success_bonus at the last step if the episode succeeded (v5: the
      task completed without collision);
    - ``r_collision`` = -collision_penalty if the segment had a collision (v5: the
      episode's last step);
    - ``r_sd`` = -beta sum_i 1[d_i < d_min] / (d_i + eps) over the tool points at
      ``sd_samples_per_segment`` instants of the segment (Eq. safety_reward; 0 if the
      method has no distance rewards);
    - ``r_ga`` = lambda_ga * mean_j cos(Delta Gamma_j[xyz], grad d(v_j)) over the window
      via-points v_j *before* this step's update (the points ``c`` was observed at), grad d
      from the same time-indexed field as ``c`` (Eq. grad_alignment_reward; 0 without
      distance rewards). ``info["r_ga"]`` already includes lambda_ga;
    - ``r_signature`` = signature_weight * signature similarity between the executed
      segment's planned path and the demonstration's (GPRL only).

    **Start**: ``reset(seed, options={"tc": TaskConfig})`` or a TC sampled from the
    task's training distribution with the env's generator. The via-points are the
    demonstration's, conditioned on the TC: the interaction via-point and its successors
    move by the object's start offset; via-point 0 is the robot's start pose.

    **End**: ``terminated`` after ``n_windows`` steps, or (v5, ``collision_ends_episode``)
    at the step whose segment collides: execution stops at the control period of the
    collision, as a protective stop ends a hardware trial, and the episode ends there
    (``stopped_at_step``; -1 if it ran to the end). ``info`` at the end carries ``success``
    (v5: the task completed and no collision; with ``collision_ends_episode=False``, v4's
    completion regardless of collision), ``completed`` (the task's success criterion at the
    end, whatever happened before), ``collision``, ``min_clearance`` (m, the minimum
    robot/tool-obstacle distance, >= 0), ``min_signed_clearance`` (m, negative =
    penetration depth), ``peak_joint_speed`` (rad/s, the
    largest commanded joint speed of the episode; not part of the MDP, recorded because
    the hardware safety layer bounds it), ``kinematic_retention`` (mean velocity cosine to
    the demonstration) and ``adaptation_time_s`` per step.

    The ``demo`` reference (``action_mode == "none"``) runs the same episodes with the
    action ignored (Delta Gamma = 0): the TC-conditioned demonstration executed as is.

    **Versions**: v7 — r_sd's beta = eps / (instants x tool points): the whole tool at
    contact for a segment costs one collision penalty (docs/FINDINGS.md "Environment v7").
    v6 (docs/FINDINGS.md "Protocol v6") — (a) r_tc in units of one task and
    beta = eps / 4; (b) S_W from the zero-mean GP of Eq. 1 per axis; (c) action scales from
    the reach rule; (d) TC conditioning by `distgprl.skill.conditioning` (DCP's push ends at
    the world-fixed goal).
    v5 — (a) a collision ends the episode (protective stop) and success is
    completion without collision (``completed`` keeps v4's success); (b) S_W is built per
    axis from the GP's covariance in via-point units (``covariance_scale="signal"``; v4's
    unit-variance K made S_W nearly the identity); (c) DBM's bars vary across the belt too
    (scene revision 2); (d) ``min_clearance`` is a distance (>= 0), the signed value is
    ``min_signed_clearance``. docs/FINDINGS.md "Environment v5".
    v4 — (a) r_ga takes grad d at the window's via-points before the step's
    update, as Eq. grad_alignment_reward defines v_j (v3 used the updated via-points, so a
    move across an obstacle's medial axis could be scored against the gradient on the far
    side); (b) for methods with the HAP prior, ``aux`` carries the moving obstacles'
    anchors, with which L_hap leaves out the C_safe points the moving obstacles block
    (v3's L_hap used the static C_safe only). Methods without distance rewards or HAP
    prior (GPRL, the ``demo`` reference) behave exactly as in v3.
    v3 — position action scale 0.1 m. v2 — time-indexed clearances and r_ga gradients; O(1)
    state inputs. v1 — floored via-point scale. v0 — first release. (CHANGELOG.md: in full.)
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
        # Time-indexed clearances (v2); ``field``: all obstacles as they are now.
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
        # aux: Gamma, the step's one-hot and, for L_hap's moving-obstacle filter (v4), the
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
        """Which C_safe points the moving obstacles block, given their anchor (L_hap, v4).

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
            # (v_j in Gamma_{t_s}^W, not the updated ones; v4).
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
            # v5: success is completion without collision (as on hardware, where a
            # collision is a protective stop); v4's success is kept as ``completed``.
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
