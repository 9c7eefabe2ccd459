"""Benchmarks (`distgprl bench [--quick]`): medians and spreads with warm-up and repeats.

Sections of `run_benchmarks` (all measured in one process, so ratios compare like with like):

1. **Adaptation compute** per window and per episode, as in the paper (§V): EDF query at the
   window via-points and the tool points, GP conditioning (the window update
   Delta Gamma = S_W a plus re-evaluating the executed segment of the trajectory), policy
   inference of a SAC actor with the real observation size, and the total, side by side with
   the paper's figures and with naive alternatives measured in the same run (PyBullet
   ``getClosestPoints`` for the same points and shapes; re-solving the GP from scratch).
2. One simulated episode per task (full trajectory, dynamics and contact checks).
3. One SAC gradient step with the regularised actor loss (batch 256, paper network) vs plain SAC,
   in wall and in process CPU time (the latter is ``ratios.regularised_over_plain_sac_step``).
4. Training throughput of a short real training run and where its time goes (timers around
   simulation, IK, EDF, SAC update, ...).
5. Scaling: adaptation time vs number of via-points and of obstacles; training throughput vs
   number of worker processes.

Every timing is wall time of the calling process; the machine's load average is recorded
before and after, because other processes sharing the cores inflate every figure.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.agents.sac import NumpyActor

# The paper's per-window figures (ms, i7-1185G7) and its per-episode total.
PAPER_MS_PER_WINDOW = {"edf": 4.0, "gp_conditioning": 2.0, "policy": 0.5}
PAPER_MS_PER_EPISODE = 19.3
TARGET_MS_PER_EPISODE = 1.0
BENCH_TASK = "dcp"
BENCH_METHOD = "dist-gprl"


@dataclass(frozen=True)
class Timing:
    """Wall-time statistics of one operation, in microseconds."""

    median_us: float
    p10_us: float
    p90_us: float
    repeats: int

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_samples(cls, samples_s: np.ndarray | list[float]) -> Timing:
        """Statistics of per-call durations given in seconds."""
        us = np.asarray(samples_s, dtype=float) * 1e6
        return cls(
            float(np.median(us)),
            float(np.percentile(us, 10)),
            float(np.percentile(us, 90)),
            int(us.size),
        )


def measure(
    func: Callable[[], object], repeats: int = 200, warmup: int = 20, inner: int = 10
) -> Timing:
    """Time ``func``: ``warmup`` untimed calls, then ``repeats`` samples of ``inner`` calls."""
    for _ in range(warmup):
        func()
    samples = np.empty(repeats)
    for i in range(repeats):
        start = time.perf_counter()
        for _ in range(inner):
            func()
        samples[i] = (time.perf_counter() - start) / inner
    samples *= 1e6
    return Timing(
        float(np.median(samples)),
        float(np.percentile(samples, 10)),
        float(np.percentile(samples, 90)),
        repeats,
    )


def measure_interleaved(
    funcs: dict[str, Callable[[], object]],
    repeats: int,
    warmup: int = 3,
    inner: int = 1,
    clock: Callable[[], float] = time.perf_counter,
) -> dict[str, Timing]:
    """Time several functions with their samples interleaved (A, B, A, B, ...).

    On a loaded machine the load drifts over seconds; interleaving exposes every candidate to
    the same drift, so the ratio of their medians is fair. ``clock`` (seconds) is wall time by
    default; ``time.process_time`` gives process CPU time, which other processes sharing the
    cores inflate far less.
    """
    for func in funcs.values():
        for _ in range(warmup):
            func()
    samples = {name: np.empty(repeats) for name in funcs}
    for i in range(repeats):
        for name, func in funcs.items():
            start = clock()
            for _ in range(inner):
                func()
            samples[name][i] = (clock() - start) / inner
    return {name: Timing.from_samples(values) for name, values in samples.items()}


def bench_gp(n_query: int = 200, n_via_points: int = 15, seed: int = 0) -> dict[str, Timing]:
    """GP skill: trajectory evaluation at ``n_query`` times and one window update.

    Compared with the naive alternative (rebuilding the conditioning maps from the kernel,
    i.e. re-solving the GP, on every evaluation).
    """
    from distgprl.skill.gp import GPSkill, KernelParams

    rng = np.random.default_rng(seed)
    skill = GPSkill(
        kernel=KernelParams(0.12, 1.0, 1e-6),
        via_times=np.linspace(0, 1, n_via_points),
        via_points=rng.normal(size=(n_via_points, 6)),
        prior_mean=np.zeros(6),
        duration=5.0,
        axis_scale=np.full(6, 0.3),
    )
    tau = np.linspace(0, 1, n_query)
    maps = skill.maps(tau)
    gamma = skill.via_points.copy()
    window = np.arange(5, 10)
    s_w = skill.window_operator(window)
    action = rng.uniform(-1, 1, size=(5, 6))

    def evaluate():
        return maps.positions(gamma)

    def window_update():
        gamma[window] += s_w @ action

    def naive_refit():
        fresh = GPSkill(skill.kernel, skill.via_times, gamma, skill.prior_mean, skill.duration)
        return fresh.position(gamma, tau)

    return {
        "trajectory_eval": measure(evaluate),
        "window_update": measure(window_update),
        "naive_gp_resolve": measure(naive_refit, repeats=50),
    }


# ------------------------------------------------------------------------------ sizes
@dataclass(frozen=True)
class BenchSizes:
    """How much `run_benchmarks` measures (repeats, episodes, sweep points).

    Attributes:
        repeats: samples per adaptation micro-benchmark (each of ``inner`` calls).
        inner: calls per sample of the fast (microsecond) operations.
        naive_repeats: samples of the slow naive alternatives (PyBullet, GP re-solve).
        in_env_episodes: real environment episodes whose recorded adaptation time is reported.
        sim_episodes: simulated episodes per task.
        tasks: tasks of the simulation benchmark.
        sac_repeats: samples of one SAC gradient step (regularised and plain, interleaved).
        learning_starts: random-action steps before gradient steps start (not timed).
        training_steps: timed training steps (each: env step + one gradient step).
        worker_steps: timed training steps per worker in the worker-scaling runs.
        workers: worker counts of the worker-scaling runs (independent processes).
        via_points: via-point counts of the via-point scaling curve.
        obstacles: box counts of the obstacle scaling curve.
        scaling_repeats: samples per point of the scaling curves.
    """

    repeats: int
    inner: int
    naive_repeats: int
    in_env_episodes: int
    sim_episodes: int
    tasks: tuple[str, ...]
    sac_repeats: int
    learning_starts: int
    training_steps: int
    worker_steps: int
    workers: tuple[int, ...]
    via_points: tuple[int, ...]
    obstacles: tuple[int, ...]
    scaling_repeats: int


FULL_SIZES = BenchSizes(
    repeats=200,
    inner=10,
    naive_repeats=40,
    in_env_episodes=30,
    sim_episodes=20,
    tasks=("dcp", "dbm"),
    sac_repeats=60,
    learning_starts=60,
    training_steps=1200,
    worker_steps=450,
    workers=(1, 2),
    via_points=(15, 30, 45, 60),
    obstacles=(1, 2, 4, 8, 16, 32),
    scaling_repeats=60,
)
QUICK_SIZES = BenchSizes(
    repeats=40,
    inner=5,
    naive_repeats=8,
    in_env_episodes=5,
    sim_episodes=2,
    tasks=("dcp", "dbm"),
    sac_repeats=12,
    learning_starts=20,
    training_steps=60,
    worker_steps=45,
    workers=(1, 2),
    via_points=(15, 60),
    obstacles=(1, 8, 32),
    scaling_repeats=10,
)
TINY_SIZES = BenchSizes(
    repeats=5,
    inner=2,
    naive_repeats=2,
    in_env_episodes=1,
    sim_episodes=1,
    tasks=("dcp",),
    sac_repeats=2,
    learning_starts=6,
    training_steps=6,
    worker_steps=6,
    workers=(1,),
    via_points=(15, 30),
    obstacles=(1, 4),
    scaling_repeats=2,
)
"""The test-suite size: every section runs, numbers are meaningless."""


# ------------------------------------------------------------------------------ helpers
def machine_info() -> dict[str, Any]:
    """CPU model, core count, load average, Python and torch threading."""
    import torch

    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_average": list(os.getloadavg()),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "torch_threads": torch.get_num_threads(),
    }


def _run_spec(
    task: str = BENCH_TASK,
    method: str = BENCH_METHOD,
    env_overrides: dict[str, Any] | None = None,
    sac_overrides: dict[str, Any] | None = None,
):
    """The paper preset with the given overrides (a small replay buffer: allocation only)."""
    from distgprl.config import load_config
    from distgprl.experiments.runner import RunSpec
    from distgprl.methods import get_method

    overrides: dict[str, dict[str, Any]] = {"sac": {"buffer_size": 20_000, **(sac_overrides or {})}}
    if env_overrides:
        overrides["env"] = env_overrides
    return RunSpec(task, get_method(method), 0, load_config("paper", task, overrides))


def _shape_bodies(client, shapes) -> list[int]:
    """One static PyBullet body per EDF primitive, built as the task simulations build them."""
    from distgprl.sim.bullet import create_shape_body

    return [create_shape_body(client, shape, (0.5, 0.5, 0.5, 1.0)) for shape in shapes]


class BulletDistance:
    """The naive EDF: PyBullet closest points of a point-sized probe, one query per body.

    The probe (a sphere of ``PROBE_RADIUS``) is moved to each point and
    ``getClosestPoints`` is called against every obstacle body; the minimum plus the probe
    radius is the point's distance. Used for the same points and shapes as the EDF.
    """

    PROBE_RADIUS = 1e-4

    def __init__(self, shapes) -> None:
        import pybullet

        from distgprl.sim.bullet import connect_direct

        self.client = connect_direct()
        shape = self.client.createCollisionShape(pybullet.GEOM_SPHERE, radius=self.PROBE_RADIUS)
        self.probe = self.client.createMultiBody(0, shape)
        self.bodies = _shape_bodies(self.client, shapes)
        self._reset = self.client.resetBasePositionAndOrientation
        self._closest = self.client.getClosestPoints

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (n,) of each point (n, 3) to the nearest body, m (capped at 10 m)."""
        out = np.empty(len(points))
        probe, bodies, reset, closest = self.probe, self.bodies, self._reset, self._closest
        for i, point in enumerate(points.tolist()):
            reset(probe, point, (0.0, 0.0, 0.0, 1.0))
            best = 10.0
            for body in bodies:
                for contact in closest(probe, body, 10.0):
                    best = min(best, contact[8])
            out[i] = best + self.PROBE_RADIUS
        return out

    def close(self) -> None:
        self.client.disconnect()


class AdaptationPipeline:
    """The adaptation compute of one episode, isolated from the simulation.

    Per window k (as `AdaptationEnv.step` does, plus policy inference): the actor maps the
    observation to a raw action (policy: the SAC actor's weights run by `NumpyActor`); the EDF
    is refreshed from the obstacle shapes and queried at the window via-points and the tool
    points (EDF); the window's via-points are updated with Delta Gamma = S_W a and the segment
    to execute is re-evaluated from the GP's precomputed map (GP conditioning). The obstacle
    shapes and tool points are read from the simulator once (state reads are not compute; the
    env's own timer includes them).

    Args:
        env: an `AdaptationEnv` after `reset` (its layout, skill, segment maps and field).
        actor: the SB3 SAC actor (``actor(obs, deterministic=True)``).
        field: the distance field to query (default the env's).
        shapes: obstacle shapes for the field's update (default the env's current ones).
    """

    def __init__(self, env, actor, field=None, shapes=None) -> None:
        import torch

        self.env = env
        self.actor = actor
        self.numpy_actor = NumpyActor(actor)
        self.field = field if field is not None else env.field
        self.shapes = tuple(shapes) if shapes is not None else tuple(env.sim.obstacle_shapes())
        self.tool_points = np.asarray(env.sim.tool_points())
        self.gamma_initial = env.gamma.copy()
        self.state = env.observation()["state"]
        self.layout = env.layout
        self._torch = torch
        rng = np.random.default_rng(0)
        self.actions = rng.uniform(-1, 1, (self.layout.n_steps, self.layout.points_per_step * 6))

    def edf(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """EDF update and query at the window via-points and tool points."""
        self.field.update(self.shapes)
        indices = self.layout.indices[step]
        points = np.concatenate((self.env.gamma[indices, :3], self.tool_points))
        return self.field.distance(points)

    def gp_conditioning(self, step: int, action: np.ndarray) -> np.ndarray:
        """Delta Gamma = S_W a on the window, then the segment's poses (m, 6)."""
        self.env.apply_action(step, action)
        return self.env.segment_poses(step)

    def policy(self) -> np.ndarray:
        """Deterministic action for the current observation, (A,) (`NumpyActor`)."""
        return self.numpy_actor(self.state)

    def policy_torch(self) -> np.ndarray:
        """The same action from the torch actor (``inference_mode``), (A,)."""
        torch = self._torch
        with torch.inference_mode():
            state = torch.as_tensor(self.state).unsqueeze(0)
            return self.actor({"state": state}, deterministic=True)[0].numpy()

    def window(self, step: int) -> np.ndarray:
        """Policy + EDF + GP conditioning of one window."""
        action = self.policy()
        self.edf(step)
        return self.gp_conditioning(step, action)

    def restart(self) -> None:
        self.env.gamma[:] = self.gamma_initial

    def episode(self) -> None:
        """All windows of one episode (from the episode's initial via-points)."""
        self.restart()
        for step in range(self.layout.n_steps):
            self.window(step)


def _naive_pipeline(pipeline: AdaptationPipeline, bullet: BulletDistance, model):
    """Naive counterparts: PyBullet distances, GP re-solve, SB3 ``predict``."""
    from distgprl.skill.gp import GPSkill

    env = pipeline.env
    skill = env.skill
    obs = env.observation()

    def edf(step: int) -> np.ndarray:
        points = np.concatenate(
            (env.gamma[pipeline.layout.indices[step], :3], pipeline.tool_points)
        )
        return bullet.distance(points)

    def gp(step: int, action: np.ndarray) -> np.ndarray:
        env.apply_action(step, action)
        fresh = GPSkill(skill.kernel, skill.via_times, env.gamma, skill.prior_mean, skill.duration)
        return fresh.position(env.gamma, env.segment_tau(step))

    def policy() -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    return edf, gp, policy


# ------------------------------------------------------------------------------ sections
def bench_adaptation(env, model, sizes: BenchSizes) -> dict[str, Any]:
    """Section 1: per-window and per-episode adaptation compute vs paper and naive versions."""
    from distgprl.experiments.runner import deterministic_policy, run_episode

    pipeline = AdaptationPipeline(env, model.actor)
    bullet = BulletDistance(pipeline.shapes)
    try:
        naive_edf, naive_gp, naive_policy = _naive_pipeline(pipeline, bullet, model)
        points = np.concatenate((env.gamma[pipeline.layout.indices[1], :3], pipeline.tool_points))
        agreement = float(
            np.max(np.abs(bullet.distance(points) - pipeline.field.distance(points)[0]))
        )
        step, action = 1, pipeline.actions[1]

        def ours_gp() -> None:
            pipeline.restart()
            pipeline.gp_conditioning(step, action)

        def theirs_gp() -> None:
            pipeline.restart()
            naive_gp(step, action)

        def naive_episode() -> None:
            pipeline.restart()
            for k in range(pipeline.layout.n_steps):
                naive_gp(k, naive_policy())
                naive_edf(k)

        fast = {
            "edf": lambda: pipeline.edf(step),
            "gp_conditioning": ours_gp,
            "policy": pipeline.policy,
            "total": lambda: (pipeline.restart(), pipeline.window(step)),
        }
        window = {
            name: measure(func, sizes.repeats, warmup=10, inner=sizes.inner)
            for name, func in fast.items()
        }
        episode = measure(pipeline.episode, 3 * sizes.repeats, warmup=10, inner=1)  # short samples
        naive = measure_interleaved(
            {
                "edf_pybullet": lambda: naive_edf(step),
                "gp_resolve": theirs_gp,
                "policy_sb3_predict": naive_policy,
                "policy_torch_actor": pipeline.policy_torch,
            },
            sizes.naive_repeats,
        )
        naive_total = measure(naive_episode, max(2, sizes.naive_repeats // 2), warmup=1, inner=1)
        # Same-run ratios EDF vs PyBullet with interleaved samples (the headline comparison).
        paired = measure_interleaved(
            {"edf": lambda: pipeline.edf(step), "pybullet": lambda: naive_edf(step)},
            sizes.naive_repeats,
        )
        state_read = measure(
            lambda: env.sim.obstacle_shapes(), sizes.repeats, warmup=5, inner=sizes.inner
        )
    finally:
        bullet.close()
        pipeline.restart()

    # The environment's own per-window timer over real episodes (includes the obstacle read
    # from PyBullet, the r_ga EDF query and the blend; excludes policy and tool points).
    policy = deterministic_policy(model)
    tcs = env.spec_task.evaluation_tcs(sizes.in_env_episodes)
    rows = [run_episode(env, tc, policy) for tc in tcs]
    in_env_window = [r[f"adaptation_ms_w{k}"] / 1e3 for r in rows for k in (1, 2, 3)]
    in_env_episode = [
        sum(r[f"adaptation_ms_w{k}"] for k in (1, 2, 3)) / 1e3 + r["policy_ms"] / 1e3 for r in rows
    ]

    n_windows = pipeline.layout.n_steps
    ms = episode.median_us / 1e3
    return {
        "task": env.task_name,
        "method": env.method.name,
        "n_windows": n_windows,
        "points_queried": int(len(points)),
        "policy_numpy_vs_torch_max_abs_difference": float(
            np.max(np.abs(pipeline.policy() - pipeline.policy_torch()))
        ),
        "observation_size": int(pipeline.state.shape[0]),
        "action_size": int(env.action_space.shape[0]),
        "per_window": {name: t.to_dict() for name, t in window.items()},
        "per_episode": episode.to_dict(),
        "paper_ms_per_window": {**PAPER_MS_PER_WINDOW, "total": sum(PAPER_MS_PER_WINDOW.values())},
        "paper_ms_per_episode": PAPER_MS_PER_EPISODE,
        "naive_per_window": {name: t.to_dict() for name, t in naive.items()},
        "naive_per_episode": naive_total.to_dict(),
        "edf_vs_pybullet_interleaved": {name: t.to_dict() for name, t in paired.items()},
        "edf_pybullet_max_abs_difference_m": agreement,
        "obstacle_state_read": state_read.to_dict(),
        "in_env_per_window": Timing.from_samples(in_env_window).to_dict(),
        "in_env_per_episode_with_sb3_predict": Timing.from_samples(in_env_episode).to_dict(),
        "speedup": {
            "episode_vs_paper": PAPER_MS_PER_EPISODE / ms,
            "episode_vs_naive": naive_total.median_us / episode.median_us,
            "edf_vs_pybullet": paired["pybullet"].median_us / paired["edf"].median_us,
            "gp_vs_resolve": naive["gp_resolve"].median_us / window["gp_conditioning"].median_us,
        },
        "target_ms_per_episode": TARGET_MS_PER_EPISODE,
        "meets_target": bool(ms <= TARGET_MS_PER_EPISODE),
    }


def bench_simulation(task: str, episodes: int) -> dict[str, Any]:
    """Section 2: one full simulated episode (the TC-conditioned demonstration, executed in
    three segments as the RL env does) and the reset, on the task's evaluation TCs."""
    from distgprl.sim.tasks import get_task
    from distgprl.sim.tasks.base import condition_by_translation, resample_to_control
    from distgprl.skill.demos import load_demonstration

    spec = get_task(task)
    demo = load_demonstration(spec.demo_path)
    sim = spec.make_sim()
    try:
        tcs = spec.evaluation_tcs(episodes)
        trajectories = [
            resample_to_control(
                demo.times,
                condition_by_translation(
                    demo.times, demo.poses, np.asarray(tc.object_offset), spec.interaction_time
                ),
                sim.control_dt,
            )
            for tc in tcs
        ]
        sim.reset(tcs[0])
        sim.execute(trajectories[0])  # warm-up
        episode_s, reset_s = [], []
        for tc, poses in zip(tcs, trajectories, strict=True):
            start = time.perf_counter()
            sim.reset(tc)
            middle = time.perf_counter()
            for chunk in np.array_split(poses, 3):
                sim.execute(chunk)
            episode_s.append(time.perf_counter() - middle)
            reset_s.append(middle - start)
        steps = int(trajectories[0].shape[0])
        substeps = sim.physics.substeps
        control_dt = sim.control_dt
    finally:
        sim.close()
    episode = Timing.from_samples(episode_s)
    return {
        "episode": episode.to_dict(),
        "reset": Timing.from_samples(reset_s).to_dict(),
        "control_steps": steps,
        "physics_steps": steps * substeps,
        "per_control_step_us": episode.median_us / steps,
        "real_time_factor": steps * control_dt / (episode.median_us / 1e6),
    }


def _fill_replay_buffer(model, env, n: int, seed: int = 0) -> None:
    """``n`` synthetic transitions with the env's observation layout (finite, realistic aux)."""
    rng = np.random.default_rng(seed)
    n_via, n_steps = env.skill.n_via_points, env.layout.n_steps
    state_dim = env.observation_space["state"].shape[0]
    action_dim = env.action_space.shape[0]
    env.reset(seed=seed)
    # Methods with the HAP prior: the moving obstacles' anchors of a real episode start.
    anchors = env.moving_obstacle_anchors().ravel() if env.method.hap_prior else np.zeros(0)
    for i in range(n):
        one_hot = np.zeros(n_steps)
        one_hot[i % n_steps] = 1.0
        via_points = env.skill.via_points + rng.normal(0, 0.02, (n_via, 6))
        obs = {
            "state": rng.normal(size=(1, state_dim)).astype(np.float32),
            "aux": np.concatenate([via_points.ravel(), one_hot, anchors])[None].astype(np.float32),
        }
        action = rng.uniform(-1, 1, (1, action_dim)).astype(np.float32)
        model.replay_buffer.add(obs, obs, action, rng.normal(size=1), np.zeros(1), [{}])


def bench_sac_step(env, model, repeats: int) -> dict[str, Any]:
    """Section 3: one gradient step (batch 256, paper network), regularised vs plain SAC.

    Same model and buffer; "plain" only drops the regulariser from the actor loss. Timed
    twice, samples interleaved each time: wall time (``regularised``, ``plain``) and process
    CPU time (``cpu_regularised``, ``cpu_plain``); ``cpu_regularised_over_plain``, the ratio
    of the CPU-time medians, is the headline ``ratios.regularised_over_plain_sac_step``.
    """
    import torch
    from stable_baselines3.common.logger import configure

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as `train_run` (RunConfig.torch_threads)
    try:
        model.set_logger(configure(None, []))
        _fill_replay_buffer(model, env, 2048)
        regulariser = model.regulariser
        batch = model.batch_size

        def regularised() -> None:
            model.regulariser = regulariser
            model.train(gradient_steps=1, batch_size=batch)

        def plain() -> None:
            model.regulariser = None
            model.train(gradient_steps=1, batch_size=batch)

        steps = {"regularised": regularised, "plain": plain}
        timings = measure_interleaved(steps, repeats)
        cpu = measure_interleaved(steps, repeats, clock=time.process_time)
        model.regulariser = regulariser
    finally:
        torch.set_num_threads(threads)
    return {
        "batch_size": batch,
        "net_arch": list(model.policy_kwargs.get("net_arch", [])),
        "torch_threads": 1,
        "regularised": timings["regularised"].to_dict(),
        "plain": timings["plain"].to_dict(),
        "regularised_over_plain": timings["regularised"].median_us / timings["plain"].median_us,
        "cpu_regularised": cpu["regularised"].to_dict(),
        "cpu_plain": cpu["plain"].to_dict(),
        "cpu_regularised_over_plain": cpu["regularised"].median_us / cpu["plain"].median_us,
    }


class SectionTimers:
    """Inclusive wall time and call counts of wrapped instance methods (cheap: ~0.3 us/call)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}

    def wrap(self, owner: object, attribute: str, name: str) -> None:
        """Replace ``owner.attribute`` (a callable) by a timed wrapper adding into ``name``."""
        original = getattr(owner, attribute)
        self.seconds.setdefault(name, 0.0)
        self.calls.setdefault(name, 0)
        seconds, calls, clock = self.seconds, self.calls, time.perf_counter

        def timed(*args: Any, **kwargs: Any) -> Any:
            start = clock()
            try:
                return original(*args, **kwargs)
            finally:
                seconds[name] += clock() - start
                calls[name] += 1

        setattr(owner, attribute, timed)


def _instrument(env, model) -> SectionTimers:
    """Timers around the pieces of a training step (see `training_breakdown`)."""
    timers = SectionTimers()
    sim = env.sim
    timers.wrap(env, "step", "env_step")
    timers.wrap(sim, "execute", "sim_execute")
    timers.wrap(sim, "_step_simulation", "physics_step")
    timers.wrap(sim, "_contact_points", "contact_query")
    timers.wrap(sim, "clearance", "clearance_query")
    timers.wrap(sim, "_move_kinematic", "kinematic_obstacles")
    timers.wrap(sim.robot, "command", "joint_commands")
    timers.wrap(sim.robot, "ik_nearest", "ik")
    for attribute in ("distance", "update", "clearance"):
        timers.wrap(env.field, attribute, "edf")
    for attribute in ("obstacle_shapes", "tool_points", "tcp_pose", "object_position"):
        timers.wrap(sim, attribute, "state_reads")
    timers.wrap(model, "train", "sac_update")
    if model.regulariser is not None:
        timers.wrap(model, "regulariser", "regulariser_forward")
    timers.wrap(model, "_sample_action", "action_sampling")
    return timers


def training_breakdown(timers: SectionTimers, wall: float, steps: int) -> dict[str, Any]:
    """Exclusive time per piece (ms per training step and fraction of the wall time)."""
    s = timers.seconds
    sim_children = ("physics_step", "contact_query", "clearance_query", "kinematic_obstacles")
    sim_children += ("joint_commands", "ik")
    parts = {
        "simulation: physics (stepSimulation)": s["physics_step"],
        "simulation: contact checks (getContactPoints)": s["contact_query"],
        "simulation: clearance (getClosestPoints)": s["clearance_query"],
        "simulation: kinematic obstacles + joint commands": s["kinematic_obstacles"]
        + s["joint_commands"],
        "simulation: loop overhead (execute, Python)": s["sim_execute"]
        - sum(s[k] for k in sim_children),
        "IK (analytic, nearest branch)": s["ik"],
        "EDF (update + queries, r_sd, r_ga, observation)": s["edf"],
        "simulator state reads (poses, tool points)": s["state_reads"],
        "env step: rest (GP, rewards, observation)": s["env_step"]
        - s["sim_execute"]
        - s["edf"]
        - s["state_reads"],
        "SAC update: regulariser forward (L_sim + L_hap)": s.get("regulariser_forward", 0.0),
        "SAC update: rest (critic/actor forward, backward, Adam)": s["sac_update"]
        - s.get("regulariser_forward", 0.0),
        "action sampling (actor forward)": s["action_sampling"],
        "SB3 loop, replay buffer, other": wall
        - s["env_step"]
        - s["sac_update"]
        - s["action_sampling"],
    }
    return {
        name: {"ms_per_step": 1e3 * value / steps, "fraction": value / wall}
        for name, value in parts.items()
    }


def bench_training(sizes: BenchSizes, task: str = BENCH_TASK) -> dict[str, Any]:
    """Section 4: steps per second of a short real training run and where the time goes."""
    import torch

    from distgprl.experiments.runner import make_agent, make_env

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        run = _run_spec(task, sac_overrides={"learning_starts": sizes.learning_starts})
        env = make_env(run)
        model = make_agent(env, run)
        env.reset(seed=0)
        model.learn(total_timesteps=sizes.learning_starts + 3, progress_bar=False)
        timers = _instrument(env, model)
        start = time.perf_counter()
        model.learn(
            total_timesteps=sizes.training_steps, reset_num_timesteps=False, progress_bar=False
        )
        wall = time.perf_counter() - start
        env.close()
    finally:
        torch.set_num_threads(threads)
    return {
        "task": task,
        "method": BENCH_METHOD,
        "steps": sizes.training_steps,
        "wall_s": wall,
        "steps_per_s": sizes.training_steps / wall,
        "breakdown": training_breakdown(timers, wall, sizes.training_steps),
        "calls_per_step": {k: v / sizes.training_steps for k, v in timers.calls.items()},
    }


WORKER_READY = "DISTGPRL-BENCH-READY"
WORKER_RATE = "DISTGPRL-BENCH-RATE"


def training_worker(task: str, learning_starts: int, steps: int) -> None:
    """One independent short training (run in its own process by `bench_workers`).

    Sets up, runs the untimed random-action phase, prints `WORKER_READY`, waits for a line on
    stdin (the start signal, so that concurrent workers overlap), then prints `WORKER_RATE`
    and its timed steps per second.
    """
    import sys

    import torch

    from distgprl.experiments.runner import make_agent, make_env

    torch.set_num_threads(1)
    run = _run_spec(task, sac_overrides={"learning_starts": learning_starts})
    env = make_env(run)
    model = make_agent(env, run)
    env.reset(seed=0)
    model.learn(total_timesteps=learning_starts + 3, progress_bar=False)
    print(WORKER_READY, flush=True)
    sys.stdin.readline()
    start = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False, progress_bar=False)
    print(f"{WORKER_RATE} {steps / (time.perf_counter() - start)!r}", flush=True)
    env.close()


def _read_marker(process: subprocess.Popen, marker: str) -> str:
    """The rest of the first stdout line of ``process`` that starts with ``marker``."""
    assert process.stdout is not None
    for line in process.stdout:
        if line.startswith(marker):
            return line[len(marker) :].strip()
    raise RuntimeError(f"benchmark worker exited (code {process.wait()}) before {marker}")


def bench_workers(sizes: BenchSizes, single: float, task: str = BENCH_TASK) -> list[dict[str, Any]]:
    """Section 5c: aggregate training throughput of independent training processes.

    One process is the in-process run of `bench_training` (``single`` steps/s, same code path);
    for N >= 2, N fresh Python processes set up, wait until all are ready, then train
    ``sizes.worker_steps`` steps at the same time; their rates are summed.
    """
    out = [{"workers": 1, "steps_per_s_each": [single], "aggregate_steps_per_s": single}]
    for count in (c for c in sizes.workers if c > 1):
        command = [sys.executable, "-m", "distgprl.experiments.bench", "--worker", task]
        command += [str(sizes.learning_starts), str(sizes.worker_steps)]
        with tempfile.TemporaryFile("w+") as errors:
            processes = [
                subprocess.Popen(
                    command,
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    stderr=errors,
                    text=True,
                )
                for _ in range(count)
            ]
            try:
                for process in processes:
                    _read_marker(process, WORKER_READY)
                for process in processes:
                    assert process.stdin is not None
                    process.stdin.write("go\n")
                    process.stdin.flush()
                rates = [float(_read_marker(process, WORKER_RATE)) for process in processes]
                for process in processes:
                    process.wait(timeout=120)
            except BaseException as exc:
                for process in processes:
                    process.kill()
                errors.seek(0)
                raise RuntimeError(f"{exc}; worker stderr tail:\n{errors.read()[-2000:]}") from exc
        out.append(
            {
                "workers": count,
                "steps_per_s_each": rates,
                "aggregate_steps_per_s": float(sum(rates)),
            }
        )
    for row in out:
        row["speedup_vs_one"] = row["aggregate_steps_per_s"] / single
    return out


def _scaled_skill(skill, n_via_points: int):
    """The task skill re-expressed with ``n_via_points`` evenly spaced via-points.

    Same fitted kernel; the via-points are the skill's own trajectory at the new times (what
    `fit_skill` gives up to the fit, without its seconds of marginal-likelihood optimisation).
    """
    from distgprl.skill.gp import GPSkill

    times = np.linspace(0.0, 1.0, n_via_points)
    via_points = skill.position(skill.via_points, times)
    via_points[0], via_points[-1] = skill.via_points[0], skill.via_points[-1]
    return GPSkill(
        skill.kernel,
        times,
        via_points,
        skill.prior_mean.copy(),
        skill.duration,
        skill.name,
        axis_scale=skill.axis_scale,
    )


def bench_via_point_scaling(sizes: BenchSizes, task: str = BENCH_TASK) -> list[dict[str, Any]]:
    """Section 5a: per-episode adaptation compute vs N via-points (3 windows of L = N // 3).

    Windows keep covering the interior, so the action (6 L) and observation sizes grow with N.
    """
    from distgprl.envs.adaptation import AdaptationEnv
    from distgprl.envs.tasks import load_task_skill
    from distgprl.experiments.runner import make_agent

    base = load_task_skill(task)
    rows = []
    for n in sizes.via_points:
        overrides = {"n_via_points": n, "window_size": n // 3}
        run = _run_spec(task, env_overrides=overrides)
        env = AdaptationEnv(task, run.method, run.config.env, skill=_scaled_skill(base, n))
        try:
            model = make_agent(env, run)
            env.reset(seed=0)
            pipeline = AdaptationPipeline(env, model.actor)
            step, action = 1, pipeline.actions[1]

            def gp(pipeline=pipeline, step=step, action=action) -> None:
                pipeline.restart()
                pipeline.gp_conditioning(step, action)

            timings = {
                "episode": measure(pipeline.episode, 3 * sizes.scaling_repeats, 3, 1),
                "edf_window": measure(lambda p=pipeline: p.edf(1), sizes.scaling_repeats, 3),
                "gp_window": measure(gp, sizes.scaling_repeats, 3, sizes.inner),
                "policy_window": measure(pipeline.policy, sizes.scaling_repeats, 3, sizes.inner),
            }
            rows.append(
                {
                    "n_via_points": n,
                    "window_size": n // 3,
                    "action_size": int(env.action_space.shape[0]),
                    "segment_samples": int(len(env.segment_tau(1))),
                    **{name: t.to_dict() for name, t in timings.items()},
                }
            )
        finally:
            env.close()
    return rows


def random_boxes(count: int, seed: int = 0) -> list:
    """``count`` axis-aligned and rotated boxes spread over the workspace (EDF primitives)."""
    from scipy.spatial.transform import Rotation

    from distgprl.safety.shapes import Box

    rng = np.random.default_rng(seed)
    return [
        Box(
            f"box{i}",
            rng.uniform([0.2, -0.5, 0.02], [0.8, 0.5, 0.5]),
            Rotation.from_euler("z", rng.uniform(0, np.pi)).as_matrix(),
            rng.uniform(0.01, 0.06, 3),
            True,
        )
        for i in range(count)
    ]


def bench_obstacle_scaling(env, model, sizes: BenchSizes) -> list[dict[str, Any]]:
    """Section 5b: per-episode adaptation compute and the EDF query vs number of boxes, with
    PyBullet closest points on the same points and boxes."""
    from distgprl.safety.edf import DistanceField

    rows = []
    for count in sizes.obstacles:
        shapes = random_boxes(count)
        field = DistanceField(shapes)
        pipeline = AdaptationPipeline(env, model.actor, field=field, shapes=shapes)
        bullet = BulletDistance(shapes)
        try:
            points = np.concatenate(
                (env.gamma[pipeline.layout.indices[1], :3], pipeline.tool_points)
            )
            paired = measure_interleaved(
                {
                    "edf": lambda p=pipeline: p.edf(1),
                    "pybullet": lambda b=bullet, x=points: b.distance(x),
                },
                sizes.scaling_repeats,
            )
            episode = measure(pipeline.episode, 3 * sizes.scaling_repeats, 3, 1)
        finally:
            bullet.close()
            pipeline.restart()
        rows.append(
            {
                "n_obstacles": count,
                "episode": episode.to_dict(),
                "edf_window": paired["edf"].to_dict(),
                "pybullet_window": paired["pybullet"].to_dict(),
                "edf_vs_pybullet": paired["pybullet"].median_us / paired["edf"].median_us,
            }
        )
    return rows


# ------------------------------------------------------------------------------ reporting
def _fmt_ms(timing: dict[str, float], digits: int = 3) -> str:
    return (
        f"{timing['median_us'] / 1e3:.{digits}f} "
        f"({timing['p10_us'] / 1e3:.{digits}f}–{timing['p90_us'] / 1e3:.{digits}f})"
    )


def markdown_table(document: dict[str, Any]) -> str:
    """The benchmark results as Markdown tables (for the README), from a `run_benchmarks` JSON.

    Times are medians with the 10th–90th percentile range in parentheses, in ms.
    """
    a = document["adaptation"]
    machine = document["machine"]
    load = machine["load_average"]
    lines = [
        f"Machine: {machine['cpu']}, {machine['cores']} cores; 1-min load average "
        f"{load[0]:.2f} at start, {document['load_average_after'][0]:.2f} at end "
        f"({'quick' if document['quick'] else 'full'} run).",
        "",
        "| Adaptation compute (ms) | this package | paper (i7-1185G7) | naive, same run |",
        "|---|---|---|---|",
    ]
    naive_names = {
        "edf": ("edf_pybullet", "PyBullet getClosestPoints"),
        "gp_conditioning": ("gp_resolve", "GP re-solved"),
        "policy": ("policy_sb3_predict", "SB3 predict"),
    }
    labels = {
        "edf": f"EDF query ({a['points_queried']} points), per window",
        "gp_conditioning": "GP conditioning (S_W update + segment), per window",
        "policy": f"policy (SAC actor in NumPy, {a['observation_size']}-D obs), per window",
        "total": "total, per window",
    }
    for name, label in labels.items():
        naive = ""
        if name in naive_names:
            key, what = naive_names[name]
            naive = f"{_fmt_ms(a['naive_per_window'][key])} {what}"
            if name == "policy":
                naive += f"; {_fmt_ms(a['naive_per_window']['policy_torch_actor'])} torch actor"
        lines.append(
            f"| {label} | {_fmt_ms(a['per_window'][name])} | "
            f"{a['paper_ms_per_window'][name]:g} | {naive} |"
        )
    lines.append(
        f"| **total, per episode ({a['n_windows']} windows)** | **{_fmt_ms(a['per_episode'])}** | "
        f"{a['paper_ms_per_episode']:g} | {_fmt_ms(a['naive_per_episode'], 2)} |"
    )
    s = a["speedup"]
    lines += [
        "",
        f"Per episode: {s['episode_vs_paper']:.0f}× faster than the paper's figure, "
        f"{s['episode_vs_naive']:.0f}× faster than the naive pipeline; EDF "
        f"{s['edf_vs_pybullet']:.0f}× faster than PyBullet on the same points (interleaved, "
        f"max |difference| {a['edf_pybullet_max_abs_difference_m'] * 1e3:.3f} mm); GP conditioning "
        f"{s['gp_vs_resolve']:.0f}× faster than re-solving. Target ≤ "
        f"{a['target_ms_per_episode']:g} ms per episode: "
        f"{'met' if a['meets_target'] else 'NOT met'}. The environment's own timer (includes the "
        f"obstacle read from PyBullet) gives {_fmt_ms(a['in_env_per_window'])} ms per window.",
        "",
        "| Other | median (p10–p90) |",
        "|---|---|",
    ]
    for task, sim in document["simulation"].items():
        lines.append(
            f"| simulated episode, {task} ({sim['control_steps']} control steps, "
            f"{sim['physics_steps']} physics steps), ms | {_fmt_ms(sim['episode'], 1)} |"
        )
    sac = document["sac_step"]
    lines.append(
        f"| SAC gradient step, regularised actor loss (batch {sac['batch_size']}), ms | "
        f"{_fmt_ms(sac['regularised'], 2)} |"
    )
    lines.append(
        f"| SAC gradient step, plain SAC, ms | {_fmt_ms(sac['plain'], 2)} "
        f"(regularised / plain = {sac['regularised_over_plain']:.2f}) |"
    )
    if "cpu_regularised" in sac:  # not in benchmark files written before it was measured
        lines.append(
            f"| SAC gradient step, process CPU time, regularised / plain, ms | "
            f"{_fmt_ms(sac['cpu_regularised'], 2)} / {_fmt_ms(sac['cpu_plain'], 2)} "
            f"(ratio {sac['cpu_regularised_over_plain']:.2f}) |"
        )
    training = document["training"]
    lines.append(
        f"| training throughput ({training['task']}/{training['method']}, 1 process), steps/s | "
        f"{training['steps_per_s']:.1f} |"
    )
    for row in document["scaling"]["workers"]:
        lines.append(
            f"| training throughput, {row['workers']} independent process(es), aggregate steps/s "
            f"| {row['aggregate_steps_per_s']:.1f} |"
        )
    lines += ["", "| Where a training step's time goes | ms/step | share |", "|---|---|---|"]
    for name, part in sorted(training["breakdown"].items(), key=lambda kv: -kv[1]["fraction"]):
        lines.append(f"| {name} | {part['ms_per_step']:.2f} | {100 * part['fraction']:.0f}% |")
    return "\n".join(lines) + "\n"


def plot_results(document: dict[str, Any], path: Path) -> Path:
    """A 2x2 figure: per-window components vs paper and naive; via-point and obstacle scaling;
    training-time breakdown. Written as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    a = document["adaptation"]
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    names = ["edf", "gp_conditioning", "policy"]
    ours = [a["per_window"][n]["median_us"] / 1e3 for n in names]
    paper = [a["paper_ms_per_window"][n] for n in names]
    naive = [
        a["naive_per_window"][k]["median_us"] / 1e3
        for k in ("edf_pybullet", "gp_resolve", "policy_sb3_predict")
    ]
    x = np.arange(len(names))
    ax = axes[0, 0]
    ax.bar(x - 0.27, ours, 0.27, label="this package")
    ax.bar(x, naive, 0.27, label="naive (same run)")
    ax.bar(x + 0.27, paper, 0.27, label="paper (i7-1185G7)")
    ax.set_xticks(x, ["EDF query", "GP conditioning", "policy"])
    ax.set_yscale("log")
    ax.set_ylabel("ms per window (median)")
    ax.set_title("Adaptation compute per window")
    ax.legend(fontsize=8)

    ax = axes[0, 1]
    rows = document["scaling"]["via_points"]
    n = [r["n_via_points"] for r in rows]
    for key, label in (
        ("episode", "per episode"),
        ("edf_window", "EDF / window"),
        ("gp_window", "GP / window"),
        ("policy_window", "policy / window"),
    ):
        ax.plot(n, [r[key]["median_us"] / 1e3 for r in rows], "o-", label=label)
    ax.set_xlabel("via-points N (windows of N // 3)")
    ax.set_ylabel("ms (median)")
    ax.set_title("Adaptation compute vs via-points")
    ax.legend(fontsize=8)

    ax = axes[1, 0]
    rows = document["scaling"]["obstacles"]
    k = [r["n_obstacles"] for r in rows]
    for key, label in (
        ("episode", "adaptation per episode"),
        ("edf_window", "EDF query / window"),
        ("pybullet_window", "PyBullet closest points / window"),
    ):
        ax.plot(k, [r[key]["median_us"] / 1e3 for r in rows], "o-", label=label)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("obstacles (boxes)")
    ax.set_ylabel("ms (median)")
    ax.set_title("Adaptation compute vs obstacles")
    ax.legend(fontsize=8)

    ax = axes[1, 1]
    breakdown = sorted(document["training"]["breakdown"].items(), key=lambda kv: kv[1]["fraction"])
    ax.barh([name for name, _ in breakdown], [p["ms_per_step"] for _, p in breakdown])
    ax.tick_params(axis="y", labelsize=7)
    ax.set_xlabel("ms per training step")
    ax.set_title(f"Training step ({document['training']['steps_per_s']:.1f} steps/s)")
    load = document["machine"]["load_average"][0]
    fig.suptitle(f"distgprl bench — {document['machine']['cpu']}, load {load:.1f}", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run_benchmarks(
    quick: bool,
    out_dir: Path = Path("results/bench"),
    sizes: BenchSizes | None = None,
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Run every benchmark section; write ``bench_<quick|full>.json`` and ``.png`` in ``out_dir``.

    Args:
        quick: the ~1 minute version (fewer repeats, smaller sweeps) instead of ~10 minutes.
        out_dir: output folder (created).
        sizes: explicit sizes (overrides ``quick``; the tests use `TINY_SIZES`).
        progress: called with a short message before each section (e.g. ``print``).

    Returns:
        The path of the JSON written with `distgprl.experiments.results.write_json`.
    """
    import torch

    from distgprl.experiments.results import write_json
    from distgprl.experiments.runner import make_agent, make_env

    sizes = sizes or (QUICK_SIZES if quick else FULL_SIZES)
    say = progress or (lambda message: None)
    started = time.perf_counter()
    machine = machine_info()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # policy inference and SAC steps as in training (1 thread)
    try:
        say("adaptation compute (EDF, GP conditioning, policy) vs paper and naive")
        run = _run_spec()
        env = make_env(run)
        model = make_agent(env, run)
        env.reset(seed=0)
        adaptation = bench_adaptation(env, model, sizes)
        say("adaptation vs obstacles")
        env.reset(seed=0)
        obstacles = bench_obstacle_scaling(env, model, sizes)
        say("SAC gradient step")
        sac_step = bench_sac_step(env, model, sizes.sac_repeats)
        env.close()
        say("adaptation vs via-points")
        via_points = bench_via_point_scaling(sizes)
    finally:
        torch.set_num_threads(threads)
    say("simulated episodes")
    simulation = {task: bench_simulation(task, sizes.sim_episodes) for task in sizes.tasks}
    say("training throughput and breakdown")
    training = bench_training(sizes)
    say("training throughput vs workers")
    workers = bench_workers(sizes, training["steps_per_s"])
    document = {
        "quick": bool(quick),
        "sizes": asdict(sizes),
        "machine": machine,
        "load_average_after": list(os.getloadavg()),
        "wall_time_s": time.perf_counter() - started,
        "adaptation": adaptation,
        "simulation": simulation,
        "sac_step": sac_step,
        "ratios": {
            # Process CPU time of a regularised (dist-gprl, DCP) over a plain SAC step.
            "regularised_over_plain_sac_step": sac_step["cpu_regularised_over_plain"],
        },
        "training": training,
        "scaling": {"via_points": via_points, "obstacles": obstacles, "workers": workers},
    }
    out_dir = Path(out_dir)
    name = "bench_quick" if quick else "bench_full"
    path = write_json(out_dir / f"{name}.json", document, kind="bench")
    plot_results(document, out_dir / f"{name}.png")
    return path


def load_results(path: Path) -> dict[str, Any]:
    """Read a benchmark JSON (schema-checked)."""
    from distgprl.experiments.results import read_json

    return read_json(path)


def main(argv: list[str] | None = None) -> None:
    """``python -m distgprl.experiments.bench [--quick] [--out DIR]``: run and print the table.

    ``--worker TASK LEARNING_STARTS STEPS`` is the internal entry of `bench_workers`.
    """
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="~1 minute instead of ~10")
    parser.add_argument("--out", type=Path, default=Path("results/bench"))
    parser.add_argument("--worker", nargs=3, metavar=("TASK", "LEARNING_STARTS", "STEPS"))
    args = parser.parse_args(argv)
    if args.worker:
        task, learning_starts, steps = args.worker
        training_worker(task, int(learning_starts), int(steps))
        return
    start = time.perf_counter()
    path = run_benchmarks(
        args.quick,
        args.out,
        progress=lambda m: print(f"[bench {time.perf_counter() - start:5.1f} s] {m}", flush=True),
    )
    print(markdown_table(load_results(path)))
    print(f"wrote {path} and {path.with_suffix('.png')}")


if __name__ == "__main__":
    main()


__all__ = [
    "FULL_SIZES",
    "QUICK_SIZES",
    "TINY_SIZES",
    "AdaptationPipeline",
    "BenchSizes",
    "BulletDistance",
    "NumpyActor",
    "SectionTimers",
    "Timing",
    "bench_gp",
    "markdown_table",
    "measure",
    "measure_interleaved",
    "run_benchmarks",
]
