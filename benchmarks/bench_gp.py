"""GP skill benchmark: `python benchmarks/bench_gp.py` (medians in microseconds)."""

from __future__ import annotations

import numpy as np

from distgprl.experiments.bench.timing import Timing, measure


def bench_gp(n_query: int = 200, n_via_points: int = 15, seed: int = 0) -> dict[str, Timing]:
    """GP skill: trajectory evaluation at ``n_query`` times and one window update.

    Compared with the naive alternative (rebuilding the conditioning maps from the kernel,
    i.e. re-solving the GP, on every evaluation).
    """
    from distgprl.skill.gp import GPSkill
    from distgprl.skill.kernels import KernelParams

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


def main() -> None:
    for name, timing in bench_gp().items():
        print(
            f"{name:20s} median {timing.median_us:8.2f} us  (p10 {timing.p10_us:.2f}, "
            f"p90 {timing.p90_us:.2f})"
        )


if __name__ == "__main__":
    main()
