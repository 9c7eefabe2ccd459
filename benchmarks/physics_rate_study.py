"""Physics-rate study (issue 29): do 2 physics substeps per 25 Hz control period change outcomes?

The per-step physics cost scales with ``stepSimulation`` calls (3 substeps of 1/75 s per
control period today). This evaluates the same policies on the same TCs with the default
physics and with 2 substeps of 1/50 s (same control period), and compares success and
collision TC by TC. The bar for adopting the cheaper rate: outcomes agree on >= 99 % of the
TCs for every policy (issue 29), as part of an environment version.

    python benchmarks/physics_rate_study.py --episodes 1000 [--root R --preset ci --seed 0]
        [--methods demo,dist-gprl] [--out results/bench/physics_rate.json]

Policies: the `demo` reference and, per task, each trained run named by ``--methods`` under
``--root``/``--preset`` (the trained policy's own configuration; any preset). Process CPU time
per episode is reported for both rates.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import distgprl.sim.tasks.base as task_base
from distgprl.api import load_policy
from distgprl.experiments.factories import make_env
from distgprl.experiments.rollout import evaluate_policy
from distgprl.identity import resolve_run
from distgprl.sim.bullet import PhysicsConfig


@dataclass(frozen=True)
class TwoSubsteps(PhysicsConfig):
    """The candidate rate: 2 physics steps of 1/50 s per 25 Hz control period."""

    physics_dt: float = 1.0 / 50.0
    substeps: int = 2


def outcomes(task, method, seed, preset, root, episodes, physics) -> tuple[list[dict], float]:
    """Evaluation rows on the first ``episodes`` evaluation TCs with ``physics`` (a class)."""
    original = task_base.PhysicsConfig
    task_base.PhysicsConfig = physics  # what TaskSim builds when given no physics
    try:
        run = resolve_run(task, method, seed, preset)
        env = make_env(run)
        policy = load_policy(task, method, seed, preset=preset, root=root)
        tcs = env.spec_task.evaluation_tcs(episodes)
        start = time.process_time()
        rows = evaluate_policy(env, tcs, policy.predict, progress=True)
        cpu = (time.process_time() - start) / episodes
        env.close()
    finally:
        task_base.PhysicsConfig = original
    return rows, cpu


def compare(a: list[dict], b: list[dict]) -> dict:
    """Share of TCs with the same success and collision; the rates under both."""
    same = [
        int(x["success"]) == int(y["success"]) and int(x["collision"]) == int(y["collision"])
        for x, y in zip(a, b, strict=True)
    ]
    return {
        "agreement": float(np.mean(same)),
        "success": [float(np.mean([int(r["success"]) for r in rows])) for rows in (a, b)],
        "collision": [float(np.mean([int(r["collision"]) for r in rows])) for rows in (a, b)],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--root", default="results")
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", default="demo")
    parser.add_argument("--tasks", default="dcp,dbm")
    parser.add_argument("--out", type=Path, default=Path("results/bench/physics_rate.json"))
    args = parser.parse_args()
    report = {"episodes": args.episodes, "preset": args.preset, "policies": []}
    for task in args.tasks.split(","):
        for method in args.methods.split(","):
            base, base_cpu = outcomes(
                task, method, args.seed, args.preset, args.root, args.episodes, PhysicsConfig
            )
            fast, fast_cpu = outcomes(
                task, method, args.seed, args.preset, args.root, args.episodes, TwoSubsteps
            )
            entry = {
                "task": task,
                "method": method,
                **compare(base, fast),
                "cpu_s_per_episode": [base_cpu, fast_cpu],
            }
            report["policies"].append(entry)
            print(json.dumps(entry))
    report["adopt"] = all(p["agreement"] >= 0.99 for p in report["policies"])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"adopt 2 substeps: {report['adopt']} -> {args.out}")


if __name__ == "__main__":
    main()
