"""``benchmarks/bench_sim.py`` and ``benchmarks/bench_gp.py`` at one episode / a few queries:
their results have the fields the scripts print, every timing positive."""

from __future__ import annotations

from _scripts import load_script


def test_one_simulated_episode_is_timed_with_its_step_counts():
    script = load_script("bench_sim", "benchmarks")
    result = script.bench_simulation("dcp", 1)
    assert result["episode"]["median_us"] > 0 and result["reset"]["median_us"] > 0
    assert result["physics_steps"] % result["control_steps"] == 0  # whole substeps
    assert result["real_time_factor"] > 0


def test_the_gp_benchmark_times_evaluation_update_and_the_naive_resolve():
    script = load_script("bench_gp", "benchmarks")
    timings = script.bench_gp(n_query=20)
    assert set(timings) == {"trajectory_eval", "window_update", "naive_gp_resolve"}
    assert all(timing.median_us > 0 for timing in timings.values())
