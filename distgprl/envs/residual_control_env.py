"""ProMP-RRL as residual RL: a 10 Hz Cartesian residual on the object-offset ProMP nominal
(Johannink et al. 2018; Carvalho et al. 2022; docs/findings/protocol.md, rule 4).

The numerics (schedule, range, gate, hold, composition) are `distgprl.adaptation.
residual_control`; this module adds the simulator, the nominal and the MDP. Methods
``promp-rrl`` (Table I's ProMP-RRL: the ProMP of the 20 expert demonstrations, protocol
rule 3, "ProMP-RRL as the paper defines it") and the ``promp-nominal`` reference (its nominal,
zero residual); the study methods ``promp-rrl-1demo`` and ``promp-nominal-1demo`` (the ProMP
of one demonstration); action mode ``residual-control``.
"""

from __future__ import annotations

import time
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from distgprl.adaptation.plan import min_jerk
from distgprl.adaptation.residual_control import (
    RL_RATE_HZ,
    GateMode,
    compose,
    control_schedule,
    hold_residual,
    residual_range,
    rotation_error,
    slew_limited,
    variance_gate,
)
from distgprl.config_types import EnvConfig
from distgprl.envs.base import TaskEnv
from distgprl.envs.episode import EpisodeTally, execute_segment, plan_segment
from distgprl.envs.via_point_env import cosine
from distgprl.envs.windowed_residual_env import load_task_promp
from distgprl.envs.world import SimWorld, WorldState
from distgprl.methods import MethodSpec
from distgprl.safety.edf import DistanceField
from distgprl.skill.demos import load_demonstration
from distgprl.skill.promp import ObjectCentricProMP
from distgprl.skill.rotations import nearest_equivalent_rotvec

if TYPE_CHECKING:
    from distgprl.sim.tasks.base import TaskConfig, TaskSpec

__all__ = [
    "GATE_MODE",
    "REWARD_TERMS",
    "ROTATION_ERROR_CLIP",
    "ResidualRLEnv",
    "condition_nominal",
    "load_nominal_promp",
]

REWARD_TERMS = ("r_progress", "r_success", "r_collision")
"""The task-completion terms of `AdaptationEnv` (r_tc); no distance shaping."""

GATE_MODE: GateMode = "certain"
"""Which reading of the variance gate the env uses (`residual_control.GATE_MODES`):
``certain`` — Carvalho et al. use the demonstrations' variability "as a decision variable to
reduce the search space for RRL": the residual acts where the ProMP's variance is low (the
demonstrations agree, the task needs precision there) and is held back where it is high."""

ROTATION_ERROR_CLIP = 4.0
"""The observed orientation error is clipped to +-this many rotation ranges per axis."""


@lru_cache(maxsize=8)
def load_nominal_promp(task: str) -> ObjectCentricProMP:
    """The nominal's ProMP of a ``one``-demonstration method (``promp-rrl-1demo``): the ProMP
    of the task's one demonstration itself, fitted (same basis and ridge as
    `load_task_promp`) to the shipped demonstration at its own TC (object offset 0), so its
    mean is the demonstration in the ProMP's basis, in the world frame.

    (The mean of `load_task_promp`'s ProMP is not: it averages 20 conditioned copies, whose
    mean offset, a few cm, would shift the approach; its variance is what the gate uses.)
    """
    from distgprl.sim.tasks import get_task

    demo = load_demonstration(get_task(task).demo_path)
    config = load_task_promp(task, "one").config
    return ObjectCentricProMP.fit([(demo.times, demo.poses)], np.zeros((1, 3)), config)


def condition_nominal(
    spec: TaskSpec, tau: np.ndarray, reference: np.ndarray, tc: TaskConfig
) -> np.ndarray:
    """The nominal of a ``one``-demonstration method conditioned on ``tc``: the one place
    that says how the TC moves it.

    The TC conditioning of docs/findings/protocol.md, rule 2, as every method gets it for a
    dense trajectory (`distgprl.sim.tasks.base.condition_by_translation`): the poses are
    translated by the object offset (dx, dy, 0) weighted by w(tau) — 1 at the task's
    interaction time, ramping in with a minimum-jerk blend before it, and after it falling
    linearly to 0 at the end where the goal is fixed in the world (DCP) or staying 1 (DBM).

    Args:
        spec: the `TaskSpec` (interaction time, goal rule).
        tau: normalised times (m,) from 0 to 1 (the first and last are the ends).
        reference: the unconditioned poses (m, 6) at ``tau``, m and rad.
        tc: the task configuration.

    Returns:
        The conditioned poses (m, 6).
    """
    from distgprl.sim.tasks.base import condition_by_translation

    conditioned: np.ndarray = condition_by_translation(
        tau,
        reference,
        np.asarray(tc.object_offset, dtype=float),
        spec.interaction_time,
        goal_fixed_in_world=spec.goal_fixed_in_world,
    )
    return conditioned


class ResidualRLEnv(TaskEnv):
    """Residual RL on the object-offset ProMP nominal, one RL step per 0.1 s (ProMP-RRL).

    An episode executes the task's trajectory of T = the demonstration's duration (4.8 s
    DCP, 5.0 s DBM) at the simulator's control rate (25 Hz); the policy acts at
    ``RL_RATE_HZ`` = 10 Hz: n = ceil(T x 10) RL steps per episode (48 DCP, 50 DBM). RL
    step j executes the control periods whose ends lie in (j / 10, (j + 1) / 10] s (2 and
    3 alternately; `residual_control.control_schedule`).

    **ProMP** (`MethodSpec.demonstrations`; how many demonstrations it is fitted on is
    recorded in the run's ``config.json`` as ``demonstration_count``): ``expert``
    (``promp-rrl``, ``promp-nominal``) — one object-centric ProMP fitted over the 20 shipped
    expert demonstrations (`load_task_promp`, refused unless they are exactly 20, each
    successful and collision-free for its TC), the nominal's and the gate's; ``one``
    (``promp-rrl-1demo``, ``promp-nominal-1demo``) — the nominal
    from the ProMP of the one demonstration (`load_nominal_promp`; its mean fits the
    demonstration to about 2 mm), the gate from the ProMP of 20 copies of it conditioned on
    training TCs.

    **Nominal** (from ``nominal_promp``): ``expert`` — the paper's "nominal trajectory offset
    by the observed object" (§V-B): the ProMP's mean in the object frame plus the object's
    offset (dx, dy, 0), conditioned on the start pose at phase 0
    (`ObjectCentricProMP.start_conditioned_mean`, as ``promp-rrl-expert``'s nominal): the
    demonstrations all start at one pose in the world, so their start varies in the object
    frame, and the conditioning moves the rest of the mean as their weights covary with it
    (on DCP, goal fixed in the world, the return too; without it the nominal ends up to the
    whole offset from the goal, zero-residual DCP success 0.32 against 0.77 on 100
    evaluation TCs); ``one`` — the ProMP's mean moved by the TC conditioning every GP method
    gets (`condition_nominal`). Then the robot's start pose blended in: the difference between
    the TCP pose at reset and the conditioned nominal at t = 0 is added with a weight
    falling from 1 to 0 (minimum jerk) over the first ``blend_fraction / n_windows`` of the
    trajectory (0.1 of T by default, about the 0.09 of T over which `AdaptationEnv` blends
    its first segment's start; the mismatch is under 1 mm on both tasks, either nominal).

    **Gate** (per control instant t_k): g_k = 1 - sigma(t_k) / max_i sigma(t_i), sigma(t) the
    mean over x, y, z of the marginal positional standard deviation of the gate's ProMP
    (``promp``, in the object frame, not conditioned on the start), the maximum over the
    episode's control instants: where the demonstrations vary most the residual is held
    back, where they agree it passes whole (Carvalho et al.)
    (`residual_control.variance_gate`, mode ``GATE_MODE`` = ``"certain"``). One gate for
    all six channels, from the positional variance: the TCs vary only positions (what
    orientation variance the expert demonstrations have, DCP's tool yaw, follows from them).

    **Action**: raw a in [-1, 1]^6, clipped, scaled per axis by the residual range
    rho = `residual_control.residual_range` (max(TC range, ``minimum_position_reach``) on
    each position axis, ``minimum_rotation_reach`` on each rotation axis: DCP 0.2, 0.2,
    0.1 m; DBM 0.1, 0.2, 0.1 m; 0.05 rad — the reach rule of every method, so the residual
    reaches the whole TC offset the nominal does not absorb: the approach before the
    ramp-in and DCP's return to the goal after the interaction, where the nominal is up to
    the full offset from the object, and at least 0.1 m, the moving obstacles' size,
    everywhere): the policy's target rho * a (dx, dy, dz m; rotation vector rad). The
    residual r_j at the end of step j approaches it from r_{j-1} by at most
    rho * dt_j / ``SLEW_TIME_S`` per axis (dt_j = 0.08 or 0.12 s, the step's span; 0.4 s to
    cross the range, 0.5 m/s on a 0.2 m range: half the hardware TCP speed bound;
    `residual_control.slew_limited`); r_{-1} = 0.

    **Commanded poses** (per control period): at control instant t_k of step j,
    residual(t_k) = r_{j-1} + f_k (r_j - r_{j-1}) (a first-order hold, f_k = 1/2, 1 or
    1/3, 2/3, 1 over the step), and pose(t_k) = nominal(t_k) + g_k residual(t_k)
    in position, Exp(g_k residual_rot(t_k)) R_nominal(t_k) in orientation
    (`residual_control.compose`). The poses are executed by the task's robot, IK and control
    loop (`TaskSim.execute`) while the objects and obstacles keep moving. A zero action
    executes the nominal exactly.

    **Observation** (``Dict``; ``state`` only, float32):

    ========================  ========  ==================================================
    ``state`` slice           size      meaning (units)
    ========================  ========  ==================================================
    p - p_nominal             3         TCP position - nominal position at the current
                                        time, clipped to +-0.8 m, in units of
                                        ``relative_position_scale`` (dimensionless)
    rot error                 3         rotation vector of R_tcp R_nominal^T, in units of
                                        the rotation range, clipped to +-4
    r_{j-1} / rho             6         the residual in force (the last step's r), in
                                        units of the range (in [-1, 1])
    e_o                       3         object position - TCP position, clipped to
                                        +-0.8 m, in units of ``relative_position_scale``
    e_g                       3         goal position - TCP position, likewise
    phi                       1         phase j / n in [0, 1] (1 only when terminal)
    g                         1         the gate at the next step's last control instant
                                        (0 when terminal)
    c                         1         EDF clearance of the tool now: the least distance
                                        of its surface points to the obstacles, clipped to
                                        +-``clearance_clip`` m, in units of
                                        ``clearance_scale``
    grad c                    3         the EDF's unit gradient at that point
    ========================  ========  ==================================================

    **Reward** r = r_progress + r_success + r_collision, each in ``info`` under its name
    (summing to the reward), computed as `AdaptationEnv` computes r_tc, from the same
    `EnvConfig` fields:

    - ``r_progress`` = progress_weight * (task progress after the step - before);
    - ``r_success`` = success_bonus at the last step if the episode succeeded;
    - ``r_collision`` = -collision_penalty if the step's control periods had a collision
      (with ``collision_ends_episode``, the episode's last step).

    No distance shaping, no HAP prior, no L_sim.

    **Start**: ``reset(seed, options={"tc": TaskConfig})`` or a TC drawn from the task's
    training distribution with the env's generator; the residual r_{-1} is 0.

    **End**: ``terminated`` after the n-th RL step, or (``collision_ends_episode``) at the
    step whose control periods collide: execution stops at the colliding control period
    (``stopped_at_step``, -1 if it ran to the end). ``info`` at the end has
    `AdaptationEnv`'s keys: ``success`` (completed and, with ``collision_ends_episode``,
    no collision), ``completed``, ``collision``, ``min_clearance`` (m, >= 0),
    ``min_signed_clearance`` (m), ``peak_joint_speed`` (rad/s), ``kinematic_retention``
    (mean cosine, over 100 times, between the velocity of the episode's commanded
    trajectory — after a stop, continued with the last residual — and the
    demonstration's GP velocity), ``adaptation_time_s`` (the policy-to-poses time summed
    over each third of the episode's RL steps, one entry per third reached, so the
    evaluation's three columns add up to the episode's) and ``final_parameters`` (the
    residuals r_j, shape (n, 6), m and rad; 0 for steps not reached).
    """

    def __init__(
        self,
        task: str,
        method: str | MethodSpec = "promp-rrl",
        config: EnvConfig | None = None,
        render_mode: str | None = None,
        promp: ObjectCentricProMP | None = None,
    ) -> None:
        """``promp`` replaces the method's ProMP (`load_task_promp`): the gate's, and for an
        ``expert`` method the nominal's too."""
        self.build(
            task,
            method,
            config,
            render_mode,
            ("residual-control",),
            "method {name} is not a residual-control method",
        )
        self.duration = float(self.skill.duration)
        self.schedule = control_schedule(self.duration, self.sim.control_dt, RL_RATE_HZ)
        self.n_steps = self.schedule.n_steps
        # The nominal on tau = 0 and every control instant (index k + 1 is instant k).
        self._tau = np.r_[0.0, self.schedule.tau]
        self.promp = (
            promp if promp is not None else load_task_promp(task, self.method.demonstrations)
        )
        self.nominal_promp = self.promp if self._fits_expert else load_nominal_promp(task)
        # the nominal ProMP's mean for the object at offset 0 (what `condition_nominal` moves)
        self._reference = self.nominal_promp.mean_trajectory(self._tau)
        self.gate = variance_gate(self.promp.trajectory_std(self.schedule.tau)[:, :3], GATE_MODE)
        self.residual_scale = residual_range(
            np.asarray(self.spec_task.tc_range),
            self.config.minimum_position_reach,
            self.config.minimum_rotation_reach,
        )
        blend = self.config.blend_fraction / self.config.n_windows
        self._start_weight = 1.0 - min_jerk(self._tau / blend)
        self.field = DistanceField(self.sim.obstacle_shapes())
        self._retention_tau = np.linspace(0.0, 1.0, 100)
        self._demo_velocity = self.skill.velocity(self.skill.via_points, self._retention_tau)
        self.observation_space = spaces.Dict(
            {"state": spaces.Box(-np.inf, np.inf, (24,), np.float32)}
        )
        self.action_space = spaces.Box(-1.0, 1.0, (6,), np.float32)
        self.nominal_poses = self._reference.copy()
        self._residuals = np.zeros((self.n_steps, 6))
        self._pending = np.zeros(6)  # the current RL step's residual and poses (`apply_action`)
        self._pending_poses = np.zeros((0, 6))
        # Where the RL steps run (the simulation) and what the observation reads (the
        # hardware trials' adapter: the perceived scene).
        self.sim_world = SimWorld(self.sim, stop_on_collision=self.config.collision_ends_episode)
        self.world: WorldState = self.sim_world

    # -- the episode's plan ------------------------------------------------------------------
    @property
    def _fits_expert(self) -> bool:
        """Whether the nominal is the object-centric ProMP of the expert demonstrations."""
        return self.method.demonstrations == "expert"

    def start_plan(self, tc: TaskConfig, tcp_pose: np.ndarray, start_time: float) -> None:
        """Condition the nominal on ``tc`` and blend the TCP pose (6,) in at its start; step 0.
        ``start_time`` (s) is the via-point env's `start_plan`'s: the nominal keeps the
        demonstration's timing, so it does not use it."""
        self.tc = tc
        if self._fits_expert:
            offset = np.r_[np.asarray(tc.object_offset, dtype=float), 0.0]
            nominal = self.nominal_promp.start_conditioned_mean(self._tau, offset, tcp_pose)
        else:
            nominal = condition_nominal(self.spec_task, self._tau, self._reference, tc)
        start = np.array(tcp_pose, dtype=float)
        start[3:] = nearest_equivalent_rotvec(start[3:], nominal[0, 3:])
        nominal += self._start_weight[:, None] * (start - nominal[0])[None, :]
        self.nominal_poses = nominal
        self.commanded_poses = nominal.copy()  # filled in as the episode executes
        self._residuals = np.zeros((self.n_steps, 6))
        self._instants_done = 0
        self.step_index = 0

    def _previous_residual(self, step: int) -> np.ndarray:
        """The residual (6,) in force at the start of RL step ``step`` (0 before the first)."""
        return self._residuals[step - 1] if step > 0 else np.zeros(6)

    def step_residual(self, step: int, raw: np.ndarray) -> np.ndarray:
        """The residual (6,), m and rad, at the end of RL step ``step`` for a raw action
        ``raw`` (6,) in [-1, 1]: the target ``raw * residual_scale`` approached from the
        previous step's residual at the slew limit (`residual_control.slew_limited`)."""
        target = np.clip(np.asarray(raw, dtype=float).reshape(6), -1.0, 1.0) * self.residual_scale
        if not self.method.trainable:  # the promp-nominal reference ignores the action
            target = np.zeros(6)
        duration = float(self.schedule.step_duration[step])
        return slew_limited(self._previous_residual(step), target, self.residual_scale, duration)

    def step_poses(self, step: int, residual: np.ndarray) -> np.ndarray:
        """The poses (m_j, 6) RL step ``step`` commands to end at ``residual`` (6,), m and
        rad, from the previous step's (`residual_control.hold_residual`, `compose`)."""
        indices = self.schedule.steps[step]
        fraction = self.schedule.fraction[indices]
        held = hold_residual(self._previous_residual(step), residual, fraction)
        return compose(self.nominal_poses[indices + 1], held, self.gate[indices])

    # -- the plan's API (the episode loop's, `distgprl.envs.episode.PlanAdapter`) ------------
    def apply_action(self, step: int, action: np.ndarray) -> np.ndarray:
        """The residual (6,), m and rad, at the end of RL step ``step`` for the raw action
        (6,) (`step_residual`; the ``promp-nominal`` reference: 0), and the step's poses."""
        self._pending = self.step_residual(step, action)
        self._pending_poses = self.step_poses(step, self._pending)
        return self._pending

    def segment_poses(self, step: int) -> np.ndarray:
        """The poses (m_j, 6) RL step ``step`` commands (`step_poses` of `apply_action`'s
        residual): nominal + gated residual, one per control period."""
        return self._pending_poses.copy()

    def mark_commanded(self, step: int, poses: np.ndarray) -> None:
        """Record RL step ``step`` as executed: ``poses`` its commanded path (a re-timed
        step's path has more instants than the step's control periods; fewer: stopped)."""
        indices = self.schedule.steps[step]
        done = len(indices) if len(poses) >= len(indices) else len(poses)
        self.commanded_poses[indices[:done] + 1] = self._pending_poses[:done]
        self._instants_done = int(indices[0]) + done
        self._residuals[step] = self._pending

    @property
    def last_commanded(self) -> np.ndarray:
        """The last commanded pose (6,) (the blended start before the first step)."""
        return np.asarray(self.commanded_poses[self._instants_done], dtype=float).copy()

    # -- observation -------------------------------------------------------------------------
    def observation(self) -> dict[str, np.ndarray]:
        """The current observation (``state``, as returned by `step`)."""
        config = self.config
        nominal = self.nominal_poses[self._instants_done]
        tcp = self.world.tcp_pose()
        rotation = rotation_error(tcp, nominal) / self.residual_scale[3:]
        self.field.update(self.world.moving_obstacle_shapes())
        distance, gradient = self.field.distance(self.world.tool_points())
        closest = int(np.argmin(distance))
        clip = config.clearance_clip
        terminal = self.step_index >= self.n_steps
        next_gate = 0.0 if terminal else self.gate[self.schedule.steps[self.step_index][-1]]
        state = np.concatenate(
            [
                self.relative(tcp[:3] - nominal[:3]),
                np.clip(rotation, -ROTATION_ERROR_CLIP, ROTATION_ERROR_CLIP),
                self._previous_residual(self.step_index) / self.residual_scale,
                self.relative(self.world.object_position() - tcp[:3]),
                self.relative(self.world.goal_position() - tcp[:3]),
                [self.step_index / self.n_steps, next_gate],
                [np.clip(distance[closest], -clip, clip) / config.clearance_scale],
                gradient[closest],
            ]
        ).astype(np.float32)
        return {"state": state}

    # -- gymnasium API -----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        tc = self.episode_tc(seed, options)
        self.sim.reset(tc)
        self.start_plan(tc, self.sim.tcp_pose(), float(self.sim.time))
        self._episode_over = False
        self._progress = self.sim.task_progress()
        self.tally = EpisodeTally()  # what the episode's RL steps add up to
        self._step_times: list[float] = []
        return self.observation(), {"tc": tc}

    def step(self, action: np.ndarray):
        if self._episode_over:
            raise RuntimeError("episode is over; call reset()")
        config, step = self.config, self.step_index
        start = time.perf_counter()
        residual, poses = plan_segment(self, step, action)
        self._step_times.append(time.perf_counter() - start)

        stop = config.collision_ends_episode
        result = execute_segment(self, self.sim_world, step, poses).report
        assert result is not None  # no gate: nothing is refused
        self.tally.add(result)
        terms = dict.fromkeys(REWARD_TERMS, 0.0)
        progress = self.sim.task_progress()
        terms["r_progress"] = config.progress_weight * (progress - self._progress)
        self._progress = progress
        if result.collision:
            terms["r_collision"] = -config.collision_penalty
        stopped = stop and result.collision
        terminated = self.step_index >= self.n_steps or stopped
        self._episode_over = terminated
        info: dict = {"step": step}
        if terminated:
            completed = bool(self.sim.success())
            success = completed and not (self.tally.collision and stop)
            if success:
                terms["r_success"] = config.success_bonus
            info.update(
                success=success,
                completed=completed,
                collision=bool(self.tally.collision),
                stopped_at_step=step if stopped else -1,
                min_clearance=max(float(self.tally.min_clearance), 0.0),
                min_signed_clearance=float(self.tally.min_clearance),
                peak_joint_speed=float(self.tally.peak_joint_speed),
                kinematic_retention=self._kinematic_retention(residual),
                adaptation_time_s=self._adaptation_times(),
                final_parameters=self._residuals.copy(),
            )
        reward = float(sum(terms.values()))
        info.update(terms)
        return self.observation(), reward, terminated, False, info

    def _kinematic_retention(self, last_residual: np.ndarray) -> float:
        """Mean velocity cosine between the episode's commanded trajectory (continued with
        ``last_residual`` (6,) after a stop) and the demonstration's."""
        poses = self.commanded_poses.copy()
        rest = np.arange(self._instants_done, len(self.schedule.tau))
        if len(rest):
            held = np.tile(last_residual, (len(rest), 1))
            poses[rest + 1] = compose(self.nominal_poses[rest + 1], held, self.gate[rest])
        times = self._tau * self.duration
        velocity = np.gradient(poses, times, axis=0)
        at = self._retention_tau * self.duration
        sampled = np.stack([np.interp(at, times, velocity[:, a]) for a in range(6)], axis=1)
        return float(np.mean(cosine(sampled, self._demo_velocity)))

    def _adaptation_times(self) -> list[float]:
        """The per-step computation times summed over each third of the episode's RL
        steps, s (one entry per third the episode reached)."""
        thirds = np.array_split(np.arange(self.n_steps), 3)
        done = len(self._step_times)
        return [
            float(sum(self._step_times[k] for k in third if k < done))
            for third in thirds
            if len(third) and third[0] < done
        ]
