"""Scripted experts that write the shipped demonstrations.

Each expert plans a few key TCP poses for a task configuration and joins them with
minimum-jerk segments (zero velocity and acceleration at every key pose; `minimum_jerk` in
:mod:`distgprl.sim.profiles`), sampled at its ``SAMPLE_RATE``. ``python -m
distgprl.sim.experts [--out DIR]`` regenerates, for every task, ``<task>.csv`` (nominal TC)
and ``<task>_varied/demo_XX.csv`` with ``tcs.json`` (20 TCs drawn from :data:`VARIED_SEED`;
a drawn TC on which the expert's own execution fails or collides is skipped, so every varied
demonstration succeeds for its TC). The output is byte-for-byte reproducible.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from distgprl.data import TASK_NAMES
from distgprl.sim.profiles import minimum_jerk
from distgprl.sim.tasks.base import DEMO_DIR, TaskConfig, TaskSim, resample_to_control
from distgprl.skill.demos import save_demonstration

VARIED_SEED = 3_141_592
"""Seed of the TCs of the varied demonstrations (distinct from evaluation/training seeds)."""

VARIED_COUNT = 20


# ---------------------------------------------------------------------------- DCP
def dcp_expert(tc: TaskConfig) -> tuple[np.ndarray, np.ndarray]:
    """Demonstration (times (n,), poses (n, 6)) pushing the drifting cube into the goal.

    Key poses: start -> above and behind the cube -> engage (blade 2 cm behind the cube,
    8 mm above the table, square to the cube-to-goal direction) -> push the cube centre
    onto the goal centre -> retreat up and back.
    """
    from distgprl.sim.tasks.dcp import SCENE, engagement_time

    scene = SCENE
    t_engage = engagement_time()
    cube = np.asarray(scene.cube_start) + np.asarray(tc.object_offset)
    cube_engage = cube + np.asarray(scene.drift_velocity) * t_engage
    goal = np.asarray(scene.goal_centre)
    direction = goal - cube_engage
    direction /= np.linalg.norm(direction)
    yaw = math.atan2(direction[1], direction[0]) - math.pi / 2.0
    start = np.asarray(scene.start_pose, dtype=float)

    def pose(xy: np.ndarray, z: float) -> np.ndarray:
        return np.array([xy[0], xy[1], z, 0.0, 0.0, yaw])

    back = scene.cube_half + 0.02
    key_poses = np.stack(
        [
            start,
            pose(cube_engage - direction * (back + 0.05), 0.10),
            pose(cube_engage - direction * back, 0.008),
            pose(goal - direction * scene.cube_half, 0.008),
            pose(goal - direction * (scene.cube_half + 0.10), 0.15),
        ]
    )
    key_times = np.array([0.0, 1.4, t_engage, 4.0, 4.8])
    return minimum_jerk(key_times, key_poses)


# ---------------------------------------------------------------------------- driver
def _experts() -> dict[str, Callable[[TaskConfig], tuple[np.ndarray, np.ndarray]]]:
    from distgprl.sim.tasks.dbm import dbm_expert

    return {"dcp": dcp_expert, "dbm": dbm_expert}


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
    expert = _experts()[task_name]
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
