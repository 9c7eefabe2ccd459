"""Table I (simulation): one row per method (the paper's order, then the ablation and the
`demo` reference), per task each metric's mean ± sample std over seeds with its 95 %
t-interval (`aggregate`) and the IQM of success and collision with its stratified-bootstrap
interval (`IQM_METRICS`); and Table I per run (`per_seed_rows`).

Both are of one evaluation, the `Frames` they are given: by default the best learning-curve
policy's (`distgprl.report.runs.TABLE_POLICY`; protocol v6, rule 6, docs/findings/protocol.md),
or the final policy's beside it. MinCl is `COLLISION_FREE_MINCL` (rule 5); a cell at whose
seeds no trained policy beat the untrained one carries `UNTRAINED_MARK` (protocol v8, rule 2,
docs/findings/environment-v8.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
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
from distgprl.report.frame import COLLISION_FREE_MINCL, EVALUATION_KEYS, Frames, summaries
from distgprl.report.markdown import (
    csv_text,
    interval_text,
    latex_table,
    markdown_table,
    number_text,
)
from distgprl.report.runs import TABLE_POLICY

NO_POINTS = pd.DataFrame({"step": [], "success_rate": []})
"""The curve points of a run without a learning curve (an untrained reference)."""

METRICS = (
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
    (COLLISION_FREE_MINCL, "MinCl (m)"),
    ("min_clearance_p5", "MinCl all episodes (m)"),
    ("min_signed_clearance_p5", "SignedCl (m)"),
    ("completion_rate", "Completed"),
    ("mean_kinematic_retention", "KinRet"),
)
"""Columns per task: the paper's three — Success (the task completed without collision),
Collision, MinCl (`COLLISION_FREE_MINCL`) — then MinCl over all episodes (0 wherever 5 % or
more collide), the signed clearance's 5th percentile over all episodes (negative =
penetration depth, m), completion regardless of collision and kinematic retention."""

CLEARANCE_METRICS = (COLLISION_FREE_MINCL, "min_clearance_p5", "min_signed_clearance_p5")
"""Metrics in metres, shown to the millimetre."""

RATE_BOUNDS = (0.0, 1.0)
"""The range of a rate (metrics named ``*_rate``): their intervals are clipped to it."""

INTERVAL_METRICS = ("success_rate", "collision_rate")
"""Metrics whose Markdown and LaTeX cells also show the 95 % interval."""

IQM_METRICS = (("success_rate", "Success IQM"), ("collision_rate", "Collision IQM"))
"""Metrics with a column per task of the interquartile mean over seeds and its 95 %
stratified-bootstrap interval: the aggregates table's estimate (`method_estimate`, one
stratum: the task). In the CSV and the Markdown table, not the LaTeX one (the paper's
layout)."""

BEATS_UNTRAINED = "beats_untrained"
"""The best-policy summary field (`distgprl.experiments.policies.BestSelection`): whether the
selected trained curve point's curve success is above the untrained step-0 point's (true,
false; absent, or None, where unknown)."""

UNTRAINED_CURVE_SUCCESS = "untrained_curve_success_rate"
"""The best-policy summary field: the untrained step-0 point's curve success (curve TCs)."""

PER_SEED_EXTRA = (
    ("peak_joint_speed_p95", "PeakJS p95 (rad/s)"),
    ("joint_speed_over_limit_rate", "JS > limit"),
)
"""Per-run columns beyond Table I: the 95th percentile of the episodes' peak commanded joint
speed and the share of episodes above the hardware safety layer's joint speed limit."""

LATE_CURVE_POINTS = 5
"""How many of the last learning-curve evaluations `late_curve` averages."""

LATE_CURVE = (
    ("late_curve_success", "Late curve succ"),
    ("late_curve_success_range", "Late curve range"),
)
"""Per-run columns from ``progress.csv``: the mean curve success over the last
`LATE_CURVE_POINTS` evaluations (the preset's ``curve_episodes`` fixed TCs each,
deterministic policy of that step) and their max - min: how much the final policy's number
depends on where training stopped (empty for `demo`, which has no curve)."""

PER_SEED_COLUMNS = (*METRICS, *PER_SEED_EXTRA, *LATE_CURVE)
"""The metric columns of Table I per run, after its identifying columns."""

ALL_COLLIDED = "– (all collided)"
"""MinCl's text where every episode collided (of the run; of every seed, in Table I)."""

MINCL_NOTE = (
    "MinCl: 5th percentile of the episode-wise minimum clearance (robot links and tool vs "
    'obstacles, m) over the episodes without a collision (FINDINGS "Protocol v6", rule 5); '
    "(n=k): over the k seeds with a collision-free episode; "
    f"{ALL_COLLIDED}: every episode of every seed collided, so MinCl is undefined (not 0). "
    "MinCl all episodes: v5's, over every episode (a colliding one counts 0)"
)
"""The sentence under the Markdown Table I saying what MinCl is over."""

UNTRAINED_MARK = "†"
"""The mark of a best-policy cell (or run) where no trained policy beat the untrained one."""

_UNTRAINED_WHAT = (
    "no learning-curve point after the first SAC update had a higher curve success than the "
    "untrained step-0 policy (protocol v8, rule 2); the best trained policy is still reported"
)

UNTRAINED_NOTE = (
    f"{UNTRAINED_MARK} (untrained x, k of n seeds): no trained policy beat the untrained one "
    f"at k of the cell's n seeds: {_UNTRAINED_WHAT}, and x is the untrained policy's "
    "learning-curve success (curve TCs, not the evaluation TCs), mean over those k seeds"
)
"""The footnote of `UNTRAINED_MARK` under the Markdown and LaTeX Table I where it is used."""

UNTRAINED_RUN_NOTE = (
    f"{UNTRAINED_MARK} (untrained x): no trained policy beat the untrained one: "
    f"{_UNTRAINED_WHAT}, and x is the untrained policy's learning-curve success (curve TCs)"
)
"""The footnote of `UNTRAINED_MARK` under the Markdown Table I per run where it is used."""

POLICY_TITLES = {
    "best": "best learning-curve policy, Algorithm 1's output",
    "final": "final policy",
}
"""How a table's title names the evaluation it reports."""


@dataclass(frozen=True)
class Cell:
    """Aggregate of one metric over seeds: mean, sample std, 95 % t-interval, seed count."""

    mean: float
    std: float
    ci_low: float
    ci_high: float
    n: int

    def rate_interval(self) -> tuple[float, float]:
        """The interval clipped to `RATE_BOUNDS` (NaN stays NaN)."""
        return float(np.clip(self.ci_low, *RATE_BOUNDS)), float(np.clip(self.ci_high, *RATE_BOUNDS))

    def text(self, digits: int = 2, interval: bool = False) -> str:
        """``mean ± std`` (``mean`` for one seed, ``–`` for none); with ``interval`` and at
        least two seeds followed by the `rate_interval` ``[low, high]``."""
        if self.n < 2:
            return number_text(self.mean, digits)
        text = f"{self.mean:.{digits}f} ± {self.std:.{digits}f}"
        if interval:
            low, high = self.rate_interval()
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


@dataclass(frozen=True)
class UntrainedMarks:
    """The seeds of one Table I cell at which no trained policy beat the untrained one.

    Attributes:
        seeds: how many of the cell's seeds record ``beats_untrained`` false.
        untrained_curve_success: the mean over those seeds of the untrained step-0 point's
            learning-curve success (NaN where ``seeds`` is 0 or none records it).
    """

    seeds: int
    untrained_curve_success: float


def untrained_marks(summaries: list[dict[str, Any]]) -> UntrainedMarks:
    """`UntrainedMarks` of one cell's summaries (one per seed): only an explicit false
    ``beats_untrained`` counts; a missing one is unknown and not counted."""
    beaten = [s for s in summaries if s.get(BEATS_UNTRAINED) is False]
    figures = [
        float(s[UNTRAINED_CURVE_SUCCESS])
        for s in beaten
        if s.get(UNTRAINED_CURVE_SUCCESS) is not None
    ]
    return UntrainedMarks(len(beaten), float(np.mean(figures)) if figures else float("nan"))


def collect_scores(frames: Frames) -> Scores:
    """{(task, method): [`run_scores` per seed]} of ``frames`` (`load_frames`): the rates and
    learning-curve measures the aggregates and the claims bootstrap, from Table I's
    evaluations when ``frames`` are Table I's (the one switch, `TABLE_POLICY`)."""
    out: dict[tuple[str, str], list[dict[str, float]]] = {}
    for (task, method, seed, _), summary in summaries(frames.runs):
        points = frames.curves.get((task, method, seed), NO_POINTS)
        out.setdefault((task, method), []).append(run_scores(summary, points))
    return out


PER_SEED_SUMMARY: tuple[str, ...] = ("policy_step", BEATS_UNTRAINED, UNTRAINED_CURVE_SUCCESS)
PER_SEED_SUMMARY += ("collision_free_episodes", *(key for key, _ in METRICS + PER_SEED_EXTRA))
"""The summary fields Table I per run copies (empty where a summary does not record one)."""


def per_seed_rows(frames: Frames) -> list[dict[str, Any]]:
    """One row per run, in task, table order, seed: `EVALUATION_KEYS` (``policy``: ``best``,
    ``final`` or ``untrained``), `PER_SEED_SUMMARY` (for the best policy its learning-curve
    step and whether it beat the untrained step-0 point; the collision-free episodes MinCl is
    over), `late_curve`, the training wall time (``train_wall_min``, min) and process CPU
    time per RL step (``train_cpu_ms_per_step``, ms; both from ``done.json``, empty for
    `demo`), the training machine's ``numerics`` fingerprint (`distgprl.machine`) and the
    ``config_hash``."""
    rows = []
    for key, summary in summaries(frames.runs):
        row: dict[str, Any] = dict(zip(EVALUATION_KEYS, key, strict=True))
        row |= {name: summary.get(name, "") for name in PER_SEED_SUMMARY}
        row |= late_curve(frames.curves.get(key[:3], NO_POINTS))
        wall, cpu = summary.get("train_wall_time_s"), summary.get("cpu_s_per_step")
        row["train_wall_min"] = "" if wall is None else round(float(wall) / 60.0, 1)
        row["train_cpu_ms_per_step"] = "" if cpu is None else round(1e3 * float(cpu), 1)
        row |= {"numerics": summary["numerics"], "config_hash": summary["config_hash"]}
        rows.append(row)
    rows.sort(key=lambda r: (task_order(r["task"]), TABLE_ORDER.index(r["method"]), r["seed"]))
    return rows


def late_curve(points: pd.DataFrame) -> dict[str, float | str]:
    """`LATE_CURVE` values of one run's curve points (its rows of a `curves_of` frame; empty
    strings without a trained point among the last `LATE_CURVE_POINTS`)."""
    late = points.tail(LATE_CURVE_POINTS)
    success = late["success_rate"][late["step"] != 0].tolist()
    if not success:
        return {key: "" for key, _ in LATE_CURVE}
    return {
        "late_curve_success": float(np.mean(success)),
        "late_curve_success_range": float(max(success) - min(success)),
    }


def simulation_table(
    frames: Frames, order: tuple[str, ...] = TABLE_ORDER
) -> tuple[list[dict[str, Any]], list[str]]:
    """Rows of Table I of ``frames``' evaluations, one per method of ``order`` with runs (in
    that order), and the tasks.
    Per task: ``<task>_seeds``, a `Cell` per `METRICS` key (``<task>_<key>``),
    ``<task>_all_collided_seeds`` (seeds whose every episode collided), ``<task>_untrained``
    (`UntrainedMarks`) and an `Estimate` per `IQM_METRICS` key (``<task>_<key>_iqm``)."""
    by_cell: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for (task, method, _, _), summary in summaries(frames.runs):
        by_cell.setdefault((task, method), []).append(summary)
    tasks = sorted({task for task, _ in by_cell}, key=task_order)
    rows = []
    for method in order:
        if not any((task, method) in by_cell for task in tasks):
            continue
        row: dict[str, Any] = {"method": method, "label": METHODS[method].label}
        for task in tasks:
            seeds = by_cell.get((task, method), [])
            row[f"{task}_seeds"] = len(seeds)
            for key, _ in METRICS:
                row[f"{task}_{key}"] = aggregate(
                    [float(s[key]) for s in seeds if s.get(key) is not None]
                )
            row[f"{task}_all_collided_seeds"] = sum(
                s.get("collision_free_episodes") == 0 for s in seeds
            )
            row[f"{task}_untrained"] = untrained_marks(seeds)
            scores = {(task, method): [{k: float(s[k]) for k, _ in IQM_METRICS} for s in seeds]}
            for key, _ in IQM_METRICS:
                row[f"{task}_{key}_iqm"] = method_estimate(
                    scores, [task], method, key, "iqm", BOOTSTRAP_SEED
                )
        rows.append(row)
    return rows, tasks


def untrained_text(marks: UntrainedMarks, seeds: int) -> str:
    """`` † (untrained 0.68, 5 of 5 seeds)`` where ``marks`` counts seeds (of the cell's
    ``seeds``) at which no trained policy beat the untrained one; empty otherwise."""
    if marks.seeds == 0:
        return ""
    figure = number_text(marks.untrained_curve_success, 2)
    return f" {UNTRAINED_MARK} (untrained {figure}, {marks.seeds} of {seeds} seeds)"


def _task_cells(row: dict[str, Any], task: str, markdown: bool) -> list[str]:
    """``row``'s `METRICS` cells of ``task`` as Markdown and LaTeX show them: rates with their
    interval; MinCl with ``(n=k)`` where only k of the seeds have one and `ALL_COLLIDED`
    where none has; the Success cell followed by its `untrained_text`. In ``markdown`` also
    the seed count in brackets after Success, and the `IQM_METRICS` cells."""
    seeds, collided = row[f"{task}_seeds"], row[f"{task}_all_collided_seeds"]
    cells = []
    for key, _ in METRICS:
        cell: Cell = row[f"{task}_{key}"]
        text = cell.text(3 if key in CLEARANCE_METRICS else 2, interval=key in INTERVAL_METRICS)
        if key == COLLISION_FREE_MINCL and cell.n == 0 and seeds and collided == seeds:
            text = ALL_COLLIDED
        elif key == COLLISION_FREE_MINCL and 0 < cell.n < seeds:
            text += f" (n={cell.n})"
        cells.append(text)
    cells[0] += f" [{seeds}]" if seeds and markdown else ""
    cells[0] += untrained_text(row[f"{task}_untrained"], seeds)
    estimates = [row[f"{task}_{key}_iqm"] for key, _ in IQM_METRICS] if markdown else []
    return cells + [interval_text(e.point, e.low, e.high) for e in estimates]


def per_seed_texts(rows: list[dict[str, Any]], preset: str, policy: str) -> tuple[str, str]:
    """(CSV, Markdown) of `per_seed_rows` of the ``policy`` evaluations."""
    fields = [*EVALUATION_KEYS, *PER_SEED_SUMMARY, *(key for key, _ in LATE_CURVE)]
    fields += ["train_wall_min", "train_cpu_ms_per_step", "numerics", "config_hash"]
    header = ["Task", "Method", "Seed", "Policy", "Collision-free episodes"]
    header += [*(label for _, label in PER_SEED_COLUMNS), "Train wall (min)", "Train CPU (ms/step)"]
    table = []
    for row in rows:
        step, free = row["policy_step"], row["collision_free_episodes"]
        cells = [row["task"].upper(), METHODS[row["method"]].label, str(row["seed"])]
        cells.append(row["policy"] + ("" if step == "" else f" (step {step})"))
        if row[BEATS_UNTRAINED] is False:  # the best policy did not beat the untrained one
            cells[-1] += (
                f" {UNTRAINED_MARK} (untrained {number_text(row[UNTRAINED_CURVE_SUCCESS], 2)})"
            )
        cells.append(str(free) or "–")
        for key, _ in PER_SEED_COLUMNS:
            all_collided = row[key] == "" and key == COLLISION_FREE_MINCL and free == 0
            cells.append(
                ALL_COLLIDED
                if all_collided
                else number_text(row[key], 3 if key in CLEARANCE_METRICS else 2)
            )
        cells += [number_text(row[key], 1) for key in ("train_wall_min", "train_cpu_ms_per_step")]
        table.append(cells)
    title = f"Table I per run ({preset} preset, {POLICY_TITLES[policy]})"
    marked = any(row.get(BEATS_UNTRAINED) is False for row in rows)
    note = f"\n{UNTRAINED_RUN_NOTE}.\n" if marked else ""
    return csv_text(rows, fields), markdown_table(title, header, table) + note


def _csv_cells(row: dict[str, Any], task: str) -> dict[str, Any]:
    """One row's CSV cells of ``task``: ``<task>_seeds``; per `METRICS` key its Cell's
    ``_mean``, ``_std``, ``_ci_low``, ``_ci_high`` (a rate's interval clipped,
    `Cell.rate_interval`); ``<task>_<COLLISION_FREE_MINCL>_seeds`` (the seeds MinCl is over:
    those with a collision-free episode); ``<task>_all_collided_seeds``;
    ``<task>_untrained_best_seeds`` and ``<task>_untrained_curve_success_mean`` (the
    `UntrainedMarks`; NaN: none); per `IQM_METRICS` key the `Estimate`'s ``_iqm``,
    ``_iqm_low``, ``_iqm_high`` (NaN without runs or interval)."""
    out = {f"{task}_seeds": row[f"{task}_seeds"]}
    for key, _ in METRICS:
        cell: Cell = row[f"{task}_{key}"]
        low, high = cell.rate_interval() if key.endswith("_rate") else (cell.ci_low, cell.ci_high)
        parts = {"mean": cell.mean, "std": cell.std, "ci_low": low, "ci_high": high}
        out |= {f"{task}_{key}_{part}": value for part, value in parts.items()}
    marks: UntrainedMarks = row[f"{task}_untrained"]
    out[f"{task}_{COLLISION_FREE_MINCL}_seeds"] = row[f"{task}_{COLLISION_FREE_MINCL}"].n
    out[f"{task}_all_collided_seeds"] = row[f"{task}_all_collided_seeds"]
    out[f"{task}_untrained_best_seeds"] = marks.seeds
    out[f"{task}_untrained_curve_success_mean"] = marks.untrained_curve_success
    for key, _ in IQM_METRICS:
        iqm: Estimate = row[f"{task}_{key}_iqm"]
        parts = {"iqm": iqm.point, "iqm_low": iqm.low, "iqm_high": iqm.high}
        out |= {f"{task}_{key}_{part}": value for part, value in parts.items()}
    return out


def _markdown(
    rows: list[dict[str, Any]],
    tasks: list[str],
    note: str,
    marked: bool,
    heading: str,
) -> str:
    header = ["Method"]
    for t in tasks:
        header += [f"{t.upper()} {name}" for _, name in METRICS + IQM_METRICS]
    table = [
        [row["label"], *(text for task in tasks for text in _task_cells(row, task, True))]
        for row in rows
    ]
    title = (
        f"{heading}: mean ± std over seeds (seeds "
        "per cell in brackets after Success); Success and Collision also give the 95 % "
        "t-interval over seeds, [low, high] clipped to [0, 1], where there are two or more "
        "seeds; the IQM columns give the interquartile mean over seeds with its 95 % "
        f"stratified-bootstrap interval ({BOOTSTRAP_REPS} replicates)"
    )
    notes = "".join(
        f"\n{text}.\n" for text in (MINCL_NOTE, UNTRAINED_NOTE if marked else "", note) if text
    )
    return markdown_table(title, header, table) + notes


def _latex(
    rows: list[dict[str, Any]], tasks: list[str], preset: str, policy: str, marked: bool
) -> str:
    caption = (
        f"Simulation results ({preset} preset, {POLICY_TITLES[policy]}), mean "
        "$\\pm$ std over seeds; Success and Collision also give the 95\\,\\% t-interval over "
        "seeds [low, high], clipped to [0, 1], where there are two or more seeds; MinCl over "
        "the episodes without a collision, (n=k) over the k seeds that have one"
    )
    spans = (f"\\multicolumn{{{len(METRICS)}}}{{c}}{{{t.upper()}}}" for t in tasks)
    header = [" & " + " & ".join(spans)]
    header.append("Method & " + " & ".join(name for _ in tasks for _, name in METRICS))
    table = [
        [row["label"].replace("_", "\\_")]
        + [text for task in tasks for text in _task_cells(row, task, False)]
        for row in rows
    ]
    label = "tab:sim_results" if policy == TABLE_POLICY else f"tab:sim_results_{policy}"
    columns = "l" + "c" * (len(tasks) * len(METRICS))
    footnote = f"{UNTRAINED_NOTE}." if marked else ""
    return latex_table(caption, label, columns, header, table, footnote)


def table1_texts(
    rows: list[dict[str, Any]],
    tasks: list[str],
    preset: str,
    note: str,
    policy: str,
    heading: str | None = None,
) -> tuple[str, str, str]:
    """(CSV, Markdown, LaTeX) of Table I from `simulation_table`'s rows and tasks of the
    ``policy`` evaluations; ``note`` (the runs left out or substituted, `run_evaluations`)
    goes under the Markdown table, after `MINCL_NOTE` (and `UNTRAINED_NOTE` where a cell is
    marked). ``heading`` opens the Markdown's title (default: ``Table I (<preset> preset,
    <policy>)``)."""
    heading = heading or f"Table I ({preset} preset, {POLICY_TITLES[policy]})"
    marked = any(row[f"{task}_untrained"].seeds > 0 for row in rows for task in tasks)
    fields = ["method", "label", *(k for task in tasks for k in _csv_cells(rows[0], task))]
    table = [
        row | {k: v for task in tasks for k, v in _csv_cells(row, task).items()} for row in rows
    ]
    return (
        csv_text(table, fields, significant=6),
        _markdown(rows, tasks, note, marked, heading),
        _latex(rows, tasks, preset, policy, marked),
    )
