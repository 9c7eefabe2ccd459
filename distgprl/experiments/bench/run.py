"""`run_benchmarks`: every section in one process, one schema-versioned JSON and a figure."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

from distgprl.experiments.bench.adaptation import bench_adaptation
from distgprl.experiments.bench.environment import bench_env_step
from distgprl.experiments.bench.floor import bench_floor, sac_update_matrix_products
from distgprl.experiments.bench.plots import plot_results
from distgprl.experiments.bench.sac_update import bench_sac_step
from distgprl.experiments.bench.sizes import BenchSizes, run_spec, sizes_for
from distgprl.experiments.bench.suite import bench_suite
from distgprl.experiments.bench.timing import machine_info

__all__ = ["load_results", "run_benchmarks"]


def run_benchmarks(
    quick: bool,
    out_dir: Path = Path("results/bench"),
    sizes: BenchSizes | None = None,
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Run every benchmark section; write ``bench_<quick|full>.json`` and ``.png`` in ``out_dir``.

    Args:
        quick: the short version (`QUICK_SIZES`: fewer repeats and timed steps).
        out_dir: output folder (created).
        sizes: explicit sizes (overrides ``quick``; the tests use `TINY_SIZES`).
        progress: called with a short message before each section (e.g. ``print``).

    Returns:
        The path of the JSON written with `distgprl.schema.write_json`.
    """
    import torch

    from distgprl.experiments.factories import make_agent, make_env
    from distgprl.schema import write_json

    sizes = sizes or sizes_for(quick)
    say = progress or (lambda message: None)
    started = time.perf_counter()
    machine = machine_info()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # policy inference and SAC steps as in training (1 thread)
    try:
        say("adaptation compute (EDF, GP conditioning, policy) vs paper and naive")
        run = run_spec()
        env = make_env(run)
        model = make_agent(env, run)
        env.reset(seed=0)
        adaptation = bench_adaptation(env, model, sizes)
        say("SAC gradient step")
        sac_step = bench_sac_step(env, model, sizes.sac_repeats)
        say("matrix products of a plain SAC update (the suite's floor)")
        update_floor = sac_update_matrix_products(model, sizes.sac_repeats)
        env.close()
    finally:
        torch.set_num_threads(threads)
    say("environment step vs bare physics")
    environment = {task: bench_env_step(task, sizes.env_episodes) for task in sizes.tasks}
    say("suite cost: a training step of every method and task")
    suite = bench_suite(sizes)
    suite["floor"] = bench_floor(update_floor, environment, suite)
    document = {
        "quick": bool(quick),
        "sizes": asdict(sizes),
        "machine": machine,
        "load_average_after": list(os.getloadavg()),
        "wall_time_s": time.perf_counter() - started,
        "adaptation": adaptation,
        "environment": environment,
        "sac_step": sac_step,
        "ratios": {
            # Process CPU time of a regularised (dist-gprl, DCP) over a plain SAC step.
            "regularised_over_plain_sac_step": sac_step["cpu_regularised_over_plain"],
            # Process CPU time of an env step over the stepSimulation calls inside it.
            "env_step_over_bare_physics": {
                task: section["env_step_over_bare_physics"] for task, section in environment.items()
            },
            # The suite's measured CPU-hours over its floor's (section 4 over section 5).
            "suite_over_floor": suite["cpu_hours"] / suite["floor"]["cpu_hours"],
        },
        "suite": suite,
    }
    out_dir = Path(out_dir)
    name = "bench_quick" if quick else "bench_full"
    path = write_json(out_dir / f"{name}.json", document, kind="bench")
    plot_results(document, out_dir / f"{name}.png")
    return path


def load_results(path: Path) -> dict[str, Any]:
    """Read a benchmark JSON (schema-checked)."""
    from distgprl.schema import read_json

    return read_json(path)
