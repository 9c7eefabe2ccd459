"""Section 4: the CPU cost of the whole paper suite, from measured per-step costs (issue 29).

Every trainable method of Table I on every task trains a few real steps (env step + one
gradient step, the paper preset, one torch thread) timed in process CPU time; the suite's
CPU-hours are the sum over methods, tasks and `distgprl.identity.SWEEP_SEEDS` of
``paper total_steps x seconds per step`` (`suite_cpu_hours`), and ``hours_two_idle_cores``
its wall time on two otherwise idle cores.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from distgprl.experiments.bench.sizes import BenchSizes, run_spec

__all__ = ["bench_suite", "suite_cpu_hours", "training_step_cpu_s"]

IDLE_CORES = 2
"""Cores of the machine the suite's wall time ``hours_two_idle_cores`` is given for."""


def suite_cpu_hours(
    cpu_s_per_step: Mapping[tuple[str, str], float],
    total_steps: Mapping[str, int],
    seeds: int,
) -> float:
    """CPU-hours of a suite: sum over (method, task) of seeds x steps x seconds per step.

    Args:
        cpu_s_per_step: process CPU seconds per training step, by (method, task).
        total_steps: RL steps per run, by task.
        seeds: runs per (method, task).
    """
    seconds = sum(seeds * total_steps[task] * cost for (_, task), cost in cpu_s_per_step.items())
    return seconds / 3600.0


def training_step_cpu_s(task: str, method: str, learning_starts: int, steps: int) -> float:
    """Process CPU seconds per training step (env step + one gradient step) of ``method`` on
    ``task`` (paper preset), over ``steps`` steps after ``learning_starts`` random ones."""
    import torch

    from distgprl.experiments.factories import make_agent, make_env

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        run = run_spec(task, method, sac_overrides={"learning_starts": learning_starts})
        env = make_env(run)
        try:
            model = make_agent(env, run)
            env.reset(seed=0)
            model.learn(total_timesteps=learning_starts + 3, progress_bar=False)
            start = time.process_time()
            model.learn(total_timesteps=steps, reset_num_timesteps=False, progress_bar=False)
            return (time.process_time() - start) / steps
        finally:
            env.close()
    finally:
        torch.set_num_threads(threads)


def bench_suite(sizes: BenchSizes) -> dict[str, Any]:
    """Section 4: per-step CPU cost of every trainable Table I method on ``sizes.tasks`` and
    the paper suite's CPU-hours (all of `distgprl.data.TASK_NAMES` are needed for the
    suite: with fewer tasks measured, ``cpu_hours`` covers only those)."""
    from distgprl.config import load_config
    from distgprl.identity import SWEEP_SEEDS
    from distgprl.methods import TABLE_ORDER, get_method

    methods = [name for name in TABLE_ORDER if get_method(name).trainable]
    costs = {
        (method, task): training_step_cpu_s(task, method, sizes.learning_starts, sizes.suite_steps)
        for method in methods
        for task in sizes.tasks
    }
    total_steps = {task: load_config("paper", task).run.total_steps for task in sizes.tasks}
    hours = suite_cpu_hours(costs, total_steps, len(SWEEP_SEEDS))
    return {
        "methods": methods,
        "tasks": list(sizes.tasks),
        "seeds": len(SWEEP_SEEDS),
        "total_steps": total_steps,
        "steps_timed_per_run": sizes.suite_steps,
        "cpu_ms_per_step": {f"{m}/{t}": 1e3 * cost for (m, t), cost in costs.items()},
        "cpu_hours": hours,
        "hours_two_idle_cores": hours / IDLE_CORES,
    }
