"""Table I (simulation) and Table II (hardware) from result files only.

`write_tables` also writes Table I per run, each run's paired comparisons, TC by TC,
with the `demo` reference and with `dist-gprl` (`distgprl.report.paired`), the robust
aggregates with stratified-bootstrap intervals (`distgprl.report.aggregate`) and the claims
table (`distgprl.report.claims`).

Each cell is the mean ± sample standard deviation (ddof = 1) over seeds with a 95 %
confidence interval (Student t over seeds; a single seed has neither). The CSV has all four
numbers of every cell. The Markdown and LaTeX tables show the interval, as
``0.88 ± 0.06 [0.73, 1.00]``, on the Success and Collision columns only (the table is
copied into the README, and ten columns of intervals would make it unreadable); their
caption says so. Those displayed intervals, and the CSV's intervals of every rate
(`RATE_BOUNDS`), are clipped to [0, 1], the range of a rate; cells of a single seed stay
``mean`` and the seed count follows the Success cell in brackets, e.g. ``[3]``. Rows follow
the paper's order, then the ablation and the `demo` reference. Pure functions of the files
they read.

Table II (hardware, ``table2_<preset>``) counts the trial files of the preset's policies
(`select_trial_files`: never trials with the pre-flight check overridden, dry runs, or
policies of an older configuration; those are listed under the table). Its rates are over
all trials (a refused trial is a failure without collision), with the exact (Clopper-Pearson)
95 % binomial interval over the trials; its MinCl is over the trials that moved the robot
only (`moved_robot`), and says over how many when that is fewer than the trials.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from distgprl.data import task_order
from distgprl.errors import UserInputError
from distgprl.io import atomic_write_text
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.aggregate import Scores, aggregate_texts, run_scores
from distgprl.report.claims import claims_texts
from distgprl.report.markdown import markdown_table as _markdown_table
from distgprl.report.paired import (
    FINAL_POLICY,
    REFERENCES,
    best_vs_final_rows,
    cross_preset_rows,
    paired_rows,
    paired_texts,
    supplementary_sizes,
)
from distgprl.report.runs import current_hash, known_preset, select_runs
from distgprl.schema import (
    SCHEMA_VERSION,
    csv_meta_path,
    moved_robot,
    read_csv,
    read_json,
)

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


def _cell_text(cell: Cell, key: str) -> str:
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


def _summary_paths(root: Path, preset: str) -> list[Path]:
    """The ``summary.json`` files of the runs that count (`select_runs`)."""
    current = select_runs(root, preset).current
    return sorted(
        path
        for path in (Path(root) / preset).glob("*/*/seed*/summary.json")
        if path.parent in current
    )


def collect_summaries(root: Path, preset: str) -> dict[tuple[str, str], list[dict]]:
    """{(task, method): [summary per seed]} from ``<root>/<preset>/<task>/<method>/seed*/``."""
    out: dict[tuple[str, str], list[dict]] = {}
    for path in _summary_paths(root, preset):
        task, method = path.parts[-4], path.parts[-3]
        out.setdefault((task, method), []).append(read_json(path)["summary"])
    return out


def collect_scores(root: str | Path, preset: str) -> Scores:
    """{(task, method): [`run_scores` per seed]} of the runs `collect_summaries` reads: the
    rates and learning-curve measures the aggregates and the claims table bootstrap."""
    out: dict[tuple[str, str], list[dict[str, float]]] = {}
    for path in _summary_paths(Path(root), preset):
        task, method = path.parts[-4], path.parts[-3]
        summary = read_json(path)["summary"]
        out.setdefault((task, method), []).append(run_scores(path.parent, summary))
    return out


def per_seed_rows(root: str | Path, preset: str) -> list[dict]:
    """One row per run: task, method, seed, the Table I metrics, the training wall time
    (min, from ``done.json``; empty for `demo`) and the config hash. Task, table order, seed."""
    rows = []
    for path in _summary_paths(Path(root), preset):
        task, method, seed = path.parts[-4], path.parts[-3], path.parts[-2]
        if method not in METHODS:
            continue
        document = read_json(path)
        summary = document["summary"]
        done = path.parent / "done.json"
        wall = read_json(done).get("train_wall_time_s") if done.exists() else None
        row = {"task": task, "method": method, "seed": int(seed.removeprefix("seed"))}
        row.update({key: summary.get(key, "") for key, _ in (*METRICS, *PER_SEED_EXTRA)})
        row.update(late_curve(path.parent / "progress.csv"))
        row["train_wall_min"] = "" if wall is None else round(float(wall) / 60.0, 1)
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
`LATE_CURVE_POINTS` evaluations (20 fixed TCs each, deterministic policy of that
step) and their max - min. Next to the final 100-TC success they show how much the final policy's
number depends on where training stopped (empty for `demo`, which has no curve)."""


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


def _per_seed_texts(rows: list[dict], preset: str) -> tuple[str, str]:
    """(CSV, Markdown) of `per_seed_rows`."""
    columns = (*METRICS, *PER_SEED_EXTRA, *LATE_CURVE)
    fields = ["task", "method", "seed", *(key for key, _ in columns), "train_wall_min"]
    fields.append("config_hash")
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    header = ["Task", "Method", "Seed", *(label for _, label in columns), "Train wall (min)"]
    table = []
    for row in rows:
        cells = [row["task"].upper(), METHODS[row["method"]].label, str(row["seed"])]
        for key, _ in columns:
            value = row[key]
            digits = 3 if key in CLEARANCE_METRICS else 2
            cells.append("–" if value == "" else f"{float(value):.{digits}f}")
        cells.append("–" if row["train_wall_min"] == "" else f"{row['train_wall_min']:.1f}")
        table.append(cells)
    return buffer.getvalue(), _markdown_table(f"Table I per run ({preset} preset)", header, table)


def simulation_table(root: str | Path, preset: str) -> tuple[list[dict], list[str]]:
    """Rows of Table I: one per (method), columns per task and metric."""
    summaries = collect_summaries(Path(root), preset)
    tasks = sorted({task for task, _ in summaries}, key=task_order)
    rows = []
    for method in TABLE_ORDER:
        if not any((task, method) in summaries for task in tasks):
            continue
        row = {"method": method, "label": METHODS[method].label}
        for task in tasks:
            seeds = summaries.get((task, method), [])
            row[f"{task}_seeds"] = len(seeds)
            for key, _ in METRICS:
                row[f"{task}_{key}"] = aggregate([s[key] for s in seeds if key in s])
        rows.append(row)
    return rows, tasks


HARDWARE_TASK = "dbm"
"""The task of the hardware cell (and of the policies its trials run)."""


@dataclass(frozen=True)
class TrialFiles:
    """The hardware trial files Table II of a preset counts, and why others do not.

    Attributes:
        counted: (method, rows) of every counted file, in table order then file name.
        excluded: one line per left-out file of the preset: ``method/file (reason)``.
    """

    counted: tuple[tuple[str, tuple[dict, ...]], ...]
    excluded: tuple[str, ...]

    def note(self) -> str:
        """A sentence for the table: what was left out (empty if nothing)."""
        if not self.excluded:
            return ""
        return f"Not tabulated ({len(self.excluded)}): " + "; ".join(self.excluded)


def select_trial_files(root: str | Path, preset: str) -> TrialFiles:
    """The trial files ``<root>/hardware/<method>/*.csv`` of ``preset``'s policies (their
    meta's ``preset``; another preset's files belong to its own table) that Table II counts:
    not those run with the pre-flight check overridden (``force``: the safety layer's
    refusals were not applied, so they are not the method's hardware result) or as a dry
    run, and, for this checkout's presets, only those whose policy's recorded config hash
    is the one the code resolves now (as Table I; a trial of an older policy is listed)."""
    base = Path(root) / "hardware"
    checked = known_preset(preset)
    counted, excluded = [], []
    for method in TABLE_ORDER:
        for path in sorted((base / method).glob("*.csv")) if (base / method).exists() else []:
            meta, rows = read_csv(path)
            if meta.get("preset") != preset:
                continue
            name = f"{method}/{path.name}"
            policy_hash = (meta.get("policy") or {}).get("run_config_hash")
            if meta.get("force"):
                excluded.append(f"{name} (pre-flight check overridden, --force)")
            elif meta.get("dry_run"):
                excluded.append(f"{name} (dry run)")
            elif (
                checked
                and METHODS[method].trainable
                and policy_hash
                != current_hash(HARDWARE_TASK, method, int(meta.get("seed", -1)), preset)
            ):
                recorded = policy_hash or "not recorded"
                excluded.append(f"{name} (policy config hash {recorded}, not the current one)")
            else:
                counted.append((method, tuple(rows)))
    return TrialFiles(tuple(counted), tuple(excluded))


def binomial_interval(successes: int, trials: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) two-sided interval of a rate of ``successes`` in ``trials``."""
    alpha, failures = 1.0 - level, trials - successes
    low = 0.0 if successes == 0 else stats.beta.ppf(alpha / 2, successes, failures + 1)
    high = 1.0 if failures == 0 else stats.beta.ppf(1 - alpha / 2, successes + 1, failures)
    return float(low), float(high)


def hardware_table(root: str | Path, preset: str) -> list[dict]:
    """Rows of Table II from the trial files `select_trial_files` counts (`hardware_rows`)."""
    return hardware_rows(select_trial_files(root, preset))


def hardware_rows(files: TrialFiles) -> list[dict]:
    """Rows of Table II from the trial files ``files`` counts, one per (method,
    backend): trials on the real robot (``ur``) and on the digital twin are never mixed.
    Refused trials (the safety layer's pre-flight check refused a window's plan) count as
    failures without collision and are also counted on their own. Success and collision
    rates are over all trials, each with its exact 95 % binomial interval
    (``<rate>_ci_low``, ``<rate>_ci_high``); MinCl, the 5th percentile of the trials'
    minimum clearance, only over the ``executed`` trials that moved the robot
    (`moved_robot`; NaN if none did)."""
    by_method: dict[str, list[dict]] = {}
    for method, trial_rows in files.counted:
        by_method.setdefault(method, []).extend(trial_rows)
    rows = []
    for method, trials in by_method.items():  # counted in table order
        for backend in sorted({r.get("backend", "unknown") for r in trials}):
            subset = [r for r in trials if r.get("backend", "unknown") == backend]
            executed = [r for r in subset if moved_robot(r)]
            clearance = [
                float(r["min_clearance"])
                for r in executed
                if r["min_clearance"] not in ("", "nan") and np.isfinite(float(r["min_clearance"]))
            ]
            row = {
                "method": method,
                "label": METHODS[method].label,
                "backend": backend,
                "trials": len(subset),
                "refused": sum(r.get("status") == "refused" for r in subset),
                "min_clearance_p5": float(np.percentile(clearance, 5)) if clearance else np.nan,
                "executed": len(executed),
            }
            for key, column in (("success_rate", "success"), ("collision_rate", "collision")):
                count = int(sum(round(float(r[column])) for r in subset))
                row[key] = count / len(subset)
                row[f"{key}_ci_low"], row[f"{key}_ci_high"] = binomial_interval(count, len(subset))
            rows.append(row)
    return rows


def _csv_text(rows: list[dict], tasks: list[str]) -> str:
    buffer = io.StringIO()
    fields = ["method", "label"]
    for task in tasks:
        fields.append(f"{task}_seeds")
        for key, _ in METRICS:
            fields += [f"{task}_{key}_{part}" for part in ("mean", "std", "ci_low", "ci_high")]
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
        writer.writerow(out)
    return buffer.getvalue()


def _markdown(rows: list[dict], tasks: list[str], preset: str, note: str = "") -> str:
    header = ["Method"] + [f"{t.upper()} {name}" for t in tasks for _, name in METRICS]
    table = []
    for row in rows:
        cells = [row["label"]]
        for task in tasks:
            n = row.get(f"{task}_seeds", 0)
            for index, (key, _) in enumerate(METRICS):
                text = _cell_text(row.get(f"{task}_{key}", aggregate([])), key)
                cells.append(f"{text} [{n}]" if index == 0 and n else text)
        table.append(cells)
    title = (
        f"Table I ({preset} preset): mean ± std over seeds (seeds per cell in brackets after "
        "Success); Success and Collision also give the 95 % t-interval over seeds, "
        "[low, high] clipped to [0, 1], where there are two or more seeds"
    )
    return _markdown_table(title, header, table) + (f"\n{note}.\n" if note else "")


def _latex(rows: list[dict], tasks: list[str], preset: str) -> str:
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
                text = _cell_text(row.get(f"{task}_{key}", aggregate([])), key)
                cells.append(text.replace("±", "$\\pm$"))
        lines.append(" & ".join(cells) + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}", "\\end{table}", ""]
    return "\n".join(lines)


HARDWARE_COLUMNS = (
    ("trials", "Trials"),
    ("refused", "Refused"),
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
    ("min_clearance_p5", "MinCl (m)"),
)
"""Table II columns after method and backend (MinCl: 5th percentile of the minimum
clearance of the trials that moved the robot, m). The CSV adds ``executed``, the number of
those trials."""

HARDWARE_CAPTION = (
    "Hardware trials (DBM); refused trials count as failures; Success and Collision with "
    "the exact 95 % binomial interval over the trials; MinCl is over the trials that "
    "moved the robot (n = their number where fewer than the trials; – if none did)"
)


def _hardware_min_clearance(row: dict) -> str:
    """The MinCl cell: the value, ``(n=k)`` if only k of the trials moved the robot."""
    value = row["min_clearance_p5"]
    text = "–" if np.isnan(value) else f"{value:.3f}"
    if row["executed"] != row["trials"]:
        text += f" (n={row['executed']})"
    return text


def _hardware_texts(rows: list[dict], preset: str, note: str = "") -> tuple[str, str, str]:
    """(CSV, Markdown, LaTeX) of Table II from `hardware_table` rows."""
    buffer = io.StringIO()
    fields = ["method", "backend", *(key for key, _ in HARDWARE_COLUMNS), "executed"]
    fields += [f"{key}_ci_{end}" for key in INTERVAL_METRICS for end in ("low", "high")]
    writer = csv.DictWriter(buffer, fieldnames=fields, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        value = row["min_clearance_p5"]
        writer.writerow({**row, "min_clearance_p5": "" if np.isnan(value) else value})

    def cells(row: dict) -> list[str]:
        return [
            row["label"],
            row["backend"],
            str(row["trials"]),
            str(row["refused"]),
            *(
                f"{row[key]:.2f} [{row[f'{key}_ci_low']:.2f}, {row[f'{key}_ci_high']:.2f}]"
                for key in INTERVAL_METRICS
            ),
            _hardware_min_clearance(row),
        ]

    header = ["Method", "Backend", *(label for _, label in HARDWARE_COLUMNS)]
    caption = f"{HARDWARE_CAPTION} ({preset} preset policies)"
    markdown = _markdown_table(f"Table II: {caption}", header, [cells(row) for row in rows])
    if note:
        markdown += f"\n{note}.\n"
    latex_caption = caption.replace("–", "--").replace(" %", "\\,\\%")
    lines = [
        "\\begin{table}[htb]",
        "\\centering",
        f"\\caption{{{latex_caption}}}",
        "\\label{tab:hardware_results}",
        "\\begin{tabular}{ll" + "c" * len(HARDWARE_COLUMNS) + "}",
        "\\toprule",
        " & ".join(header) + " \\\\",
        "\\midrule",
        *(" & ".join(cells(row)).replace("–", "--") + " \\\\" for row in rows),
        "\\bottomrule",
        "\\end{tabular}",
        "\\end{table}",
        "",
    ]
    return buffer.getvalue(), markdown, "\n".join(lines)


def write_tables(
    root: str | Path, preset: str, out_dir: str | Path, against: str | None = None
) -> list[Path]:
    """Write Table I (and Table II when hardware trials exist) as CSV, Markdown, LaTeX,
    Table I per run (``table1_<preset>_per_seed``: every seed's numbers and wall time), the
    stratified-bootstrap aggregates (``aggregates_<preset>``: mean, IQM and Dist-GPRL's
    probability of improvement, `distgprl.report.aggregate`) and the claims table
    (``claims_<preset>``: a verdict per paper claim, `distgprl.report.claims`), CSV and
    Markdown, and
    every run paired TC by TC with the `demo` reference and with `dist-gprl` of the same
    seed where those were evaluated (``paired_vs_<reference>_<preset>``, CSV and Markdown;
    ``..._n<N>`` for supplementary evaluations on N TCs), and, for runs whose best
    learning-curve policy was evaluated, that policy paired with the run's final one
    (``paired_best_vs_final_<preset>``). With ``against`` (another preset), also every run
    paired with the same run of that preset (``paired_<preset>_vs_<against>``, CSV and
    Markdown; `cross_preset_rows`)."""
    rows, tasks = simulation_table(root, preset)
    if not rows:
        raise UserInputError(f"{Path(root) / preset}: no summary.json files; run a sweep first")
    cross = None  # computed first: a refused pairing writes nothing
    if against is not None:
        cross = cross_preset_rows(root, preset, against)
        if not cross:
            raise UserInputError(
                f"--against {against}: no run of {Path(root) / preset} has a finished "
                f"counterpart (same task, method and seed) under {Path(root) / against}"
            )
    out_dir = Path(out_dir)
    stem = f"table1_{preset}"
    note = select_runs(root, preset).note()
    table_one = (
        "Table I: per task, each metric's mean, sample std and 95 % t-interval over seeds "
        "(ci_low, ci_high; empty for one seed)"
    )
    written = _write_or_remove(
        out_dir / stem,
        (".csv", ".md", ".tex"),
        (_csv_text(rows, tasks), _markdown(rows, tasks, preset, note), _latex(rows, tasks, preset)),
        preset,
        table_one,
    )
    written += _write_or_remove(
        out_dir / f"{stem}_per_seed",
        (".csv", ".md"),
        _per_seed_texts(per_seed_rows(root, preset), preset),
        preset,
        "Table I per run: every seed's metrics, late learning-curve means and training wall time",
    )
    scores = collect_scores(root, preset)
    written += _write_or_remove(
        out_dir / f"aggregates_{preset}",
        (".csv", ".md"),
        aggregate_texts(scores, preset),
        preset,
        "mean, IQM and probability of improvement over seeds with 95 % stratified-bootstrap "
        "intervals (distgprl.report.aggregate)",
    )
    written += _write_or_remove(
        out_dir / f"claims_{preset}",
        (".csv", ".md"),
        claims_texts(scores, preset),
        preset,
        "each claim of the paper, the statistic testing it and the verdict "
        "(rules: distgprl.report.claims)",
    )
    sizes = supplementary_sizes(root, preset)
    for reference in REFERENCES:
        for episodes in (None, *sizes):
            pairs = paired_rows(root, preset, reference, episodes)
            written += _write_or_remove(
                out_dir / f"paired_vs_{reference}_{preset}{f'_n{episodes}' if episodes else ''}",
                (".csv", ".md"),
                paired_texts(pairs, preset, reference, episodes) if pairs else None,
                preset,
                f"each run paired TC by TC with the {reference} reference (McNemar)",
            )
    for stale in out_dir.glob(f"paired_vs_*_{preset}_n*.*"):  # sizes no longer present
        if stale not in written:
            stale.unlink()
    best = best_vs_final_rows(root, preset)
    written += _write_or_remove(
        out_dir / f"paired_best_vs_final_{preset}",
        (".csv", ".md"),
        paired_texts(best, preset, FINAL_POLICY) if best else None,
        preset,
        "each run's best learning-curve policy paired TC by TC with its final one (McNemar)",
    )
    if cross is not None:
        written += _write_or_remove(
            out_dir / f"paired_{preset}_vs_{against}",
            (".csv", ".md"),
            paired_texts(cross, preset, base_preset=against),
            preset,
            f"each run paired TC by TC with the same run of the {against} preset (McNemar)",
        )
    trial_files = select_trial_files(root, preset)
    hardware = hardware_rows(trial_files)
    written += _write_or_remove(
        out_dir / f"table2_{preset}",
        (".csv", ".md", ".tex"),
        _hardware_texts(hardware, preset, trial_files.note()) if hardware else None,
        preset,
        "Table II: hardware trials per method; rates with the exact 95 % binomial interval",
    )
    return written


def table_meta_text(csv_text: str, preset: str, description: str) -> str:
    """The metadata sidecar (`csv_meta_path`) of a table's CSV, in the result files'
    convention (``{"meta": ..., "columns": ...}``, `distgprl.schema.write_csv`) so that
    `read_csv` reads the table and a plain ``pandas.read_csv`` reads the CSV. Only what the
    committed results determine (no time, no commit): ``make tables`` stays byte for byte."""
    columns = next(csv.reader([csv_text.split("\n", 1)[0]]))
    meta = {
        "schema_version": SCHEMA_VERSION,
        "kind": "table",
        "preset": preset,
        "description": description,
        "rate_intervals_clipped_to": list(RATE_BOUNDS),
    }
    return json.dumps({"meta": meta, "columns": columns}, indent=2) + "\n"


def _write_table(path: Path, text: str, preset: str, description: str) -> list[Path]:
    """Write one table file; a CSV with its metadata sidecar (`table_meta_text`)."""
    written = [atomic_write_text(path, text)]
    if path.suffix == ".csv":
        written.append(
            atomic_write_text(csv_meta_path(path), table_meta_text(text, preset, description))
        )
    return written


def _write_or_remove(
    stem: Path,
    suffixes: tuple[str, ...],
    texts: tuple[str, ...] | None,
    preset: str,
    description: str,
) -> list[Path]:
    """Write ``texts`` (one per suffix) to ``stem`` + suffix; with ``texts`` None
    (nothing to tabulate, e.g. no trial files any more) remove those files instead, so no
    stale table from earlier results is left behind."""
    paths = [Path(f"{stem}{suffix}") for suffix in suffixes]
    if texts is None:
        for path in paths:
            path.unlink(missing_ok=True)
            if path.suffix == ".csv":
                csv_meta_path(path).unlink(missing_ok=True)
        return []
    written = []
    for path, text in zip(paths, texts, strict=True):
        written += _write_table(path, text, preset, description)
    return written
