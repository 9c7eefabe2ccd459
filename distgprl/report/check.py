"""Sanity check of a Table I CSV (used by CI after the reduced-size sweep).

`python -m distgprl.report.check TABLE.csv [--tasks dcp,dbm]`: every method of the
registry has a row, every task has at least one seed per row, rates lie in [0, 1]
(kinematic retention, a cosine, in [-1, 1]), success does not exceed completion and
success + collision does not exceed 1 (success is completion without collision), and MinCl
is a finite, non-negative distance of plausible size (at most 1 m).
Exit code 1 with a line per problem.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import math
import sys
from pathlib import Path

from distgprl.data import TASK_NAMES
from distgprl.methods import TABLE_ORDER

LOWER_BOUNDS = {"success_rate": 0.0, "collision_rate": 0.0, "mean_kinematic_retention": -1.0}
"""The metrics whose mean must lie in [lower bound, 1]."""


def check_table(path: str | Path, tasks: list[str]) -> list[str]:
    """Problems found in the table (empty if it is sane)."""
    with open(path, newline="") as handle:
        rows = {row["method"]: row for row in csv.DictReader(handle)}
    problems = [f"missing row: {m}" for m in TABLE_ORDER if m not in rows]
    for (method, row), task in itertools.product(rows.items(), tasks):
        name = f"{method} {task}"
        if int(row.get(f"{task}_seeds") or 0) < 1:
            problems.append(f"{method}: no {task} seeds")
            continue
        mean = {key: float(row[f"{task}_{key}_mean"]) for key in (*LOWER_BOUNDS, "completion_rate")}
        problems += [
            f"{name} {key} out of range: {mean[key]}"
            for key, low in LOWER_BOUNDS.items()
            if not low <= mean[key] <= 1.0
        ]
        success, collision, completed = (
            mean[k] for k in ("success_rate", "collision_rate", "completion_rate")
        )
        if success > completed + 1e-9:
            problems.append(f"{name} success above completion: {success} > {completed}")
        if success + collision > 1.0 + 1e-9:
            problems.append(f"{name} success + collision above 1: {round(success + collision, 6)}")
        clearance = float(row[f"{task}_min_clearance_p5_mean"])
        if not math.isfinite(clearance) or abs(clearance) > 1.0:
            problems.append(f"{name} MinCl implausible: {clearance}")
        elif clearance < 0.0:
            problems.append(f"{name} MinCl negative: {clearance}")
    return problems


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m distgprl.report.check")
    parser.add_argument("table", help="a Table I CSV (table1_<preset>.csv)")
    parser.add_argument("--tasks", default=",".join(TASK_NAMES), help="comma-separated tasks")
    args = parser.parse_args(argv)
    problems = check_table(args.table, args.tasks.split(","))
    for problem in problems:
        print(problem)
    print(f"{args.table}: {'OK' if not problems else f'{len(problems)} problem(s)'}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
