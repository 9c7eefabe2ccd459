"""Scripted experts that write the shipped demonstrations.

Each task's expert (``TaskSpec.expert``, declared in its task module: `dcp_expert` in
:mod:`distgprl.sim.tasks.dcp`, `dbm_expert` in :mod:`distgprl.sim.tasks.dbm`) plans a few key
TCP poses for a task configuration and joins them with minimum-jerk segments (zero velocity
and acceleration at every key pose; `minimum_jerk` in :mod:`distgprl.sim.profiles`). ``python -m
distgprl.sim.experts [--out DIR]`` regenerates, for every task, ``<task>.csv`` (nominal TC)
and ``<task>_varied/demo_XX.csv`` with ``tcs.json`` (20 TCs drawn from :data:`VARIED_SEED`;
a drawn TC on which the expert's own execution fails or collides is skipped, so every varied
demonstration succeeds for its TC). The output is byte-for-byte reproducible.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from distgprl.data import DEMO_DIR, TASK_NAMES
from distgprl.sim.tasks.base import TaskConfig, TaskSim, resample_to_control
from distgprl.skill.demos import save_demonstration

VARIED_SEED = 3_141_592
"""Seed of the TCs of the varied demonstrations (distinct from evaluation/training seeds)."""

VARIED_COUNT = 20


def run_demonstration(
    sim: TaskSim, tc: TaskConfig, times: np.ndarray, poses: np.ndarray
) -> tuple[bool, bool, float]:
    """Execute a demonstration in ``sim`` for ``tc``: (success, collision, min clearance m)."""
    sim.reset(tc)
    result = sim.execute(resample_to_control(times, poses, sim.control_dt))
    return sim.success(), result.collision, result.min_clearance


def generate(task_name: str, out_dir: Path = DEMO_DIR) -> list[TaskConfig]:
    """Write the nominal and the varied demonstrations of one task into ``out_dir``.

    Returns the TCs of the varied demonstrations.
    """
    from distgprl.sim.tasks import get_task

    spec = get_task(task_name)
    expert = spec.expert
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    times, poses = expert(spec.nominal_tc)
    save_demonstration(out_dir / f"{task_name}.csv", times, poses)
    varied_dir = out_dir / f"{task_name}_varied"
    varied_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(VARIED_SEED)
    tcs: list[TaskConfig] = []
    sim = spec.make_sim()
    try:
        attempts = 0
        while len(tcs) < VARIED_COUNT:
            attempts += 1
            if attempts > 20 * VARIED_COUNT:
                raise RuntimeError(f"{task_name}: expert succeeds too rarely for varied demos")
            tc = spec.sample_tc(rng)
            times, poses = expert(tc)
            success, collision, _ = run_demonstration(sim, tc, times, poses)
            if not success or collision:
                continue
            save_demonstration(varied_dir / f"demo_{len(tcs):02d}.csv", times, poses)
            tcs.append(tc)
    finally:
        sim.close()
    payload = {
        "task": task_name,
        "seed": VARIED_SEED,
        "files": [f"demo_{i:02d}.csv" for i in range(len(tcs))],
        "tcs": [tc.to_dict() for tc in tcs],
    }
    (varied_dir / "tcs.json").write_text(json.dumps(payload, indent=1) + "\n")
    return tcs


def main(argv: list[str] | None = None) -> None:
    """Command-line entry: regenerate all shipped demonstrations."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEMO_DIR, help="output folder")
    parser.add_argument("--task", choices=TASK_NAMES, action="append", help="task(s)")
    args = parser.parse_args(argv)
    for name in args.task or TASK_NAMES:
        tcs = generate(name, args.out)
        print(f"{name}: nominal + {len(tcs)} varied demonstrations in {args.out}")


if __name__ == "__main__":
    main()
