"""Sanity check of a Table I CSV, run by CI after the reduced-size sweep:
`python -m distgprl.report.check TABLE.csv [--tasks dcp,dbm]` prints a line per problem and
exits 1 if there is any."""

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
"""The metrics whose mean must lie in [lower bound, 1] (kinematic retention is a cosine)."""


def check_table(path: str | Path, tasks: list[str]) -> list[str]:
    """Problems of the table (empty if it is sane): a registry method without a row, a task
    without seeds, a rate out of its range, success above completion or success + collision
    above 1 (success is completion without collision), MinCl negative or not a finite
    distance of at most 1 m."""
    with open(path, newline="") as handle:
        rows = {row["method"]: row for row in csv.DictReader(handle)}
    problems = [f"missing row: {m}" for m in TABLE_ORDER if m not in rows]
    for (method, row), task in itertools.product(rows.items(), tasks):
        if int(row.get(f"{task}_seeds") or 0) < 1:
            problems.append(f"{method}: no {task} seeds")
            continue
        keys = (*LOWER_BOUNDS, "completion_rate", "min_clearance_p5")
        mean = {key: float(row[f"{task}_{key}_mean"]) for key in keys}
        success, collision = mean["success_rate"], mean["collision_rate"]
        clearance = mean["min_clearance_p5"]
        found = [
            f"{key} out of range: {mean[key]}"
            for key, low in LOWER_BOUNDS.items()
            if not low <= mean[key] <= 1.0
        ]
        if success > mean["completion_rate"] + 1e-9:
            found.append(f"success above completion: {success} > {mean['completion_rate']}")
        if success + collision > 1.0 + 1e-9:
            found.append(f"success + collision above 1: {round(success + collision, 6)}")
        if not math.isfinite(clearance) or abs(clearance) > 1.0:
            found.append(f"MinCl implausible: {clearance}")
        elif clearance < 0.0:
            found.append(f"MinCl negative: {clearance}")
        problems += [f"{method} {task} {text}" for text in found]
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
