"""Where a training run's process CPU time goes outside its training steps (issue 29).

    python benchmarks/run_costs.py [--task dcp] [--method dist-gprl] [--steps 3000]
        [--root /tmp/run_costs] [--out results/bench/run_costs_dcp.json]

Trains one `paper`-preset run for ``--steps`` steps (its curve every ``eval_every`` steps, a
checkpoint at the end, then the final and best-policy evaluations, as `distgprl train` does)
in a fresh results root, under cProfile with a process-CPU clock, and reports the cumulative
CPU seconds of: the training steps (``learn``), the learning-curve evaluations
(``record_curve``), the checkpoints (model, replay buffer, kept actors: ``checkpoint``), the
evaluations after training (``_evaluate_trained``), and the rest (imports, building the
environments and the agent, saving the final model). cProfile adds a fixed cost per Python
call, so the shares matter, not the absolute seconds. A full run scales each part by its
count: a `paper` run has ``total_steps / eval_every + 1`` curve points (21 DCP, 31 DBM) and
``total_steps / checkpoint_every`` checkpoints.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import shutil
import time
from pathlib import Path

PARTS = {
    "learn": "training steps",
    "record_curve": "learning-curve evaluations",
    "checkpoint": "checkpoints",
    "_evaluate_trained": "evaluations after training",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="dcp")
    parser.add_argument("--method", default="dist-gprl")
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--root", type=Path, default=Path("/tmp/run_costs"))
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    shutil.rmtree(args.root, ignore_errors=True)
    profile = cProfile.Profile(time.process_time)
    start = time.process_time()
    profile.enable()
    from distgprl.experiments.training import train_run

    train_run(
        args.task, args.method, 0, "paper", steps=args.steps, root=args.root, show_progress=False
    )
    profile.disable()
    total = time.process_time() - start
    stats = pstats.Stats(profile).stats  # (file, line, name) -> (cc, calls, tt, ct, callers)
    parts: dict[str, dict[str, float]] = {}
    for (path, _, name), (_, calls, _, cumulative, _) in stats.items():
        if name in PARTS and path.endswith("training.py"):
            entry = parts.setdefault(name, {"calls": 0, "cpu_s": 0.0})
            entry["calls"] += calls
            entry["cpu_s"] += cumulative
    # imports, building the environments and the agent, saving the final model
    rest = total - sum(value["cpu_s"] for value in parts.values())
    labelled = {PARTS[name]: value for name, value in parts.items()}
    report = {
        "task": args.task,
        "method": args.method,
        "steps": args.steps,
        "total_cpu_s": total,
        "parts": labelled,
        "rest_cpu_s": rest,
        "shares": {label: value["cpu_s"] / total for label, value in labelled.items()}
        | {"the rest (imports, environments, agent, final save)": rest / total},
    }
    print(json.dumps(report, indent=1))
    if args.out is not None:
        from distgprl.schema import write_json

        write_json(args.out, report, kind="bench")  # with the meta block (commit, machine)


if __name__ == "__main__":
    main()
