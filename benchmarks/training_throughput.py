"""Training throughput: where a short real training run's time goes, and the aggregate rate
of independent training processes (the training-speed study of issue 29; the package's
`distgprl bench` keeps the paper's §V figures).

    python benchmarks/training_throughput.py [--size full|quick|tiny] [--out PATH]

1. One process (paper preset, DCP / dist-gprl, one torch thread): steps per second of a
   short training run with timers around its pieces (simulation, IK, EDF, SAC update, ...;
   `training_breakdown`: exclusive ms per step and share of the wall time).
2. For each worker count N (1 included), N fresh processes (``--worker TASK LEARNING_STARTS
   STEPS``, this file) set up, wait until all are ready, then train at the same time; their
   rates are summed (``speedup_vs_one``: like for like, the same uninstrumented code).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from distgprl.experiments.bench.sizes import BENCH_METHOD, BENCH_TASK, run_spec

SIZES: dict[str, dict[str, Any]] = {
    "full": {"learning_starts": 60, "steps": 1200, "worker_steps": 450, "workers": (1, 2)},
    "quick": {"learning_starts": 20, "steps": 60, "worker_steps": 45, "workers": (1, 2)},
    "tiny": {"learning_starts": 6, "steps": 6, "worker_steps": 6, "workers": (1,)},
}
"""How much each size measures: random-action steps before the timed ones, timed steps of the
in-process run and of each worker, worker counts (``tiny``: the tests', numbers meaningless)."""


class SectionTimers:
    """Inclusive wall time and call counts of wrapped instance methods (cheap: ~0.3 us/call)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}

    def wrap(self, owner: object, attribute: str, name: str) -> None:
        """Replace ``owner.attribute`` (a callable) by a timed wrapper adding into ``name``."""
        original = getattr(owner, attribute)
        self.seconds.setdefault(name, 0.0)
        self.calls.setdefault(name, 0)
        seconds, calls, clock = self.seconds, self.calls, time.perf_counter

        def timed(*args: Any, **kwargs: Any) -> Any:
            start = clock()
            try:
                return original(*args, **kwargs)
            finally:
                seconds[name] += clock() - start
                calls[name] += 1

        setattr(owner, attribute, timed)


def _instrument(env, model) -> SectionTimers:
    """Timers around the pieces of a training step (see `training_breakdown`)."""
    timers = SectionTimers()
    sim = env.sim
    timers.wrap(env, "step", "env_step")
    timers.wrap(sim, "execute", "sim_execute")
    timers.wrap(sim.calls, "step_simulation", "physics_step")
    timers.wrap(sim.calls, "contact_points", "contact_query")
    timers.wrap(sim.control, "clearance", "clearance_query")
    # the control loop plans a segment's kinematic poses and conveyor path, then resets
    # the bodies per physics step (`ControlLoop.run`): both count as kinematic obstacles
    for attribute in ("kinematic_schedule", "convey_schedule"):
        timers.wrap(sim, attribute, "kinematic_obstacles")
    for attribute in ("reset_base_pose", "reset_base_velocity"):
        timers.wrap(sim.calls, attribute, "kinematic_obstacles")
    timers.wrap(sim.robot, "command", "joint_commands")
    timers.wrap(sim.robot, "ik_nearest", "ik")
    timers.wrap(sim.robot, "ik_segment", "ik")
    for attribute in ("distance", "update", "clearance"):
        timers.wrap(env.field, attribute, "edf")
    for attribute in ("obstacle_shapes", "tool_points", "tcp_pose", "object_position"):
        timers.wrap(sim, attribute, "state_reads")
    timers.wrap(model, "train", "sac_update")
    if model.regulariser is not None:
        timers.wrap(model, "regulariser", "regulariser_forward")
    timers.wrap(model, "_sample_action", "action_sampling")
    return timers


def training_breakdown(timers: SectionTimers, wall: float, steps: int) -> dict[str, Any]:
    """Exclusive time per piece (ms per training step and fraction of the wall time)."""
    s = timers.seconds
    sim_children: tuple[str, ...] = (
        "physics_step",
        "contact_query",
        "clearance_query",
        "kinematic_obstacles",
    )
    sim_children += ("joint_commands", "ik")
    parts = {
        "simulation: physics (stepSimulation)": s["physics_step"],
        "simulation: contact checks (getContactPoints)": s["contact_query"],
        "simulation: clearance (getClosestPoints)": s["clearance_query"],
        "simulation: kinematic obstacles + joint commands": s["kinematic_obstacles"]
        + s["joint_commands"],
        "simulation: loop overhead (execute, Python)": s["sim_execute"]
        - sum(s[k] for k in sim_children),
        "IK (analytic, nearest branch)": s["ik"],
        "EDF (update + queries, r_sd, r_ga, observation)": s["edf"],
        "simulator state reads (poses, tool points)": s["state_reads"],
        "env step: rest (GP, rewards, observation)": s["env_step"]
        - s["sim_execute"]
        - s["edf"]
        - s["state_reads"],
        "SAC update: regulariser forward (L_sim + L_hap)": s.get("regulariser_forward", 0.0),
        "SAC update: rest (critic/actor forward, backward, Adam)": s["sac_update"]
        - s.get("regulariser_forward", 0.0),
        "action sampling (actor forward)": s["action_sampling"],
        "SB3 loop, replay buffer, other": wall
        - s["env_step"]
        - s["sac_update"]
        - s["action_sampling"],
    }
    return {
        name: {"ms_per_step": 1e3 * value / steps, "fraction": value / wall}
        for name, value in parts.items()
    }


def bench_training(learning_starts: int, steps: int, task: str = BENCH_TASK) -> dict[str, Any]:
    """Steps per second of a short real training run (``steps`` timed training steps after
    ``learning_starts`` random ones, one torch thread) and where the time goes."""
    import torch

    from distgprl.experiments.factories import make_agent, make_env

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        run = run_spec(task, sac_overrides={"learning_starts": learning_starts})
        env = make_env(run)
        model = make_agent(env, run)
        env.reset(seed=0)
        model.learn(total_timesteps=learning_starts + 3, progress_bar=False)
        timers = _instrument(env, model)
        start = time.perf_counter()
        model.learn(total_timesteps=steps, reset_num_timesteps=False, progress_bar=False)
        wall = time.perf_counter() - start
        env.close()
    finally:
        torch.set_num_threads(threads)
    return {
        "task": task,
        "method": BENCH_METHOD,
        "steps": steps,
        "wall_s": wall,
        "steps_per_s": steps / wall,
        "breakdown": training_breakdown(timers, wall, steps),
        "calls_per_step": {k: v / steps for k, v in timers.calls.items()},
    }


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

    from distgprl.experiments.factories import make_agent, make_env

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


def _worker_rates(count: int, learning_starts: int, steps: int, task: str) -> list[float]:
    """Steps per second of ``count`` fresh worker processes training at the same time."""
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", task]
    command += [str(learning_starts), str(steps)]
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


def bench_workers(
    counts: Sequence[int], learning_starts: int, steps: int, task: str = BENCH_TASK
) -> list[dict[str, Any]]:
    """Aggregate training throughput of independent training processes.

    For every N in ``counts`` (1 included), N fresh Python processes set up, wait until all
    are ready, then train ``steps`` steps at the same time; their rates are summed. Every N
    runs the same uninstrumented code, so ``speedup_vs_one`` is a like-for-like ratio (the
    in-process run of `bench_training` carries its section timers, which cost a few
    milliseconds per step, and is not the reference).
    """
    out: list[dict[str, Any]] = []
    for count in counts:
        rates = _worker_rates(count, learning_starts, steps, task)
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


def run_study(size: str) -> dict[str, Any]:
    """Both measurements at ``size`` (a key of `SIZES`)."""
    sizes = SIZES[size]
    return {
        "size": size,
        "training": bench_training(sizes["learning_starts"], sizes["steps"]),
        "workers": bench_workers(sizes["workers"], sizes["learning_starts"], sizes["worker_steps"]),
    }


def describe(document: dict[str, Any]) -> str:
    """The results as text: the in-process rate and its breakdown, then the worker rates."""
    training = document["training"]
    lines = [
        f"training {training['task']}/{training['method']}: {training['steps_per_s']:.1f} steps/s"
    ]
    for name, part in sorted(training["breakdown"].items(), key=lambda kv: -kv[1]["fraction"]):
        lines.append(f"  {name}: {part['ms_per_step']:.2f} ms/step ({100 * part['fraction']:.0f}%)")
    for row in document["workers"]:
        lines.append(
            f"{row['workers']} worker process(es): {row['aggregate_steps_per_s']:.1f} steps/s "
            f"(x{row['speedup_vs_one']:.2f} of one)"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", choices=tuple(SIZES), default="full")
    parser.add_argument("--out", type=Path, help="also write the results as JSON here")
    parser.add_argument("--worker", nargs=3, metavar=("TASK", "LEARNING_STARTS", "STEPS"))
    args = parser.parse_args(argv)
    if args.worker:
        task, learning_starts, steps = args.worker
        training_worker(task, int(learning_starts), int(steps))
        return
    document = run_study(args.size)
    print(describe(document))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(document, indent=1) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
