"""Section 2: one simulated episode per task (full trajectory, dynamics, contact checks)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from distgprl.experiments.bench.timing import Timing

__all__ = ["bench_simulation"]


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
                    demo.times,
                    demo.poses,
                    np.asarray(tc.object_offset),
                    spec.interaction_time,
                    goal_fixed_in_world=spec.goal_fixed_in_world,
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
