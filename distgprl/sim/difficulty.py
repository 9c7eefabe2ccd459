"""How hard is a task for the unadapted demonstration? (GP-free stand-in measurement.)

Conditions the shipped demonstration on each evaluation TC by translation
(:func:`~distgprl.sim.tasks.base.condition_by_translation`: samples after the interaction
time move by the object offset, with a minimum-jerk blend before it), executes it and
records the outcome. ``python -m distgprl.sim.difficulty [--task NAME]`` prints the rates
per task and the mean progress: the figures of a task's entry in
``distgprl/data/demo_outcomes.json`` (`distgprl.reward_scale.DemoOutcome`).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np

from distgprl.data import TASK_NAMES
from distgprl.sim.tasks import get_task
from distgprl.sim.tasks.base import TaskConfig, condition_by_translation, resample_to_control
from distgprl.skill.demos import load_demonstration


@dataclass(frozen=True)
class EpisodeOutcome:
    """One executed episode: TC, success, collision, min clearance (m), IK failures and the
    task progress gained (`TaskSim.task_progress` at the end minus at the start)."""

    tc: TaskConfig
    success: bool
    collision: bool
    min_clearance: float
    ik_failures: int
    progress: float


def demo_outcomes(task_name: str, episodes: int = 100) -> list[EpisodeOutcome]:
    """Execute the translated demonstration on the first ``episodes`` evaluation TCs."""
    spec = get_task(task_name)
    demo = load_demonstration(spec.demo_path)
    sim = spec.make_sim()
    outcomes = []
    try:
        for tc in spec.evaluation_tcs(episodes):
            poses = condition_by_translation(
                demo.times,
                demo.poses,
                np.asarray(tc.object_offset),
                spec.interaction_time,
                goal_fixed_in_world=spec.goal_fixed_in_world,
            )
            sim.reset(tc)
            start = sim.task_progress()
            result = sim.execute(resample_to_control(demo.times, poses, sim.control_dt))
            outcomes.append(
                EpisodeOutcome(
                    tc,
                    sim.success(),
                    result.collision,
                    result.min_clearance,
                    result.ik_failures,
                    sim.task_progress() - start,
                )
            )
    finally:
        sim.close()
    return outcomes


def summarise(outcomes: list[EpisodeOutcome]) -> dict[str, float]:
    """Success, collision and fail-or-collide rates, 5th-percentile min clearance (m), mean
    progress gained."""
    success = np.array([o.success for o in outcomes])
    collision = np.array([o.collision for o in outcomes])
    clearance = np.array([o.min_clearance for o in outcomes])
    return {
        "episodes": float(len(outcomes)),
        "success_rate": float(success.mean()),
        "collision_rate": float(collision.mean()),
        "fail_or_collide_rate": float((~success | collision).mean()),
        "min_clearance_p5": float(np.percentile(clearance, 5)),
        "progress": float(np.mean([o.progress for o in outcomes])),
    }


def main(argv: list[str] | None = None) -> None:
    """Print the demo's rates on the evaluation TCs of each task (or of ``--task``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--task", choices=TASK_NAMES, action="append", help="task(s)")
    args = parser.parse_args(argv)
    for name in args.task or TASK_NAMES:
        summary = summarise(demo_outcomes(name, args.episodes))
        print(name, " ".join(f"{k}={v:.3f}" for k, v in summary.items()))


if __name__ == "__main__":
    main()
