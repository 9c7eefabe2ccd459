"""Table I (simulation) and Table II (hardware) from result files only.

`write_tables` also writes Table I per run, each run's paired comparisons, TC by TC,
with the `demo` reference and with `dist-gprl` (`distgprl.report.paired`), the robust
aggregates with stratified-bootstrap intervals (`distgprl.report.aggregate`) and the claims
table (`distgprl.report.claims`).

The tables themselves are made by `distgprl.report.table1` (Table I: cells over seeds, the
per-run table; texts `distgprl.report.table1_text`) and `distgprl.report.table2` (Table II:
the hardware trial files); this module writes them, with a metadata sidecar per CSV
(`table_meta_text`), and removes a table the results no longer make. Pure functions of the
files they read.

**Which policy** (docs/findings/protocol.md, rule 6): Table I (``table1_<preset>``), its
per-run table, the aggregates and the claims report each run's best learning-curve policy,
Algorithm 1's output (`distgprl.report.runs.TABLE_POLICY`, the one switch); the final
policy's Table I and per-run table are written beside it (``table1_final_<preset>``). An
untrained reference's one evaluation is in both.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

from distgprl.errors import UserInputError
from distgprl.io import atomic_write_text
from distgprl.report.aggregate import aggregate_texts, tasks_of
from distgprl.report.claims_table import claims_texts
from distgprl.report.onsets import onset_texts
from distgprl.report.paired import (
    FINAL_POLICY,
    REFERENCES,
    best_vs_final_rows,
    cross_preset_rows,
    paired_rows,
    paired_texts,
    supplementary_sizes,
)
from distgprl.report.repair import repair_table, repair_texts
from distgprl.report.robustness import robustness_texts, study_verdicts
from distgprl.report.runs import TABLE_POLICY, run_evaluations
from distgprl.report.table1 import (
    LATE_CURVE_POINTS,
    RATE_BOUNDS,
    aggregate,
    collect_scores,
    late_curve,
    per_seed_rows,
    simulation_table,
)
from distgprl.report.table1_text import per_seed_texts, table1_texts
from distgprl.report.table2 import (
    binomial_interval,
    hardware_rows,
    hardware_table,
    hardware_texts,
    noise_texts,
    select_trial_files,
)
from distgprl.schema import SCHEMA_VERSION, csv_meta_path, moved_robot
from distgprl.studies import studies_of

__all__ = [  # the tables' functions, importable from here as before the split
    "LATE_CURVE_POINTS",
    "aggregate",
    "binomial_interval",
    "hardware_table",
    "late_curve",
    "moved_robot",
    "per_seed_rows",
    "select_trial_files",
    "simulation_table",
    "table_meta_text",
    "write_tables",
]


def write_tables(
    root: str | Path, preset: str, out_dir: str | Path, against: str | None = None
) -> list[Path]:
    """Write Table I of the best policy (``table1_<preset>``, `TABLE_POLICY`) and of the
    final policy (``table1_final_<preset>``), each with its table per run
    (``..._per_seed``: every seed's numbers and wall time), and Table II when hardware
    trials exist, as CSV, Markdown, LaTeX; the
    stratified-bootstrap aggregates (``aggregates_<preset>``: mean, IQM and Dist-GPRL's
    probability of improvement, `distgprl.report.aggregate`) and the claims table
    (``claims_<preset>``: a verdict per paper claim, `distgprl.report.claims`), both on
    Table I's evaluations (`collect_scores` with `TABLE_POLICY`), CSV and Markdown, and
    every run paired TC by TC with the `demo` reference and with `dist-gprl` of the same
    seed where those were evaluated (``paired_vs_<reference>_<preset>``, CSV and Markdown;
    ``..._n<N>`` for supplementary evaluations on N TCs), and, for runs whose best
    learning-curve policy was evaluated, that policy paired with the run's final one
    (``paired_best_vs_final_<preset>``). With ``against`` (another preset), also every run
    paired with the same run of that preset (``paired_<preset>_vs_<against>``, CSV and
    Markdown; `cross_preset_rows`). Table I + repair (``table1_repair_<preset>``, CSV and
    Markdown; `distgprl.report.repair`) where runs have their safety-layer evaluations."""
    rows, tasks = simulation_table(root, preset, TABLE_POLICY)
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
    written: list[Path] = []
    for policy in (TABLE_POLICY, "final"):
        written += _write_table_one(root, preset, out_dir, policy)
    scores = collect_scores(root, preset, TABLE_POLICY)  # the claims follow Table I
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
    studies = studies_of(preset)
    if studies:  # each claim under every reading of every study read beside this preset
        if len({study.seeds for study in studies}) > 1:
            raise ValueError(f"the studies beside {preset} compare at different seeds")
        # every reading, Table I's included, at the studies' seeds (`Study.seeds`): runs a
        # rule alone reads, at further seeds, stay out of every cross-reading verdict
        seeds = studies[0].seeds
        at_seeds = collect_scores(root, preset, TABLE_POLICY, seeds=seeds)
        results = study_verdicts(
            studies, at_seeds, lambda p: collect_scores(root, p, TABLE_POLICY, seeds=seeds)
        )
        written += _write_or_remove(
            out_dir / f"claims_robustness_{preset}",
            (".csv", ".md"),
            robustness_texts(results, preset),
            preset,
            "each claim's verdict under every reading of "
            f"{', '.join(s.name for s in studies)} (rules: distgprl.report.robustness)",
        )
        for study in studies:  # when each run of each reading learns; a control's verdict
            written += _write_or_remove(
                out_dir / f"onsets_{study.name}_{preset}",
                (".csv", ".md"),
                onset_texts(root, study, tasks_of(scores), preset),
                preset,
                f"the {study.name} study's learning-curve onsets per reading and seed "
                "(rules: distgprl.report.onsets)",
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
        hardware_texts(hardware, preset, trial_files.note()) if hardware else None,
        preset,
        "Table II: hardware trials per method; rates with the exact 95 % binomial interval",
    )
    written += _write_or_remove(
        out_dir / f"table2_noise_{preset}",
        (".csv", ".md"),
        noise_texts(hardware, preset),
        preset,
        "digital twin success and collision against the sensor-noise level",
    )
    repair_rows, repair_excluded = repair_table(root, preset)
    written += _write_or_remove(
        out_dir / f"table1_repair_{preset}",
        (".csv", ".md"),
        repair_texts(repair_rows, preset, repair_excluded),
        preset,
        "Table I + repair: the hardware safety layer in the loop in simulation "
        "(distgprl.report.repair)",
    )
    return written


def _write_table_one(root: str | Path, preset: str, out_dir: Path, policy: str) -> list[Path]:
    """Table I and Table I per run of the ``policy`` evaluations: ``table1_<preset>`` for
    `TABLE_POLICY`, ``table1_<policy>_<preset>`` for the other."""
    stem = out_dir / (f"table1_{preset}" if policy == TABLE_POLICY else f"table1_{policy}_{preset}")
    rows, tasks = simulation_table(root, preset, policy)
    note = run_evaluations(root, preset, policy).note()
    which = "best learning-curve policy" if policy == "best" else f"{policy} policy"
    table_one = (
        f"Table I ({which}): per task, each metric's mean, sample std and 95 % t-interval "
        "over seeds (ci_low, ci_high; empty for one seed)"
    )
    written = _write_or_remove(
        stem,
        (".csv", ".md", ".tex"),
        table1_texts(rows, tasks, preset, note, policy),
        preset,
        table_one,
    )
    written += _write_or_remove(
        Path(f"{stem}_per_seed"),
        (".csv", ".md"),
        per_seed_texts(per_seed_rows(root, preset, policy), preset, policy),
        preset,
        f"Table I per run ({which}): every seed's metrics, late learning-curve means and "
        "training wall time",
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
