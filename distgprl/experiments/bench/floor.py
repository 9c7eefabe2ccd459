"""Section 5: the suite's arithmetic floor, what no faster code of the same algorithm avoids
(issue 29).

A training step is one env step and one SAC gradient step. Two of its costs belong to the
algorithm, not to how it is coded: the **matrix products of a plain SAC update** (the actor's
and both critics' linear layers, forward and backward, on the paper's networks and batch;
timed inside real updates by `MatrixProductClock`) and the **bare physics** of the env step
(its ``stepSimulation`` calls, section 2). With everything else free (the regulariser,
autograd, Adam, SB3's loop, IK, contact and clearance queries, the observation), a run
still costs

    total_steps x physics per step + (total_steps - learning_starts) x matrix products per update

of process CPU time (SB3 makes no gradient step before ``learning_starts``). `suite_floor`
sums that over the paper suite's runs: a lower bound, on this machine, of the CPU-hours any
implementation of the same algorithm and environment pays, beside the measured
``suite.cpu_hours`` of section 4.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

# torch's own hook for seeing every aten op below autograd, forward and backward (the bench
# package imports torch anyway, through `distgprl.agents.sac`).
from torch.utils._python_dispatch import TorchDispatchMode

__all__ = ["MatrixProductClock", "bench_floor", "sac_update_matrix_products", "suite_floor"]


def _matrix_product_flops(name: str, args: Sequence[Any]) -> int:
    """Multiply-adds x 2 of one matrix product op (bias additions not counted)."""
    if name in ("mm", "bmm"):
        first, second = args[0], args[1]
    else:  # addmm / baddbmm (input, first, second)
        first, second = args[1], args[2]
    batch = first.shape[0] if first.dim() == 3 else 1
    rows, inner = first.shape[-2], first.shape[-1]
    return 2 * batch * rows * inner * second.shape[-1]


class MatrixProductClock(TorchDispatchMode):
    """A torch dispatch mode that times every matrix product run while it is active.

    Inside ``with MatrixProductClock() as clock:`` each ``aten.mm``, ``addmm``, ``bmm`` and
    ``baddbmm`` call (``nn.Linear`` forward is an ``addmm``, its backward two ``mm``) is timed
    with ``clock`` around the kernel alone; every other op runs untimed.

    Attributes:
        seconds: ``clock`` seconds spent inside matrix products (process CPU time by default).
        calls: matrix products run.
        flops: their floating-point operations (2 per multiply-add).
    """

    NAMES = frozenset({"mm", "addmm", "bmm", "baddbmm"})

    def __init__(self, clock: Callable[[], float] = time.process_time) -> None:
        super().__init__()
        self.clock = clock
        self.seconds = 0.0
        self.calls = 0
        self.flops = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = func.overloadpacket.__name__
        if name not in self.NAMES:
            return func(*args, **kwargs)
        start = self.clock()
        result = func(*args, **kwargs)
        self.seconds += self.clock() - start
        self.calls += 1
        self.flops += _matrix_product_flops(name, args)
        return result


def sac_update_matrix_products(model, updates: int, warmup: int = 3) -> dict[str, Any]:
    """Process CPU time of the matrix products of ``updates`` plain SAC gradient steps, and
    of the same updates without the clock.

    ``model`` is a `distgprl.agents.sac.RegularisedSAC` with a filled replay buffer; its
    regulariser is left out for these updates (restored after), so they are SB3's SAC update
    with the paper's networks and batch. The updates alternate: one timed whole without the
    dispatch mode (``update_ms``, the update as training runs it), one with the clock on (its
    products only). The dispatch mode costs every other op a Python call, so the clocked
    updates' whole time (``update_ms_with_clock``) is not the update's cost;
    ``non_product_ms`` = ``update_ms`` - ``matrix_products_ms`` is the update's framework
    work (autograd, Adam, SB3's Python, the replay sample, element-wise ops; issue 49).

    Returns:
        ``matrix_products_ms`` (mean per update), ``calls_per_update``, ``gflop_per_update``,
        ``gflops`` (achieved rate), ``update_ms`` (median process CPU time of an uninstrumented
        plain update), ``non_product_ms``, ``update_ms_with_clock`` (the clocked updates'
        whole process CPU time, slowed by the dispatch mode) and ``matrix_product_share``
        (products over ``update_ms``, < 1).
    """
    import numpy as np
    import torch

    regulariser = model.regulariser
    model.regulariser = None
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as `train_run` (RunConfig.torch_threads)
    batch = model.batch_size
    clock = MatrixProductClock()
    plain, whole = [], 0.0
    try:
        for _ in range(warmup):
            model.train(gradient_steps=1, batch_size=batch)
        for _ in range(updates):
            start = time.process_time()
            model.train(gradient_steps=1, batch_size=batch)
            plain.append(time.process_time() - start)
            start = time.process_time()
            with clock:
                model.train(gradient_steps=1, batch_size=batch)
            whole += time.process_time() - start
    finally:
        model.regulariser = regulariser
        torch.set_num_threads(threads)
    products_ms = 1e3 * clock.seconds / updates
    update_ms = 1e3 * float(np.median(plain))
    return {
        "updates": updates,
        "batch_size": batch,
        "clock": "process CPU time",
        "matrix_products_ms": products_ms,
        "calls_per_update": clock.calls / updates,
        "gflop_per_update": clock.flops / updates / 1e9,
        "gflops": clock.flops / clock.seconds / 1e9 if clock.seconds > 0 else float("nan"),
        "update_ms": update_ms,
        "non_product_ms": update_ms - products_ms,
        "update_ms_with_clock": 1e3 * whole / updates,
        "matrix_product_share": products_ms / update_ms if update_ms > 0 else float("nan"),
    }


def suite_floor(
    matrix_products_s_per_update: float,
    physics_s_per_step: Mapping[str, float],
    total_steps: Mapping[str, int],
    learning_starts: Mapping[str, int],
    runs_per_task: Mapping[str, int],
    idle_cores: int,
) -> dict[str, Any]:
    """The suite's floor: every run's bare physics plus its updates' matrix products.

    Args:
        matrix_products_s_per_update: process CPU seconds of one plain SAC update's matrix
            products (`sac_update_matrix_products`).
        physics_s_per_step: bare ``stepSimulation`` CPU seconds per env step, by task.
        total_steps: RL steps per run, by task.
        learning_starts: steps before the first gradient step, by task.
        runs_per_task: trained runs per task (methods x seeds).
        idle_cores: cores the runs share (the wall time is CPU time / cores).

    Returns:
        ``cpu_hours`` and ``hours_idle_cores`` of the whole suite, and per task its
        ``physics_cpu_hours`` and ``matrix_product_cpu_hours``.
    """
    per_task = {}
    for task, runs in runs_per_task.items():
        steps = total_steps[task]
        updates = max(steps - learning_starts[task], 0)
        per_task[task] = {
            "runs": runs,
            "physics_cpu_hours": runs * steps * physics_s_per_step[task] / 3600.0,
            "matrix_product_cpu_hours": runs * updates * matrix_products_s_per_update / 3600.0,
        }
    hours = sum(t["physics_cpu_hours"] + t["matrix_product_cpu_hours"] for t in per_task.values())
    return {"cpu_hours": hours, "hours_idle_cores": hours / idle_cores, "per_task": per_task}


def bench_floor(
    update: Mapping[str, Any],
    environment: Mapping[str, Mapping[str, Any]],
    suite: Mapping[str, Any],
) -> dict[str, Any]:
    """Section 5: the paper suite's floor from the measured pieces, over the runs of section 4.

    Args:
        update: `sac_update_matrix_products` of the bench's model.
        environment: section 2 by task (`bench_env_step`: ``bare_physics_cpu_ms``).
        suite: section 4 (`bench_suite`): its ``methods``, ``seeds`` and per-task
            ``total_steps`` are the runs the floor covers.
    """
    from distgprl.config import load_config
    from distgprl.experiments.bench.suite import IDLE_CORES

    tasks = list(suite["total_steps"])
    runs = len(suite["methods"]) * suite["seeds"]
    physics_ms = {task: environment[task]["bare_physics_cpu_ms"] for task in tasks}
    floor = suite_floor(
        update["matrix_products_ms"] / 1e3,
        {task: ms / 1e3 for task, ms in physics_ms.items()},
        suite["total_steps"],
        {task: load_config("paper", task).sac.learning_starts for task in tasks},
        {task: runs for task in tasks},
        IDLE_CORES,
    )
    return {"sac_update": dict(update), "physics_cpu_ms_per_step": physics_ms, **floor}
