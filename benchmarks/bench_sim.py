"""Wall time of one full simulated episode per task: `python benchmarks/bench_sim.py`.

The TC-conditioned demonstration is executed in three segments, as the RL env does, with
dynamics and contact/clearance checks; medians over the evaluation TCs. (`distgprl bench`
measures the environment's step against the bare physics inside it, section 2b.)
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from distgprl.data import TASK_NAMES
from distgprl.experiments.bench.timing import Timing


def bench_simulation(task: str, episodes: int) -> dict[str, Any]:
    """One full simulated episode (the TC-conditioned demonstration, executed in three
    segments as the RL env does) and the reset, on the task's first ``episodes`` evaluation
    TCs."""
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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args(argv)
    for name in TASK_NAMES:
        result = bench_simulation(name, args.episodes)
        episode = result["episode"]
        print(
            f"{name}: episode ({result['control_steps']} control steps) median "
            f"{episode['median_us'] / 1000:.1f} ms [p10 {episode['p10_us'] / 1000:.1f}, "
            f"p90 {episode['p90_us'] / 1000:.1f}]; reset median "
            f"{result['reset']['median_us'] / 1000:.2f} ms"
        )


if __name__ == "__main__":
    main()
