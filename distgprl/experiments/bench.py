"""Micro-benchmarks (`distgprl bench`): medians with warm-up and repeats.

Each ``bench_*`` function returns a dict of named `Timing` results; later issues add
their own sections (EDF, simulation, SAC step) to the same report.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Timing:
    """Wall-time statistics of one operation, in microseconds."""

    median_us: float
    p10_us: float
    p90_us: float
    repeats: int

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


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
