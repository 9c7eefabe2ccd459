"""The texts of Table I (`distgprl.report.table1`): CSV, Markdown and LaTeX of the table over
seeds, CSV and Markdown of the table per run, for the best or the final policy's evaluations.

The CSV has all four numbers of every cell. The Markdown and LaTeX tables show the interval,
as ``0.88 ± 0.06 [0.73, 1.00]``, on the Success and Collision columns only (the table is
shown on the documentation site's results page, and ten columns of intervals would make it
unreadable); their caption says so. Those displayed intervals, and the CSV's intervals of every rate
(`RATE_BOUNDS`), are clipped to [0, 1], the range of a rate; cells of a single seed stay
``mean`` and the seed count follows the Success cell in brackets, e.g. ``[3]``. MinCl's
cells say over how many seeds they are where a seed's every episode collided
(`cell_text`), and a sentence under the Markdown table says what MinCl is over
(`MINCL_NOTE`). A best-policy Success cell with seeds at which no trained policy beat the
untrained one carries `UNTRAINED_MARK` and the untrained curve success beside
(`untrained_text`), explained by `UNTRAINED_NOTE` under the table (Markdown and LaTeX); the
CSV counts those seeds and gives the figure. Pure functions of the rows they are given.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from distgprl.methods import METHODS
from distgprl.report.aggregate import BOOTSTRAP_REPS, Estimate
from distgprl.report.frame import COLLISION_FREE_MINCL
from distgprl.report.markdown import csv_text, latex_table, markdown_table
from distgprl.report.runs import TABLE_POLICY
from distgprl.report.table1 import (
    BEATS_UNTRAINED,
    CLEARANCE_METRICS,
    INTERVAL_METRICS,
    IQM_METRICS,
    LATE_CURVE,
    METRICS,
    PER_SEED_EXTRA,
    RATE_BOUNDS,
    UNTRAINED_CURVE_SUCCESS,
    Cell,
    UntrainedMarks,
    aggregate,
)

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
"""The footnote of `UNTRAINED_MARK`, under the Markdown and LaTeX Table I where it is used."""

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

MINCL_SEEDS = f"{COLLISION_FREE_MINCL}_seeds"
"""CSV column per task: the seeds MinCl's cell is over (those with a collision-free episode)."""

UNTRAINED_SEEDS = "untrained_best_seeds"
"""CSV column per task: the seeds at which no trained policy beat the untrained one."""

UNTRAINED_FIGURE = "untrained_curve_success_mean"
"""CSV column per task: those seeds' mean untrained (step-0) curve success (empty: none)."""


def cell_text(cell: Cell, key: str, seeds: int = 0, all_collided: int = 0) -> str:
    """A Table I cell as the Markdown and LaTeX tables show it; for MinCl with ``seeds``
    (the cell's seed count) and ``all_collided`` (seeds whose every episode collided) also
    ``(n=k)`` where only k seeds have a MinCl, `ALL_COLLIDED` where none has."""
    if key in INTERVAL_METRICS:
        return cell.text(2, interval=True, bounds=RATE_BOUNDS)
    text = cell.text(3 if key in CLEARANCE_METRICS else 2)
    if key == COLLISION_FREE_MINCL:
        if cell.n == 0 and seeds and all_collided == seeds:
            return ALL_COLLIDED
        if 0 < cell.n < seeds:
            return f"{text} (n={cell.n})"
    return text


def untrained_text(marks: UntrainedMarks | None, seeds: int) -> str:
    """`` † (untrained 0.68, 5 of 5 seeds)`` where ``marks`` counts seeds (of the cell's
    ``seeds``) at which no trained policy beat the untrained one; empty otherwise."""
    if marks is None or marks.seeds == 0:
        return ""
    figure = (
        "–" if np.isnan(marks.untrained_curve_success) else f"{marks.untrained_curve_success:.2f}"
    )
    return f" {UNTRAINED_MARK} (untrained {figure}, {marks.seeds} of {seeds} seeds)"


def _success_text(row: dict[str, Any], task: str) -> str:
    """The Success cell of ``row`` and ``task`` with its seed count and `untrained_text`."""
    n = row.get(f"{task}_seeds", 0)
    text = _row_cell_text(row, task, "success_rate")
    text = f"{text} [{n}]" if n else text
    return text + untrained_text(row.get(f"{task}_untrained"), n)


def _has_untrained_marks(rows: list[dict[str, Any]], tasks: list[str]) -> bool:
    """Whether any cell of ``rows`` carries `UNTRAINED_MARK`."""
    return any(
        getattr(row.get(f"{task}_untrained"), "seeds", 0) > 0 for row in rows for task in tasks
    )


def _row_cell_text(row: dict[str, Any], task: str, key: str) -> str:
    """`cell_text` of ``row``'s cell of ``task`` and ``key``."""
    cell = row.get(f"{task}_{key}", aggregate([]))
    seeds, collided = row.get(f"{task}_seeds", 0), row.get(f"{task}_all_collided_seeds", 0)
    return cell_text(cell, key, seeds, collided)


def per_seed_texts(
    rows: list[dict[str, Any]], preset: str, policy: str = TABLE_POLICY
) -> tuple[str, str]:
    """(CSV, Markdown) of `per_seed_rows` of the ``policy`` evaluations."""
    columns = (*METRICS, *PER_SEED_EXTRA, *LATE_CURVE)
    fields = ["task", "method", "seed", "policy", "policy_step"]
    fields += [BEATS_UNTRAINED, UNTRAINED_CURVE_SUCCESS, "collision_free_episodes"]
    fields += [*(key for key, _ in columns), "train_wall_min"]
    fields += ["train_cpu_ms_per_step", "numerics", "config_hash"]
    table_csv = csv_text(rows, fields)
    header = ["Task", "Method", "Seed", "Policy", "Collision-free episodes"]
    header += [*(label for _, label in columns), "Train wall (min)", "Train CPU (ms/step)"]
    table = []
    for row in rows:
        cells = [row["task"].upper(), METHODS[row["method"]].label, str(row["seed"])]
        step = row["policy_step"]
        cells.append(row["policy"] + ("" if step == "" else f" (step {step})") + _run_mark(row))
        cells.append(str(row["collision_free_episodes"]) or "–")
        for key, _ in columns:
            value = row[key]
            digits = 3 if key in CLEARANCE_METRICS else 2
            if value == "" and key == COLLISION_FREE_MINCL and row["collision_free_episodes"] == 0:
                cells.append(ALL_COLLIDED)
            else:
                cells.append("–" if value == "" else f"{float(value):.{digits}f}")
        for key in ("train_wall_min", "train_cpu_ms_per_step"):
            cells.append("–" if row[key] == "" else f"{row[key]:.1f}")
        table.append(cells)
    title = f"Table I per run ({preset} preset, {POLICY_TITLES[policy]})"
    marked = any(row.get(BEATS_UNTRAINED) is False for row in rows)
    note = f"\n{UNTRAINED_RUN_NOTE}.\n" if marked else ""
    return table_csv, markdown_table(title, header, table) + note


def _run_mark(row: dict[str, Any]) -> str:
    """`` † (untrained 0.44)`` for a run whose best policy did not beat the untrained one
    (``beats_untrained`` false), empty otherwise (true, or not recorded)."""
    if row.get(BEATS_UNTRAINED) is not False:
        return ""
    figure = row.get(UNTRAINED_CURVE_SUCCESS, "")
    return f" {UNTRAINED_MARK} (untrained {'–' if figure == '' else f'{float(figure):.2f}'})"


def _number(value: float) -> str:
    """A CSV number to 6 significant digits, empty for NaN."""
    return "" if np.isnan(value) else f"{value:.6g}"


def _csv_cells(row: dict[str, Any], task: str) -> dict[str, Any]:
    """The CSV cells of one row's ``task`` columns (`_csv_text`)."""
    out = {f"{task}_seeds": row.get(f"{task}_seeds", 0)}
    for key, _ in METRICS:
        cell = row.get(f"{task}_{key}", aggregate([]))
        for part in ("mean", "std", "ci_low", "ci_high"):
            value = getattr(cell, part)
            if part.startswith("ci_") and key.endswith("_rate"):
                value = float(np.clip(value, *RATE_BOUNDS))  # NaN stays NaN
            out[f"{task}_{key}_{part}"] = _number(value)
    out[f"{task}_{MINCL_SEEDS}"] = row.get(f"{task}_{COLLISION_FREE_MINCL}", aggregate([])).n
    out[f"{task}_all_collided_seeds"] = row.get(f"{task}_all_collided_seeds", 0)
    marks = row.get(f"{task}_untrained") or UntrainedMarks(0, float("nan"))
    out[f"{task}_{UNTRAINED_SEEDS}"] = marks.seeds
    out[f"{task}_{UNTRAINED_FIGURE}"] = _number(marks.untrained_curve_success)
    for key, _ in IQM_METRICS:
        estimate = row.get(f"{task}_{key}_iqm")
        parts = (np.nan,) * 3 if estimate is None else _iqm_parts(estimate)
        for part, value in zip(("iqm", "iqm_low", "iqm_high"), parts, strict=True):
            out[f"{task}_{key}_{part}"] = _number(value)
    return out


def _csv_text(rows: list[dict[str, Any]], tasks: list[str]) -> str:
    """Table I's CSV: per row the method, its label and every task's `_csv_cells`."""
    table = [
        {"method": row["method"], "label": row["label"]}
        | {k: v for task in tasks for k, v in _csv_cells(row, task).items()}
        for row in rows
    ]
    fields = ["method", "label"]
    fields += [k for task in tasks for k in _csv_cells({}, task)]
    return csv_text(table, fields)


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


def _markdown(
    rows: list[dict[str, Any]], tasks: list[str], preset: str, note: str, policy: str
) -> str:
    header = ["Method"]
    for t in tasks:
        header += [f"{t.upper()} {name}" for _, name in METRICS]
        header += [f"{t.upper()} {name}" for _, name in IQM_METRICS]
    table = []
    for row in rows:
        cells = [row["label"]]
        for task in tasks:
            for key, _ in METRICS:
                success = key == "success_rate"
                cells.append(
                    _success_text(row, task) if success else _row_cell_text(row, task, key)
                )
            cells += [_iqm_text(row.get(f"{task}_{key}_iqm")) for key, _ in IQM_METRICS]
        table.append(cells)
    title = (
        f"Table I ({preset} preset, {POLICY_TITLES[policy]}): mean ± std over seeds (seeds "
        "per cell in brackets after Success); Success and Collision also give the 95 % "
        "t-interval over seeds, [low, high] clipped to [0, 1], where there are two or more "
        "seeds; the IQM columns give the interquartile mean over seeds with its 95 % "
        f"stratified-bootstrap interval ({BOOTSTRAP_REPS} replicates)"
    )
    untrained = UNTRAINED_NOTE if _has_untrained_marks(rows, tasks) else ""
    notes = "".join(f"\n{text}.\n" for text in (MINCL_NOTE, untrained, note) if text)
    return markdown_table(title, header, table) + notes


def _latex(rows: list[dict[str, Any]], tasks: list[str], preset: str, policy: str) -> str:
    caption = (
        f"Simulation results ({preset} preset, {POLICY_TITLES[policy]}), mean "
        "$\\pm$ std over seeds; Success and Collision also give the 95\\,\\% t-interval over "
        "seeds [low, high], clipped to [0, 1], where there are two or more seeds; MinCl over "
        "the episodes without a collision, (n=k) over the k seeds that have one"
    )
    spans = (f"\\multicolumn{{{len(METRICS)}}}{{c}}{{{t.upper()}}}" for t in tasks)
    header = [" & " + " & ".join(spans)]
    header.append("Method & " + " & ".join(name for _ in tasks for _, name in METRICS))
    table = []
    for row in rows:
        cells = [row["label"].replace("_", "\\_")]
        for task in tasks:
            for key, _ in METRICS:
                text = _row_cell_text(row, task, key)
                if key == "success_rate":
                    text += untrained_text(
                        row.get(f"{task}_untrained"), row.get(f"{task}_seeds", 0)
                    )
                cells.append(_latex_text(text))
        table.append(cells)
    label = "tab:sim_results" if policy == TABLE_POLICY else f"tab:sim_results_{policy}"
    columns = "l" + "c" * (len(tasks) * len(METRICS))
    marked = _has_untrained_marks(rows, tasks)
    footnote = f"{_latex_text(UNTRAINED_NOTE)}." if marked else ""
    return latex_table(caption, label, columns, header, table, footnote)


def _latex_text(text: str) -> str:
    """``text`` with the table's Unicode signs as LaTeX."""
    replaced = text.replace("±", "$\\pm$").replace("—", "---").replace("–", "--")
    return replaced.replace(UNTRAINED_MARK, "$^\\dagger$")


def table1_texts(
    rows: list[dict[str, Any]],
    tasks: list[str],
    preset: str,
    note: str = "",
    policy: str = TABLE_POLICY,
) -> tuple[str, str, str]:
    """(CSV, Markdown, LaTeX) of Table I from `simulation_table`'s rows and tasks of the
    ``policy`` evaluations; ``note`` (the runs left out or substituted, `run_evaluations`)
    goes under the Markdown table, after `MINCL_NOTE`."""
    return (
        _csv_text(rows, tasks),
        _markdown(rows, tasks, preset, note, policy),
        _latex(rows, tasks, preset, policy),
    )
