"""Section 3: one SAC gradient step, regularised vs plain, on a replay buffer of synthetic
transitions with the environment's observation layout."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from distgprl.experiments.bench.timing import measure_interleaved

__all__ = ["bench_sac_step", "fill_replay_buffer"]


def fill_replay_buffer(model, env, n: int, seed: int = 0) -> None:
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
        fill_replay_buffer(model, env, 2048)
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
