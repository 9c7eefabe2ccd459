"""Timing helpers of the benchmarks: per-call statistics, (interleaved) measurement, timers
around instance methods and the machine description recorded with every result."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Timing", "machine_info", "measure", "measure_interleaved"]


@dataclass(frozen=True)
class Timing:
    """Wall-time statistics of one operation, in microseconds."""

    median_us: float
    p10_us: float
    p90_us: float
    repeats: int

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_samples(cls, samples_s: np.ndarray | list[float]) -> Timing:
        """Statistics of per-call durations given in seconds."""
        us = np.asarray(samples_s, dtype=float) * 1e6
        return cls(
            float(np.median(us)),
            float(np.percentile(us, 10)),
            float(np.percentile(us, 90)),
            int(us.size),
        )


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


def measure_interleaved(
    funcs: dict[str, Callable[[], object]],
    repeats: int,
    warmup: int = 3,
    inner: int = 1,
    clock: Callable[[], float] = time.perf_counter,
) -> dict[str, Timing]:
    """Time several functions with their samples interleaved (A, B, A, B, ...).

    On a loaded machine the load drifts over seconds; interleaving exposes every candidate to
    the same drift, so the ratio of their medians is fair. ``clock`` (seconds) is wall time by
    default; ``time.process_time`` gives process CPU time, which other processes sharing the
    cores inflate far less.
    """
    for func in funcs.values():
        for _ in range(warmup):
            func()
    samples = {name: np.empty(repeats) for name in funcs}
    for i in range(repeats):
        for name, func in funcs.items():
            start = clock()
            for _ in range(inner):
                func()
            samples[name][i] = (clock() - start) / inner
    return {name: Timing.from_samples(values) for name, values in samples.items()}


def machine_info() -> dict[str, Any]:
    """CPU model, core count, load average, Python and torch threading."""
    import torch

    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_average": list(os.getloadavg()),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "torch_threads": torch.get_num_threads(),
    }
