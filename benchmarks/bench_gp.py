"""GP skill benchmark: `python benchmarks/bench_gp.py` (medians in microseconds)."""

from distgprl.experiments.bench import bench_gp

if __name__ == "__main__":
    for name, timing in bench_gp().items():
        print(
            f"{name:20s} median {timing.median_us:8.2f} us  (p10 {timing.p10_us:.2f}, "
            f"p90 {timing.p90_us:.2f})"
        )
