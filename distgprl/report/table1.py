"""Table I (simulation) from the runs' ``summary.json`` files: one row per method, per task
each metric's mean ± sample standard deviation (ddof = 1) over seeds with a 95 % confidence
interval (Student t over seeds; a single seed has neither), the IQM of success and collision
with its stratified-bootstrap interval (`IQM_METRICS`), and Table I per run.

The CSV has all four numbers of every cell. The Markdown and LaTeX tables show the interval,
as ``0.88 ± 0.06 [0.73, 1.00]``, on the Success and Collision columns only (the table is
copied into the README, and ten columns of intervals would make it unreadable); their
caption says so. Those displayed intervals, and the CSV's intervals of every rate
(`RATE_BOUNDS`), are clipped to [0, 1], the range of a rate; cells of a single seed stay
``mean`` and the seed count follows the Success cell in brackets, e.g. ``[3]``. Rows follow
the paper's order, then the ablation and the `demo` reference. Pure functions of the files
they read.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from distgprl.data import task_order
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.aggregate import (
    BOOTSTRAP_REPS,
    BOOTSTRAP_SEED,
    Estimate,
    Scores,
    method_estimate,
    run_scores,
)
from distgprl.report.markdown import markdown_table as _markdown_table
from distgprl.report.runs import select_runs
from distgprl.schema import read_csv, read_json

METRICS = (
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
    ("min_clearance_p5", "MinCl (m)"),
    ("min_signed_clearance_p5", "SignedCl (m)"),
    ("completion_rate", "Completed"),
    ("mean_kinematic_retention", "KinRet"),
)
"""Columns per task (environment v5): the paper's three — Success (the task completed without
collision), Collision, MinCl (5th percentile of the episodes' minimum clearance, a distance
>= 0) — then three it does not tabulate: the signed clearance's 5th percentile (negative =
penetration depth), completion regardless of collision (v4's Success) and kinematic
retention."""

CLEARANCE_METRICS = ("min_clearance_p5", "min_signed_clearance_p5")
"""Metrics in metres, shown to the millimetre."""

RATE_BOUNDS = (0.0, 1.0)
"""The range of a rate (metrics named ``*_rate``): their CSV intervals are clipped to it."""

INTERVAL_METRICS = ("success_rate", "collision_rate")
"""Metrics whose Markdown and LaTeX cells also show the 95 % interval (clipped to [0, 1])."""

IQM_METRICS = (("success_rate", "Success IQM"), ("collision_rate", "Collision IQM"))
"""Metrics with a robust-aggregate column per task (issue 33): the interquartile mean over
seeds with its 95 % stratified-bootstrap interval, the same estimate (same generator) as the
aggregates table's (`distgprl.report.aggregate.method_estimate`, one stratum: the task). In
the CSV and the Markdown table; the LaTeX table keeps the paper's layout."""


def cell_text(cell: Cell, key: str) -> str:
    """A Table I cell as the Markdown and LaTeX tables show it."""
    if key in INTERVAL_METRICS:
        return cell.text(2, interval=True, bounds=(0.0, 1.0))
    return cell.text(3 if key in CLEARANCE_METRICS else 2)


@dataclass(frozen=True)
class Cell:
    """Aggregate of one metric over seeds."""

    mean: float
    std: float
    ci_low: float
    ci_high: float
    n: int

    def text(
        self, digits: int = 2, interval: bool = False, bounds: tuple[float, float] | None = None
    ) -> str:
        """``mean ± std`` (``mean`` for one seed, ``–`` for none); with ``interval`` and at
        least two seeds followed by the 95 % interval ``[low, high]``, clipped to ``bounds``
        if given."""
        if self.n == 0:
            return "–"
        if self.n == 1:
            return f"{self.mean:.{digits}f}"
        text = f"{self.mean:.{digits}f} ± {self.std:.{digits}f}"
        if interval:
            low, high = self.ci_low, self.ci_high
            if bounds is not None:
                low, high = max(low, bounds[0]), min(high, bounds[1])
            text += f" [{low:.{digits}f}, {high:.{digits}f}]"
        return text


def aggregate(values: list[float]) -> Cell:
    """Mean, sample std and 95 % t-interval over seeds."""
    array = np.asarray(values, dtype=float)
    n = len(array)
    if n == 0:
        return Cell(np.nan, np.nan, np.nan, np.nan, 0)
    mean = float(array.mean())
    if n == 1:
        return Cell(mean, 0.0, np.nan, np.nan, 1)
    std = float(array.std(ddof=1))
    half = float(stats.t.ppf(0.975, n - 1) * std / np.sqrt(n))
    return Cell(mean, std, mean - half, mean + half, n)


def summary_paths(root: Path, preset: str) -> list[Path]:
    """The ``summary.json`` files of the runs that count (`select_runs`)."""
    current = select_runs(root, preset).current
    return sorted(
        path
        for path in (Path(root) / preset).glob("*/*/seed*/summary.json")
        if path.parent in current
    )


def collect_summaries(root: Path, preset: str) -> dict[tuple[str, str], list[dict[str, Any]]]:
    """{(task, method): [summary per seed]} from ``<root>/<preset>/<task>/<method>/seed*/``."""
    out: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for path in summary_paths(root, preset):
        task, method = path.parts[-4], path.parts[-3]
        out.setdefault((task, method), []).append(read_json(path)["summary"])
    return out


def collect_scores(root: str | Path, preset: str) -> Scores:
    """{(task, method): [`run_scores` per seed]} of the runs `collect_summaries` reads: the
    rates and learning-curve measures the aggregates and the claims table bootstrap."""
    out: dict[tuple[str, str], list[dict[str, float]]] = {}
    for path in summary_paths(Path(root), preset):
        task, method = path.parts[-4], path.parts[-3]
        summary = read_json(path)["summary"]
        out.setdefault((task, method), []).append(run_scores(path.parent, summary))
    return out


def per_seed_rows(root: str | Path, preset: str) -> list[dict[str, Any]]:
    """One row per run: task, method, seed, the Table I metrics, the training wall time
    (min) and process CPU time per RL step (ms, both from ``done.json``; empty for `demo` and
    for runs made before it was recorded), the numerics fingerprint of the machine that
    trained it (`distgprl.machine`; empty before it was recorded) and the config hash. Task,
    table order, seed."""
    rows = []
    for path in summary_paths(Path(root), preset):
        task, method, seed = path.parts[-4], path.parts[-3], path.parts[-2]
        if method not in METHODS:
            continue
        document = read_json(path)
        summary = document["summary"]
        done = path.parent / "done.json"
        done_document = read_json(done) if done.exists() else {}
        wall = done_document.get("train_wall_time_s")
        cpu = done_document.get("cpu_s_per_step")
        row: dict[str, Any] = {
            "task": task,
            "method": method,
            "seed": int(seed.removeprefix("seed")),
        }
        row.update({key: summary.get(key, "") for key, _ in (*METRICS, *PER_SEED_EXTRA)})
        row.update(late_curve(path.parent / "progress.csv"))
        row["train_wall_min"] = "" if wall is None else round(float(wall) / 60.0, 1)
        row["train_cpu_ms_per_step"] = "" if cpu is None else round(1e3 * float(cpu), 1)
        machine = (done_document.get("meta") or {}).get("machine") or {}
        row["numerics"] = machine.get("numerics", "")
        row["config_hash"] = document["meta"].get("config_hash", "")
        rows.append(row)
    rows.sort(key=lambda r: (task_order(r["task"]), TABLE_ORDER.index(r["method"]), r["seed"]))
    return rows


PER_SEED_EXTRA = (
    ("peak_joint_speed_p95", "PeakJS p95 (rad/s)"),
    ("joint_speed_over_limit_rate", "JS > limit"),
)
"""Per-run columns beyond Table I: the 95th percentile of the episodes' peak commanded joint
speed and the share of episodes above the hardware safety layer's joint speed limit (empty
for evaluations written before they were recorded)."""


LATE_CURVE_POINTS = 5
"""How many of the last learning-curve evaluations `late_curve` averages."""

LATE_CURVE = (
    ("late_curve_success", "Late curve succ"),
    ("late_curve_success_range", "Late curve range"),
)
"""Per-run columns from ``progress.csv``: the mean learning-curve success over the last
`LATE_CURVE_POINTS` evaluations (the preset's ``curve_episodes`` fixed TCs each, 50 in
`paper` since environment v5; deterministic policy of that step) and their max - min. Next
to the final 100-TC success they show how much the final policy's number depends on where
training stopped (empty for `demo`, which has no curve)."""


def late_curve(path: Path) -> dict[str, float | str]:
    """`LATE_CURVE` values of one run's ``progress.csv`` (empty strings if it has none)."""
    empty: dict[str, float | str] = {key: "" for key, _ in LATE_CURVE}
    if not path.exists():
        return empty
    _, rows = read_csv(path)
    success = [float(r["success_rate"]) for r in rows[-LATE_CURVE_POINTS:] if r["step"] != "0"]
    if not success:
        return empty
    return {
        "late_curve_success": float(np.mean(success)),
        "late_curve_success_range": float(max(success) - min(success)),
    }


def per_seed_texts(rows: list[dict[str, Any]], preset: str) -> tuple[str, str]:
    """(CSV, Markdown) of `per_seed_rows`."""
    columns = (*METRICS, *PER_SEED_EXTRA, *LATE_CURVE)
    fields = ["task", "method", "seed", *(key for key, _ in columns), "train_wall_min"]
    fields += ["train_cpu_ms_per_step", "numerics", "config_hash"]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    header = [
        "Task",
        "Method",
        "Seed",
        *(label for _, label in columns),
        "Train wall (min)",
        "Train CPU (ms/step)",
    ]
    table = []
    for row in rows:
        cells = [row["task"].upper(), METHODS[row["method"]].label, str(row["seed"])]
        for key, _ in columns:
            value = row[key]
            digits = 3 if key in CLEARANCE_METRICS else 2
            cells.append("–" if value == "" else f"{float(value):.{digits}f}")
        for key in ("train_wall_min", "train_cpu_ms_per_step"):
            cells.append("–" if row[key] == "" else f"{row[key]:.1f}")
        table.append(cells)
    return buffer.getvalue(), _markdown_table(f"Table I per run ({preset} preset)", header, table)


def simulation_table(root: str | Path, preset: str) -> tuple[list[dict[str, Any]], list[str]]:
    """Rows of Table I: one per (method), columns per task and metric."""
    summaries = collect_summaries(Path(root), preset)
    tasks = sorted({task for task, _ in summaries}, key=task_order)
    rows = []
    for method in TABLE_ORDER:
        if not any((task, method) in summaries for task in tasks):
            continue
        row: dict[str, Any] = {"method": method, "label": METHODS[method].label}
        for task in tasks:
            seeds = summaries.get((task, method), [])
            row[f"{task}_seeds"] = len(seeds)
            for key, _ in METRICS:
                row[f"{task}_{key}"] = aggregate([s[key] for s in seeds if key in s])
            scores = {(task, method): [{k: float(s[k]) for k, _ in IQM_METRICS} for s in seeds]}
            for key, _ in IQM_METRICS:
                row[f"{task}_{key}_iqm"] = method_estimate(
                    scores, [task], method, key, "iqm", BOOTSTRAP_SEED
                )
        rows.append(row)
    return rows, tasks


def _csv_text(rows: list[dict[str, Any]], tasks: list[str]) -> str:
    buffer = io.StringIO()
    fields = ["method", "label"]
    for task in tasks:
        fields.append(f"{task}_seeds")
        for key, _ in METRICS:
            fields += [f"{task}_{key}_{part}" for part in ("mean", "std", "ci_low", "ci_high")]
        for key, _ in IQM_METRICS:
            fields += [f"{task}_{key}_{part}" for part in ("iqm", "iqm_low", "iqm_high")]
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        out = {"method": row["method"], "label": row["label"]}
        for task in tasks:
            out[f"{task}_seeds"] = row.get(f"{task}_seeds", 0)
            for key, _ in METRICS:
                cell = row.get(f"{task}_{key}", aggregate([]))
                for part in ("mean", "std", "ci_low", "ci_high"):
                    value = getattr(cell, part)
                    if part.startswith("ci_") and key.endswith("_rate"):
                        value = float(np.clip(value, *RATE_BOUNDS))  # NaN stays NaN
                    out[f"{task}_{key}_{part}"] = "" if np.isnan(value) else f"{value:.6g}"
            for key, _ in IQM_METRICS:
                estimate = row.get(f"{task}_{key}_iqm")
                parts = (np.nan,) * 3 if estimate is None else _iqm_parts(estimate)
                for part, value in zip(("iqm", "iqm_low", "iqm_high"), parts, strict=True):
                    out[f"{task}_{key}_{part}"] = "" if np.isnan(value) else f"{value:.6g}"
        writer.writerow(out)
    return buffer.getvalue()


def _iqm_parts(estimate: Estimate) -> tuple[float, float, float]:
    """(IQM, low, high) of an estimate; NaN where it has no runs or no interval."""
    if not estimate.seeds:
        return (np.nan, np.nan, np.nan)
    if not estimate.has_interval:
        return (estimate.point, np.nan, np.nan)
    return (estimate.point, estimate.low, estimate.high)


def _iqm_text(estimate: Estimate | None) -> str:
    """``0.88 [0.80, 0.95]``, the IQM alone for one seed, ``–`` without runs."""
    if estimate is None or not estimate.seeds:
        return "–"
    if not estimate.has_interval:
        return f"{estimate.point:.2f}"
    return f"{estimate.point:.2f} [{estimate.low:.2f}, {estimate.high:.2f}]"


def _markdown(rows: list[dict[str, Any]], tasks: list[str], preset: str, note: str = "") -> str:
    header = ["Method"]
    for t in tasks:
        header += [f"{t.upper()} {name}" for _, name in METRICS]
        header += [f"{t.upper()} {name}" for _, name in IQM_METRICS]
    table = []
    for row in rows:
        cells = [row["label"]]
        for task in tasks:
            n = row.get(f"{task}_seeds", 0)
            for index, (key, _) in enumerate(METRICS):
                text = cell_text(row.get(f"{task}_{key}", aggregate([])), key)
                cells.append(f"{text} [{n}]" if index == 0 and n else text)
            cells += [_iqm_text(row.get(f"{task}_{key}_iqm")) for key, _ in IQM_METRICS]
        table.append(cells)
    title = (
        f"Table I ({preset} preset): mean ± std over seeds (seeds per cell in brackets after "
        "Success); Success and Collision also give the 95 % t-interval over seeds, "
        "[low, high] clipped to [0, 1], where there are two or more seeds; the IQM columns "
        "give the interquartile mean over seeds with its 95 % stratified-bootstrap interval "
        f"({BOOTSTRAP_REPS} replicates)"
    )
    return _markdown_table(title, header, table) + (f"\n{note}.\n" if note else "")


def _latex(rows: list[dict[str, Any]], tasks: list[str], preset: str) -> str:
    columns = "l" + "c" * (len(tasks) * len(METRICS))
    lines = [
        "\\begin{table}[htb]",
        "\\centering",
        f"\\caption{{Simulation results ({preset} preset), mean $\\pm$ std over seeds; "
        "Success and Collision also give the 95\\,\\% t-interval over seeds [low, high], "
        "clipped to [0, 1], where there are two or more seeds}",
        "\\label{tab:sim_results}",
        f"\\begin{{tabular}}{{{columns}}}",
        "\\toprule",
        " & "
        + " & ".join(f"\\multicolumn{{{len(METRICS)}}}{{c}}{{{t.upper()}}}" for t in tasks)
        + " \\\\",
        "Method & " + " & ".join(name for _ in tasks for _, name in METRICS) + " \\\\",
        "\\midrule",
    ]
    for row in rows:
        cells = [row["label"].replace("_", "\\_")]
        for task in tasks:
            for key, _ in METRICS:
                text = cell_text(row.get(f"{task}_{key}", aggregate([])), key)
                cells.append(text.replace("±", "$\\pm$"))
        lines.append(" & ".join(cells) + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}", "\\end{table}", ""]
    return "\n".join(lines)


def table1_texts(
    rows: list[dict[str, Any]], tasks: list[str], preset: str, note: str = ""
) -> tuple[str, str, str]:
    """(CSV, Markdown, LaTeX) of Table I from `simulation_table`'s rows and tasks; ``note``
    (the runs left out, `select_runs`) goes under the Markdown table."""
    return _csv_text(rows, tasks), _markdown(rows, tasks, preset, note), _latex(rows, tasks, preset)
