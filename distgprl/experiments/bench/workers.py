"""Section 5c and its worker protocol: aggregate training throughput of independent
processes (``python -m distgprl.experiments.bench --worker TASK LEARNING_STARTS STEPS``)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from typing import Any

from distgprl.experiments.bench.sizes import BENCH_TASK, BenchSizes, run_spec

__all__ = ["WORKER_RATE", "WORKER_READY", "bench_workers", "training_worker"]


WORKER_READY = "DISTGPRL-BENCH-READY"
WORKER_RATE = "DISTGPRL-BENCH-RATE"


def training_worker(task: str, learning_starts: int, steps: int) -> None:
    """One independent short training (run in its own process by `bench_workers`).

    Sets up, runs the untimed random-action phase, prints `WORKER_READY`, waits for a line on
    stdin (the start signal, so that concurrent workers overlap), then prints `WORKER_RATE`
    and its timed steps per second.
    """
    import sys

    import torch

    from distgprl.experiments.runner import make_agent, make_env

    torch.set_num_threads(1)
    run = run_spec(task, sac_overrides={"learning_starts": learning_starts})
    env = make_env(run)
    model = make_agent(env, run)
    env.reset(seed=0)
    model.learn(total_timesteps=learning_starts + 3, progress_bar=False)
    print(WORKER_READY, flush=True)
    sys.stdin.readline()
    start = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False, progress_bar=False)
    print(f"{WORKER_RATE} {steps / (time.perf_counter() - start)!r}", flush=True)
    env.close()


def _read_marker(process: subprocess.Popen, marker: str) -> str:
    """The rest of the first stdout line of ``process`` that starts with ``marker``."""
    assert process.stdout is not None
    for line in process.stdout:
        if line.startswith(marker):
            return line[len(marker) :].strip()
    raise RuntimeError(f"benchmark worker exited (code {process.wait()}) before {marker}")


def _worker_rates(count: int, sizes: BenchSizes, task: str) -> list[float]:
    """Steps per second of ``count`` fresh worker processes training at the same time."""
    command = [sys.executable, "-m", "distgprl.experiments.bench", "--worker", task]
    command += [str(sizes.learning_starts), str(sizes.worker_steps)]
    with tempfile.TemporaryFile("w+") as errors:
        processes = [
            subprocess.Popen(
                command,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=errors,
                text=True,
            )
            for _ in range(count)
        ]
        try:
            for process in processes:
                _read_marker(process, WORKER_READY)
            for process in processes:
                assert process.stdin is not None
                process.stdin.write("go\n")
                process.stdin.flush()
            rates = [float(_read_marker(process, WORKER_RATE)) for process in processes]
            for process in processes:
                process.wait(timeout=120)
        except BaseException as exc:
            for process in processes:
                process.kill()
            errors.seek(0)
            raise RuntimeError(f"{exc}; worker stderr tail:\n{errors.read()[-2000:]}") from exc
    return rates


def bench_workers(sizes: BenchSizes, task: str = BENCH_TASK) -> list[dict[str, Any]]:
    """Section 5c: aggregate training throughput of independent training processes.

    For every N in ``sizes.workers`` (1 included), N fresh Python processes set up, wait
    until all are ready, then train ``sizes.worker_steps`` steps at the same time; their
    rates are summed. Every N runs the same uninstrumented code, so ``speedup_vs_one`` is a
    like-for-like ratio (the in-process run of `bench_training` carries its section timers,
    which cost a few milliseconds per step, and is not the reference).
    """
    out: list[dict[str, Any]] = []
    for count in sizes.workers:
        rates = _worker_rates(count, sizes, task)
        out.append(
            {
                "workers": count,
                "steps_per_s_each": rates,
                "aggregate_steps_per_s": float(sum(rates)),
            }
        )
    single = next((row["aggregate_steps_per_s"] for row in out if row["workers"] == 1), None)
    for row in out:
        row["speedup_vs_one"] = None if single is None else row["aggregate_steps_per_s"] / single
    return out
