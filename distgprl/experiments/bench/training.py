"""Sections 3 and 4: one SAC gradient step (regularised vs plain) and the throughput of a
short real training run with where its time goes."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from distgprl.experiments.bench.sizes import BENCH_METHOD, BENCH_TASK, BenchSizes, run_spec
from distgprl.experiments.bench.timing import SectionTimers, measure_interleaved

__all__ = ["bench_sac_step", "bench_training", "training_breakdown"]


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

        steps: dict[str, Callable[[], object]] = {"regularised": regularised, "plain": plain}
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


def _instrument(env, model) -> SectionTimers:
    """Timers around the pieces of a training step (see `training_breakdown`)."""
    timers = SectionTimers()
    sim = env.sim
    timers.wrap(env, "step", "env_step")
    timers.wrap(sim, "execute", "sim_execute")
    timers.wrap(sim.calls, "step_simulation", "physics_step")
    timers.wrap(sim.calls, "contact_points", "contact_query")
    timers.wrap(sim.control, "clearance", "clearance_query")
    # the control loop plans a segment's kinematic poses and conveyor path, then resets
    # the bodies per physics step (`ControlLoop.run`): both count as kinematic obstacles
    for attribute in ("kinematic_schedule", "convey_schedule"):
        timers.wrap(sim, attribute, "kinematic_obstacles")
    for attribute in ("reset_base_pose", "reset_base_velocity"):
        timers.wrap(sim.calls, attribute, "kinematic_obstacles")
    timers.wrap(sim.robot, "command", "joint_commands")
    timers.wrap(sim.robot, "ik_nearest", "ik")
    timers.wrap(sim.robot, "ik_segment", "ik")
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
    sim_children: tuple[str, ...] = (
        "physics_step",
        "contact_query",
        "clearance_query",
        "kinematic_obstacles",
    )
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
        run = run_spec(task, sac_overrides={"learning_starts": sizes.learning_starts})
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
