"""Wall time of one full simulated episode per task (the whole demonstration, with dynamics,
contact and clearance checks), median and spread over 20 episodes on evaluation TCs.

Run: ``python benchmarks/bench_sim.py [--episodes 20]``. Reset time is reported separately.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from distgprl.sim.tasks import get_task
from distgprl.sim.tasks.base import condition_by_translation, resample_to_control
from distgprl.skill.demos import load_demonstration


def bench(task_name: str, episodes: int) -> tuple[np.ndarray, np.ndarray, int]:
    spec = get_task(task_name)
    demo = load_demonstration(spec.demo_path)
    sim = spec.make_sim()
    episode_times, reset_times = [], []
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
        for tc, poses in zip(tcs, trajectories, strict=True):
            start = time.perf_counter()
            sim.reset(tc)
            middle = time.perf_counter()
            for chunk in np.array_split(poses, 3):  # as the RL env does: 3 segments
                sim.execute(chunk)
            end = time.perf_counter()
            reset_times.append(middle - start)
            episode_times.append(end - middle)
        steps = trajectories[0].shape[0]
    finally:
        sim.close()
    return np.array(episode_times), np.array(reset_times), steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args()
    for name in ("dcp", "dbm"):
        episode, reset, steps = bench(name, args.episodes)
        q25, median, q75 = np.percentile(episode * 1000, [25, 50, 75])
        print(
            f"{name}: episode ({steps} control steps) median {median:.1f} ms "
            f"[IQR {q25:.1f}-{q75:.1f}, min {episode.min() * 1000:.1f}, "
            f"max {episode.max() * 1000:.1f}] ms; reset median {np.median(reset) * 1000:.2f} ms"
        )


if __name__ == "__main__":
    main()
