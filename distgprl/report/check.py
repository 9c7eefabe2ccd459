"""Sanity check of a Table I CSV (used by CI after the reduced-size sweep).

`python -m distgprl.report.check TABLE.csv [--tasks dcp,dbm]`: every method of the
registry has a row, every task has at least one seed per row, rates lie in [0, 1], success
does not exceed completion and success + collision does not exceed 1 (success is
completion without collision), and MinCl is a finite, non-negative distance of plausible
size.
Exit code 1 with a line per problem.
"""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

from distgprl.data import TASK_NAMES
from distgprl.methods import TABLE_ORDER


def check_table(path: str | Path, tasks: list[str]) -> list[str]:
    """Problems found in the table (empty if it is sane)."""
    with open(path, newline="") as handle:
        rows = {row["method"]: row for row in csv.DictReader(handle)}
    problems = [f"missing row: {m}" for m in TABLE_ORDER if m not in rows]
    for method, row in rows.items():
        for task in tasks:
            if int(row.get(f"{task}_seeds") or 0) < 1:
                problems.append(f"{method}: no {task} seeds")
                continue
            for key in ("success_rate", "collision_rate", "mean_kinematic_retention"):
                value = float(row[f"{task}_{key}_mean"])
                if not (-1.0 <= value <= 1.0) or (key != "mean_kinematic_retention" and value < 0):
                    problems.append(f"{method} {task} {key} out of range: {value}")
            # success is completion without collision
            success = float(row[f"{task}_success_rate_mean"])
            collision = float(row[f"{task}_collision_rate_mean"])
            completed = float(row[f"{task}_completion_rate_mean"])
            if success > completed + 1e-9:
                problems.append(
                    f"{method} {task} success above completion: {success} > {completed}"
                )
            if success + collision > 1.0 + 1e-9:
                problems.append(
                    f"{method} {task} success + collision above 1: {round(success + collision, 6)}"
                )
            clearance = float(row[f"{task}_min_clearance_p5_mean"])
            if not math.isfinite(clearance) or abs(clearance) > 1.0:
                problems.append(f"{method} {task} MinCl implausible: {clearance}")
            elif clearance < 0.0:
                problems.append(f"{method} {task} MinCl negative: {clearance}")
    return problems


def main(argv: list[str]) -> int:
    if not argv:
        print("usage: python -m distgprl.report.check TABLE.csv [--tasks dcp,dbm]")
        return 2
    tasks = list(TASK_NAMES)
    if "--tasks" in argv:
        tasks = argv[argv.index("--tasks") + 1].split(",")
    problems = check_table(argv[0], tasks)
    for problem in problems:
        print(problem)
    print(f"{argv[0]}: {'OK' if not problems else f'{len(problems)} problem(s)'}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
