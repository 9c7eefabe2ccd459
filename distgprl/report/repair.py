"""Table I + repair: what the hardware safety layer costs and saves in simulation.

From the runs of the current configuration (`select_runs`) whose folders hold the
evaluations with the safety layer in the loop in both sweep modes (``check``: refuse every
unsafe window at once; ``repair``: re-time what is too fast, then refuse what is still
unsafe; `distgprl.experiments.repair_follow_ups`), one row per task and method pooling the
seeds that have both, beside the plain evaluation of the same seeds and TCs:

- Success / Collision (plain, check, repair) and Refused (check, repair): means over those
  seeds of the per-run rates on the evaluation TCs (a refused episode is neither a success
  nor a collision);
- Retimed: the share of executed-or-refused windows the repair re-timed; Added: mean time
  added per episode (s);
- TC by TC against the plain evaluation, summed over the seeds: *gained* (plain failed,
  repair succeeded), *lost* (plain succeeded, repair did not: refused, or the re-timed
  motion failed) and *averted* (plain collided, repair did not).

An evaluation whose recorded config hash is not its run's, or whose TCs differ from the plain
evaluation's, is left out of the row and listed under the table.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import groupby
from pathlib import Path
from typing import Any

from distgprl.data import task_order
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.markdown import csv_text, markdown_table
from distgprl.report.runs import select_runs
from distgprl.schema import (
    EVALUATION_FIELDS,
    evaluation_file_names,
    is_safe_success,
    read_csv,
    read_json,
    repair_evaluation_file_names,
)

MODES = ("check", "repair")
"""The sweep's modes (`distgprl.experiments.repair_follow_ups.SWEEP_REPAIR_MODES`)."""

OUTCOMES = ("success", "collision", "refused")
"""One TC's outcomes, each a bool: safe success (`is_safe_success`), collision, refused."""

FIELDS = tuple(
    "task method seeds n_seeds episodes plain_success plain_collision check_success "
    "check_collision check_refused repair_success repair_collision repair_refused "
    "repair_retimed_windows repair_time_added_s gained lost averted".split()
)


@dataclass(frozen=True)
class RunOutcomes:
    """One run's `OUTCOMES` per TC in the plain evaluation (never refused) and each of
    `MODES` (``outcomes``), and its repair evaluation's summary."""

    task: str
    method: str
    seed: int
    outcomes: dict[str, list[tuple[bool, bool, bool]]]
    repair_summary: dict[str, Any]


def _tc(row: dict[str, str]) -> tuple[float, ...]:
    """A row's TC: its episode index and offsets (m), the columns both evaluations share."""
    return tuple(round(float(row[name]), 9) for name in EVALUATION_FIELDS[:5])


def _outcomes(rows: list[dict[str, str]]) -> list[tuple[bool, bool, bool]]:
    """`OUTCOMES` of each row (a row without a ``refused`` column was not refused)."""
    return [(is_safe_success(row), _flag(row, "collision"), _flag(row, "refused")) for row in rows]


def _flag(row: dict[str, str], column: str) -> bool:
    return int(float(row.get(column, "0"))) == 1


def collect(root: str | Path, preset: str) -> tuple[list[RunOutcomes], list[str]]:
    """The runs with both modes' evaluations of their configuration, and one line per
    evaluation left out (its run and why)."""
    runs, excluded = [], []
    for folder in sorted(select_runs(root, preset).current):
        task, method, seed = folder.parts[-3:]
        paths = {
            m: [folder / f for f in repair_evaluation_file_names(None, "final", m)] for m in MODES
        }
        if method not in METHODS or not all(summary.exists() for _, summary in paths.values()):
            continue
        current = read_json(folder / "config.json").get("config_hash")
        _, plain_rows = read_csv(folder / evaluation_file_names()[0])
        outcomes, reason = {"plain": _outcomes(plain_rows)}, ""
        for mode, (csv_path, _) in paths.items():
            meta, rows = read_csv(csv_path)
            if meta.get("config_hash") != current:
                reason = (
                    f"{mode} evaluation of config hash {meta.get('config_hash')}, not the run's"
                )
            elif [_tc(r) for r in rows] != [_tc(r) for r in plain_rows]:
                reason = f"{mode} evaluation on other TCs than the plain one"
            if reason:
                excluded.append(f"{task}/{method}/{seed} ({reason})")
                break
            outcomes[mode] = _outcomes(rows)
        else:
            summary = read_json(paths["repair"][1])["summary"]
            runs.append(
                RunOutcomes(task, method, int(seed.removeprefix("seed")), outcomes, summary)
            )
    return runs, excluded


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)


def _row(group: list[RunOutcomes]) -> dict[str, Any]:
    """The `FIELDS` row of one task and method's runs (module docstring), by seed."""
    group = sorted(group, key=lambda r: r.seed)
    row: dict[str, Any] = {"task": group[0].task, "method": group[0].method}
    row["seeds"] = " ".join(str(r.seed) for r in group)
    row["n_seeds"], row["episodes"] = len(group), sum(len(r.outcomes["plain"]) for r in group)
    for mode in ("plain", *MODES):
        for index, name in enumerate(OUTCOMES[: 2 if mode == "plain" else 3]):
            rates = [sum(o[index] for o in r.outcomes[mode]) / len(r.outcomes[mode]) for r in group]
            row[f"{mode}_{name}"] = _mean(rates)
    summaries = [r.repair_summary for r in group]
    windows = sum(
        s[f"windows_{kind}"] for s in summaries for kind in ("none", "retimed", "refused")
    )
    row["repair_retimed_windows"] = sum(s["windows_retimed"] for s in summaries) / max(windows, 1)
    row["repair_time_added_s"] = _mean([s["mean_time_added_s"] for s in summaries])
    pairs = [p for r in group for p in zip(r.outcomes["plain"], r.outcomes["repair"], strict=True)]
    row["gained"] = sum(not p[0] and q[0] for p, q in pairs)
    row["lost"] = sum(p[0] and not q[0] for p, q in pairs)
    row["averted"] = sum(p[1] and not q[1] for p, q in pairs)
    return row


def repair_table(root: str | Path, preset: str) -> tuple[list[dict[str, Any]], list[str]]:
    """One row of :data:`FIELDS` per task and method (module docstring) of the runs
    `collect` finds, in table order, and what it left out."""
    runs, excluded = collect(root, preset)
    runs.sort(key=lambda r: (task_order(r.task), TABLE_ORDER.index(r.method), r.task))
    groups = groupby(runs, key=lambda r: (r.task, r.method))
    return [_row(list(group)) for _, group in groups], excluded


def repair_texts(
    rows: list[dict[str, Any]], preset: str, excluded: list[str]
) -> tuple[str, str] | None:
    """(CSV, Markdown) of `repair_table`'s rows; None if there are no rows."""
    if not rows:
        return None
    rounded = [
        {k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()} for r in rows
    ]
    header = ["Task", "Method", "Seeds", "Plain S / C", "Check S / C / R", "Repair S / C / R"]
    header += ["Retimed", "Added (s)", "Gained / lost / averted"]
    table = [
        [
            row["task"].upper(),
            METHODS[row["method"]].label,
            row["seeds"],
            f"{row['plain_success']:.2f} / {row['plain_collision']:.2f}",
            *(" / ".join(f"{row[f'{mode}_{k}']:.2f}" for k in OUTCOMES) for mode in MODES),
            f"{row['repair_retimed_windows']:.2f}",
            f"{row['repair_time_added_s']:.2f}",
            f"{row['gained']} / {row['lost']} / {row['averted']}",
        ]
        for row in rows
    ]
    title = (
        f"Table I + repair ({preset} preset, simulation): the hardware safety layer in the loop "
        "on the evaluation TCs; S success, C collision, R refused (means over the seeds listed); "
        "Check refuses every unsafe window, Repair re-times what is too fast and refuses what is "
        "still unsafe; Retimed: share of windows re-timed; Added: mean time added per episode; "
        "gained / lost / averted: TCs (summed over seeds) where Repair succeeds and plain did "
        "not / plain succeeded and Repair does not / plain collided and Repair does not"
    )
    markdown = markdown_table(title, header, table)
    if excluded:
        markdown += f"\nNot tabulated ({len(excluded)}): " + "; ".join(excluded) + "\n"
    return csv_text(rounded, FIELDS), markdown
