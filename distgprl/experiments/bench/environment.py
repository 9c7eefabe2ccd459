"""Section 2: the environment's step against the bare physics inside it (issue 29).

For each task, the paper preset's environment (`BENCH_METHOD`) runs episodes on the first
evaluation TCs with the zero action (the TC-conditioned demonstration, full segments). Each
episode runs twice, interleaved: once as is, timing every ``env.step`` in process CPU time,
and once with the client's ``stepSimulation`` wrapped by a process-CPU timer (the same
episode, so the same physics calls). The second pass gives the *bare physics* floor: the
``stepSimulation`` calls the step cannot do without. ``env_step_over_bare_physics`` is the
ratio of the per-episode medians (everything above 1 is Python, IK, contact and clearance
queries, the EDF and the observation).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from distgprl.experiments.bench.sizes import BENCH_METHOD, run_spec
from distgprl.experiments.bench.timing import Timing

__all__ = ["bench_env_step"]


def _episode(env, tc, action: np.ndarray) -> tuple[float, int]:
    """Process CPU seconds of the env steps of one episode on ``tc``, and the step count."""
    clock = time.process_time
    env.reset(options={"tc": tc})
    total, steps, done = 0.0, 0, False
    while not done:
        start = clock()
        _, _, terminated, truncated, _ = env.step(action)
        total += clock() - start
        steps += 1
        done = terminated or truncated
    return total, steps


def bench_env_step(task: str, episodes: int, method: str = BENCH_METHOD) -> dict[str, Any]:
    """Section 2: per-episode env-step CPU time vs the ``stepSimulation`` CPU time in it.

    Returns medians (``Timing``, microseconds per episode) of ``env_step`` and
    ``bare_physics``, their per-step medians ``env_step_cpu_ms`` and ``bare_physics_cpu_ms``
    (the suite floor's physics, section 5), and ``env_step_over_bare_physics`` (ratio of the
    per-episode medians).
    """
    from distgprl.experiments.factories import make_env

    env = make_env(run_spec(task, method))
    calls = env.unwrapped.sim.calls
    step_simulation = calls.step_simulation
    physics = [0.0]
    clock = time.process_time

    def timed_step_simulation() -> Any:
        start = clock()
        try:
            return step_simulation()
        finally:
            physics[0] += clock() - start

    action = np.zeros(env.action_space.shape, dtype=np.float32)
    tcs = env.spec_task.evaluation_tcs(episodes)
    env_s, physics_s, steps = [], [], []
    try:
        _episode(env, tcs[0], action)  # warm-up
        for tc in tcs:
            seconds, count = _episode(env, tc, action)
            env_s.append(seconds)
            steps.append(count)
            physics[0] = 0.0
            calls.step_simulation = timed_step_simulation
            try:
                _episode(env, tc, action)
            finally:
                calls.step_simulation = step_simulation
            physics_s.append(physics[0])
    finally:
        env.close()
    env_timing, physics_timing = Timing.from_samples(env_s), Timing.from_samples(physics_s)
    per_step = float(np.median(np.asarray(env_s) / np.asarray(steps)))
    physics_per_step = float(np.median(np.asarray(physics_s) / np.asarray(steps)))
    return {
        "task": task,
        "method": method,
        "episodes": episodes,
        "clock": "process CPU time",
        "env_step_per_episode": env_timing.to_dict(),
        "bare_physics_per_episode": physics_timing.to_dict(),
        "env_step_cpu_ms": 1e3 * per_step,
        "bare_physics_cpu_ms": 1e3 * physics_per_step,
        "env_step_over_bare_physics": env_timing.median_us / physics_timing.median_us,
    }
