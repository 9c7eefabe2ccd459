"""Wall time of one full simulated episode per task: `python benchmarks/bench_sim.py`.

The TC-conditioned demonstration is executed in three segments, as the RL env does, with
dynamics and contact/clearance checks; medians over the evaluation TCs. The measurement
itself is `distgprl.experiments.bench.bench_simulation` (section 2 of `distgprl bench`).
"""

import argparse

from distgprl.experiments.bench import bench_simulation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args()
    for name in ("dcp", "dbm"):
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
