"""Table I (`simulation_table`) and Table I per run (`per_seed_rows`) of the evaluation the
`Frames` hold: `TABLE_POLICY`'s (docs/findings/protocol.md, rule 6) or the final
policy's. MinCl is `COLLISION_FREE_MINCL` (rule 5); `UNTRAINED_MARK` marks where no trained
policy beat the untrained one (protocol rule 2)."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import pandas as pd
from scipy import stats

from distgprl.data import task_order
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.aggregate import (
    BOOTSTRAP_REPS,
    BOOTSTRAP_SEED,
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

METRICS = (
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
    (COLLISION_FREE_MINCL, "MinCl (m)"),
    ("min_clearance_p5", "MinCl all episodes (m)"),
    ("min_signed_clearance_p5", "SignedCl (m)"),
    ("completion_rate", "Completed"),
    ("mean_kinematic_retention", "KinRet"),
)
"""(summary field, label) per task: the paper's three, MinCl over all episodes (a colliding one
counts 0), the signed clearance's 5th percentile (m; negative: penetration), completion."""

RATE_BOUNDS = (0.0, 1.0)
"""The range of a rate (``*_rate``): its interval is clipped to it."""

INTERVAL_METRICS = ("success_rate", "collision_rate")
"""Metrics whose cells also show the 95 % interval."""

IQM_METRICS = (("success_rate", "Success IQM"), ("collision_rate", "Collision IQM"))
"""Metrics with an IQM column per task (`method_estimate`, one stratum; not in the LaTeX)."""

LATE_CURVE_POINTS = 5
"""How many of the last learning-curve evaluations `late_curve` reads."""

PER_SEED_COLUMNS = (
    *METRICS,
    ("peak_joint_speed_p95", "PeakJS p95 (rad/s)"),
    ("joint_speed_over_limit_rate", "JS > limit"),
    ("late_curve_success", "Late curve succ"),
    ("late_curve_success_range", "Late curve range"),
)
"""Table I per run's metrics: `METRICS`, the episodes' peak commanded joint speed (95th
percentile), the share above the safety layer's joint speed limit, `late_curve`."""

ALL_COLLIDED = "– (all collided)"
"""MinCl's text where every episode collided (of the run; of every seed, in Table I)."""

MINCL_NOTE = (
    "MinCl: 5th percentile of the episode-wise minimum clearance (robot links and tool vs "
    'obstacles, m) over the episodes without a collision (FINDINGS "Protocol v6", rule 5); '
    "(n=k): over the k seeds with a collision-free episode; "
    f"{ALL_COLLIDED}: every episode of every seed collided, so MinCl is undefined (not 0). "
    "MinCl all episodes: v5's, over every episode (a colliding one counts 0)"
)

UNTRAINED_MARK = "†"

_UNTRAINED_WHAT = (
    "no learning-curve point after the first SAC update had a higher curve success than the "
    "untrained step-0 policy (protocol v8, rule 2); the best trained policy is still reported"
)

UNTRAINED_NOTE = (
    f"{UNTRAINED_MARK} (untrained x, k of n seeds): no trained policy beat the untrained one "
    f"at k of the cell's n seeds: {_UNTRAINED_WHAT}, and x is the untrained policy's "
    "learning-curve success (curve TCs, not the evaluation TCs), mean over those k seeds"
)

UNTRAINED_RUN_NOTE = (
    f"{UNTRAINED_MARK} (untrained x): no trained policy beat the untrained one: "
    f"{_UNTRAINED_WHAT}, and x is the untrained policy's learning-curve success (curve TCs)"
)

POLICY_TITLES = {
    "best": "best learning-curve policy, Algorithm 1's output",
    "final": "final policy",
}
"""How a table's title names the evaluation it reports."""


class Cell(NamedTuple):
    """One metric over seeds: mean, sample std, 95 % t-interval (NaN below two seeds), seeds."""

    mean: float
    std: float
    ci_low: float
    ci_high: float
    n: int

    def rate_interval(self) -> tuple[float, float]:
        return float(np.clip(self.ci_low, *RATE_BOUNDS)), float(np.clip(self.ci_high, *RATE_BOUNDS))

    def columns(self, name: str) -> dict[str, float]:
        """The CSV's ``<name>_mean``, ``_std``, ``_ci_low``, ``_ci_high`` (a rate's clipped)."""
        low, high = self.rate_interval() if name.endswith("_rate") else (self.ci_low, self.ci_high)
        parts = {"mean": self.mean, "std": self.std, "ci_low": low, "ci_high": high}
        return {f"{name}_{part}": number for part, number in parts.items()}

    def text(self, digits: int = 2, interval: bool = False) -> str:
        """``mean ± std [low, high]`` (the interval with ``interval``, clipped); ``mean`` for one
        seed, ``–`` for none."""
        if self.n < 2:
            return number_text(self.mean, digits)
        text = f"{self.mean:.{digits}f} ± {self.std:.{digits}f}"
        if interval:
            low, high = self.rate_interval()
            text += f" [{low:.{digits}f}, {high:.{digits}f}]"
        return text


def aggregate(values: list[float]) -> Cell:
    """The `Cell` of one value per seed."""
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


def untrained_marks(summaries: list[dict[str, Any]]) -> dict[str, float]:
    """Of one cell's summaries: ``untrained_best_seeds``, how many record ``beats_untrained``
    false (a missing one is unknown, not counted), and ``untrained_curve_success_mean``, the
    mean of their untrained step-0 curve success (NaN: none)."""
    beaten = [s for s in summaries if s.get("beats_untrained") is False]
    key = "untrained_curve_success_rate"
    figures = [s[key] for s in beaten if s.get(key) is not None]
    mean = float(np.mean(figures)) if figures else float("nan")
    return {"untrained_best_seeds": len(beaten), "untrained_curve_success_mean": mean}


NO_POINTS = pd.DataFrame({"step": [], "success_rate": []})
"""The curve points of a run without a learning curve (an untrained reference)."""


def collect_scores(frames: Frames) -> Scores:
    """{(task, method): [`run_scores` per seed]} of ``frames``' evaluations."""
    out: dict[tuple[str, str], list[dict[str, float]]] = {}
    for (task, method, seed, _), summary in summaries(frames.runs):
        points = frames.curves.get((task, method, seed), NO_POINTS)
        out.setdefault((task, method), []).append(run_scores(summary, points))
    return out


def late_curve(points: pd.DataFrame) -> dict[str, float | str]:
    """The mean and the max - min curve success of one run's last `LATE_CURVE_POINTS` curve
    points (empty strings without a trained point among them: `demo`)."""
    late = points.tail(LATE_CURVE_POINTS)
    success = late["success_rate"][late["step"] != 0].tolist()
    if not success:
        return dict.fromkeys(("late_curve_success", "late_curve_success_range"), "")
    return {
        "late_curve_success": float(np.mean(success)),
        "late_curve_success_range": float(max(success) - min(success)),
    }


def per_seed_rows(frames: Frames) -> list[dict[str, Any]]:
    """One row per run, in task, table order and seed: `EVALUATION_KEYS`, the summary's
    ``fields`` ("" where it lacks one), `late_curve`, training wall time (``train_wall_min``, min)
    and CPU time per RL step (``train_cpu_ms_per_step``, ms; both empty for `demo`), ``numerics``
    and ``config_hash``."""
    fields = ["policy_step", "beats_untrained", "untrained_curve_success_rate"]
    summary_keys = (key for key, _ in PER_SEED_COLUMNS if not key.startswith("late_curve"))
    fields += ["collision_free_episodes", *summary_keys]
    rows = []
    for key, summary in summaries(frames.runs):
        row: dict[str, Any] = dict(zip(EVALUATION_KEYS, key, strict=True))
        row |= {name: summary.get(name, "") for name in fields}
        row |= late_curve(frames.curves.get(key[:3], NO_POINTS))
        wall, cpu = summary.get("train_wall_time_s"), summary.get("cpu_s_per_step")
        row["train_wall_min"] = "" if wall is None else round(float(wall) / 60.0, 1)
        row["train_cpu_ms_per_step"] = "" if cpu is None else round(1e3 * float(cpu), 1)
        row |= {"numerics": summary["numerics"], "config_hash": summary["config_hash"]}
        rows.append(row)
    rows.sort(key=lambda r: (task_order(r["task"]), TABLE_ORDER.index(r["method"]), r["seed"]))
    return rows


def _run_cells(row: dict[str, Any]) -> list[str]:
    step, free = row["policy_step"], row["collision_free_episodes"]
    policy = row["policy"] + ("" if step == "" else f" (step {step})")
    if row["beats_untrained"] is False:
        untrained = number_text(row["untrained_curve_success_rate"], 2)
        policy += f" {UNTRAINED_MARK} (untrained {untrained})"
    cells = [row["task"].upper(), METHODS[row["method"]].label, str(row["seed"]), policy]
    cells.append(str(free) or "–")
    for key, _ in PER_SEED_COLUMNS:
        no_mincl = key == COLLISION_FREE_MINCL and row[key] == "" and free == 0
        cells.append(ALL_COLLIDED if no_mincl else number_text(row[key], _digits(key)))
    return cells + [number_text(row[key], 1) for key in ("train_wall_min", "train_cpu_ms_per_step")]


def per_seed_texts(rows: list[dict[str, Any]], preset: str, policy: str) -> tuple[str, str]:
    """(CSV, Markdown) of `per_seed_rows`' (non-empty) ``rows`` of the ``policy`` evaluations."""
    header = ["Task", "Method", "Seed", "Policy", "Collision-free episodes"]
    header += [*(label for _, label in PER_SEED_COLUMNS), "Train wall (min)", "Train CPU (ms/step)"]
    title = f"Table I per run ({preset} preset, {POLICY_TITLES[policy]})"
    markdown = markdown_table(title, header, [_run_cells(row) for row in rows])
    if any(row["beats_untrained"] is False for row in rows):
        markdown += f"\n{UNTRAINED_RUN_NOTE}.\n"
    return csv_text(rows, list(rows[0])), markdown


def _task_row(task: str, method: str, seeds: list[dict[str, Any]]) -> dict[str, Any]:
    row: dict[str, Any] = {"seeds": len(seeds)}
    for key, _ in METRICS:
        row[key] = aggregate([s[key] for s in seeds if s.get(key) is not None])
    row[f"{COLLISION_FREE_MINCL}_seeds"] = row[COLLISION_FREE_MINCL].n
    row["all_collided_seeds"] = sum(s.get("collision_free_episodes") == 0 for s in seeds)
    row |= untrained_marks(seeds)
    for key, _ in IQM_METRICS:
        iqm = method_estimate({(task, method): seeds}, [task], method, key, "iqm", BOOTSTRAP_SEED)
        row |= {f"{key}_iqm": iqm.point, f"{key}_iqm_low": iqm.low, f"{key}_iqm_high": iqm.high}
    return {f"{task}_{name}": value for name, value in row.items()}


def simulation_table(
    frames: Frames, order: tuple[str, ...] = TABLE_ORDER
) -> tuple[list[dict[str, Any]], list[str]]:
    """Rows of Table I, one per method of ``order`` with runs, and the tasks. Per task
    (``<task>_`` + ...): ``seeds``, a `Cell` per `METRICS` key, the seeds MinCl is over
    (``<MinCl>_seeds``) and those whose every episode collided (``all_collided_seeds``),
    `untrained_marks`, and per `IQM_METRICS` key the IQM (``<key>_iqm``, ``_low``, ``_high``)."""
    by_cell: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for (task, method, _, _), summary in summaries(frames.runs):
        by_cell.setdefault((task, method), []).append(summary)
    tasks = sorted({task for task, _ in by_cell}, key=task_order)
    rows = []
    for method in (m for m in order if any((task, m) in by_cell for task in tasks)):
        row = {"method": method, "label": METHODS[method].label}
        for task in tasks:
            row |= _task_row(task, method, by_cell.get((task, method), []))
        rows.append(row)
    return rows, tasks


def _digits(key: str) -> int:
    return 3 if "clearance" in key else 2  # clearances in metres, to the millimetre


def _metric_text(key: str, cell: Cell, seeds: int, all_collided: int) -> str:
    """``key``'s text of a `Cell` over ``seeds``: MinCl with ``(n=k)`` where only k of them have
    one, `ALL_COLLIDED` where every episode of every seed collided."""
    if key == COLLISION_FREE_MINCL and cell.n == 0 and seeds and seeds == all_collided:
        return ALL_COLLIDED
    text = cell.text(_digits(key), interval=key in INTERVAL_METRICS)
    if key == COLLISION_FREE_MINCL and 0 < cell.n < seeds:
        text += f" (n={cell.n})"
    return text


def _task_cells(row: dict[str, Any], task: str, markdown: bool) -> list[str]:
    """``row``'s `METRICS` cells of ``task``, Success with the `UNTRAINED_MARK`; in ``markdown``
    also Success's seed count in brackets and the `IQM_METRICS` cells."""
    seeds, marked = row[f"{task}_seeds"], row[f"{task}_untrained_best_seeds"]
    collided = row[f"{task}_all_collided_seeds"]
    cells = [_metric_text(key, row[f"{task}_{key}"], seeds, collided) for key, _ in METRICS]
    cells[0] += f" [{seeds}]" if seeds and markdown else ""
    if marked:
        figure = number_text(row[f"{task}_untrained_curve_success_mean"], 2)
        cells[0] += f" {UNTRAINED_MARK} (untrained {figure}, {marked} of {seeds} seeds)"
    iqms = [f"{task}_{key}_iqm" for key, _ in IQM_METRICS] if markdown else []
    return cells + [interval_text(row[k], row[f"{k}_low"], row[f"{k}_high"]) for k in iqms]


def _csv_row(row: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, value in row.items():
        out |= value.columns(name) if isinstance(value, Cell) else {name: value}
    return out


def table1_texts(
    rows: list[dict[str, Any]],
    tasks: list[str],
    preset: str,
    note: str,
    policy: str,
    heading: str | None = None,
) -> tuple[str, str, str]:
    """(CSV, Markdown, LaTeX) of `simulation_table`'s rows and tasks; under the Markdown
    `MINCL_NOTE`, `UNTRAINED_NOTE` where a cell is marked and ``note`` (the runs left out);
    ``heading`` opens the Markdown's title (default ``Table I (<preset> preset, <policy>)``)."""
    heading = heading or f"Table I ({preset} preset, {POLICY_TITLES[policy]})"
    marked = any(row[f"{task}_untrained_best_seeds"] for row in rows for task in tasks)
    header = [
        "Method",
        *(f"{t.upper()} {name}" for t in tasks for _, name in METRICS + IQM_METRICS),
    ]
    body = [[row["label"], *(c for t in tasks for c in _task_cells(row, t, True))] for row in rows]
    title = (
        f"{heading}: mean ± std over seeds (seeds "
        "per cell in brackets after Success); Success and Collision also give the 95 % "
        "t-interval over seeds, [low, high] clipped to [0, 1], where there are two or more "
        "seeds; the IQM columns give the interquartile mean over seeds with its 95 % "
        f"stratified-bootstrap interval ({BOOTSTRAP_REPS} replicates)"
    )
    notes = (MINCL_NOTE, UNTRAINED_NOTE if marked else "", note)
    markdown = markdown_table(title, header, body) + "".join(f"\n{n}.\n" for n in notes if n)
    caption = (
        f"Simulation results ({preset} preset, {POLICY_TITLES[policy]}), mean "
        "$\\pm$ std over seeds; Success and Collision also give the 95\\,\\% t-interval over "
        "seeds [low, high], clipped to [0, 1], where there are two or more seeds; MinCl over "
        "the episodes without a collision, (n=k) over the k seeds that have one"
    )
    spans = (f"\\multicolumn{{{len(METRICS)}}}{{c}}{{{t.upper()}}}" for t in tasks)
    latex_header = [" & " + " & ".join(spans)]
    latex_header.append("Method & " + " & ".join(name for _ in tasks for _, name in METRICS))
    latex_body = [
        [row["label"].replace("_", "\\_"), *(c for t in tasks for c in _task_cells(row, t, False))]
        for row in rows
    ]
    label = "tab:sim_results" if policy == TABLE_POLICY else f"tab:sim_results_{policy}"
    columns = "l" + "c" * (len(tasks) * len(METRICS))
    footnote = f"{UNTRAINED_NOTE}." if marked else ""
    latex = latex_table(caption, label, columns, latex_header, latex_body, footnote)
    table = [_csv_row(row) for row in rows]
    return csv_text(table, list(table[0]), significant=6), markdown, latex
