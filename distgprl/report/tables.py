"""Every results table of a preset from its result files only (`write_tables`): each made
by its module (imported below), written here with a metadata sidecar per CSV
(`write_table_files`); a table the results no longer make is removed. Table I, its per-run
table, the aggregates and the claims report `TABLE_POLICY`'s evaluations (protocol v6, rule
6, docs/findings/protocol.md); the final policy's Table I and per-run table are written
beside them (``table1_final_<preset>``), and where the preset's folder holds runs of the
study methods (`distgprl.methods.STUDY_METHODS`) their table beside Table I
(``one_demo_study_<preset>``).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from distgprl.errors import UserInputError
from distgprl.methods import STUDY_METHODS
from distgprl.report.aggregate import Scores, aggregate_texts, tasks_of
from distgprl.report.claims import claims_texts
from distgprl.report.frame import Frames, load_frames
from distgprl.report.markdown import write_table_files
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
from distgprl.report.runs import TABLE_POLICY
from distgprl.report.table1 import (
    POLICY_TITLES,
    RATE_BOUNDS,
    collect_scores,
    per_seed_rows,
    per_seed_texts,
    simulation_table,
    table1_texts,
)
from distgprl.report.table2 import hardware_rows, hardware_texts, noise_texts, select_trial_files
from distgprl.studies import studies_of

Table = tuple[str, tuple[str, ...] | None, str]
"""One table to write: (file stem, texts — CSV, Markdown and for Tables I and II LaTeX; None
to remove the files —, description for the CSV's sidecar)."""

ONE_DEMO_STUDY = ("promp-rrl", "promp-rrl-1demo", "promp-nominal", "promp-nominal-1demo")
"""The rows of the one-demonstration study beside Table I (protocol v8, rule 3): Table I's
ProMP-RRL and ProMP nominal (20 demonstrations) above their one-demonstration versions."""

SUFFIXES = (".csv", ".md", ".tex")
"""The file suffix of each of a table's texts, in order."""


def write_tables(
    root: str | Path, preset: str, out_dir: str | Path, against: str | None = None
) -> list[Path]:
    """Write every table of ``<root>/<preset>`` to ``out_dir`` (module docstring) and return
    the paths: Table I of the best and the final policy with their per-run tables, the
    aggregates and claims of Table I's evaluations and the studies beside the preset, the
    paired comparisons (and with another preset, ``against``, each run with its counterpart)
    and the hardware tables."""
    best = load_frames(root, preset, TABLE_POLICY)
    tables = _table_one(best, root, preset, TABLE_POLICY)  # first: no runs, nothing written
    tables += _table_one(load_frames(root, preset, "final"), root, preset, "final")
    tables.append(_one_demo_study(root, preset))
    scores = collect_scores(best)  # the claims follow Table I
    tables += [
        (
            f"aggregates_{preset}",
            aggregate_texts(scores, preset),
            "mean, IQM and probability of improvement over seeds with 95 % "
            "stratified-bootstrap intervals (distgprl.report.aggregate)",
        ),
        (
            f"claims_{preset}",
            claims_texts(scores, preset),
            "each claim of the paper, the statistic testing it and the verdict "
            "(rules: distgprl.report.claims)",
        ),
        *_study_tables(root, preset, best, scores),
        *_paired_tables(root, preset, against),
        *_hardware_tables(root, preset),
    ]
    out_dir = Path(out_dir)
    extra = {"rate_intervals_clipped_to": list(RATE_BOUNDS)}
    written = []
    for stem, texts, description in tables:
        suffixes = SUFFIXES if texts is None else SUFFIXES[: len(texts)]
        written += write_table_files(out_dir / stem, suffixes, texts, preset, description, **extra)
    for stale in out_dir.glob(f"paired_vs_*_{preset}_n*.*"):  # sizes no longer present
        if stale not in written:
            stale.unlink()
    return written


def _table_one(frames: Frames, root: str | Path, preset: str, policy: str) -> list[Table]:
    """Table I and Table I per run of the ``policy`` evaluations (``frames``):
    ``table1_<preset>`` for `TABLE_POLICY`, ``table1_<policy>_<preset>`` for the other.

    Raises:
        UserInputError: the preset has no evaluated run.
    """
    rows, tasks = simulation_table(frames)
    if not rows:
        raise UserInputError(f"{Path(root) / preset}: no summary.json files; run a sweep first")
    stem = f"table1_{preset}" if policy == TABLE_POLICY else f"table1_{policy}_{preset}"
    which = "best learning-curve policy" if policy == "best" else f"{policy} policy"
    texts = table1_texts(rows, tasks, preset, frames.runs.attrs["note"], policy)
    return [
        (
            stem,
            texts,
            f"Table I ({which}): per task, each metric's mean, sample std and 95 % t-interval "
            "over seeds (ci_low, ci_high; empty for one seed)",
        ),
        (
            f"{stem}_per_seed",
            per_seed_texts(per_seed_rows(frames), preset, policy),
            f"Table I per run ({which}): every seed's metrics, late learning-curve means and "
            "training wall time",
        ),
    ]


def _one_demo_study(root: str | Path, preset: str) -> Table:
    """The one-demonstration study beside Table I: Table I's columns for `ONE_DEMO_STUDY`'s
    runs (`TABLE_POLICY`), CSV and Markdown; None (no file) without a study method's run."""
    frames = load_frames(root, preset, TABLE_POLICY, methods=ONE_DEMO_STUDY)
    rows, tasks = simulation_table(frames, ONE_DEMO_STUDY)
    heading = (
        f"The one-demonstration ProMP-RRL study beside Table I ({preset} preset, "
        f"{POLICY_TITLES[TABLE_POLICY]}): ProMP-RRL and ProMP nominal are Table I's, over 20 "
        "demonstrations (protocol v8, rule 3); the (1 demo) rows fit the ProMP's nominal to the "
        "one demonstration every GP method gets. Not part of Table I or the claims"
    )
    note = frames.runs.attrs["note"]
    studied = any(row["method"] in STUDY_METHODS for row in rows)
    texts = table1_texts(rows, tasks, preset, note, TABLE_POLICY, heading)[:2] if studied else None
    about = "the one-demonstration ProMP-RRL study beside Table I, Table I's columns"
    return (f"one_demo_study_{preset}", texts, about)


def _study_tables(root: str | Path, preset: str, frames: Frames, scores: Scores) -> Iterator[Table]:
    """Beside a preset with studies (`studies_of`): each claim under every reading of every
    study, Table I's included (``frames``), at the studies' seeds (runs a rule alone reads,
    at further seeds, stay out of every cross-reading verdict), and per study when each run
    of each reading learns (its onsets, a control's verdict)."""
    studies = studies_of(preset)
    if not studies:
        return
    if len({study.seeds for study in studies}) > 1:
        raise ValueError(f"the studies beside {preset} compare at different seeds")
    seeds = studies[0].seeds
    results = study_verdicts(
        studies,
        collect_scores(frames.of_seeds(seeds)),
        lambda p: collect_scores(load_frames(root, p, TABLE_POLICY, seeds)),
    )
    names = ", ".join(s.name for s in studies)
    about = (
        f"each claim's verdict under every reading of {names} (rules: distgprl.report.robustness)"
    )
    yield (f"claims_robustness_{preset}", robustness_texts(results, preset), about)
    for study in studies:
        yield (
            f"onsets_{study.name}_{preset}",
            onset_texts(root, study, tasks_of(scores), preset),
            f"the {study.name} study's learning-curve onsets per reading and seed "
            "(rules: distgprl.report.onsets)",
        )


def _paired_tables(root: str | Path, preset: str, against: str | None) -> Iterator[Table]:
    """Every run paired TC by TC with each of `REFERENCES` (on the preset's TCs and on each
    supplementary evaluation's), each run's best policy with its final one, and with a
    preset ``against`` every run with the same run of it.

    Raises:
        UserInputError: no run of ``preset`` has a finished counterpart under ``against``.
    """
    for reference in REFERENCES:
        for episodes in (None, *supplementary_sizes(root, preset)):
            pairs = paired_rows(root, preset, reference, episodes)
            yield (
                f"paired_vs_{reference}_{preset}{f'_n{episodes}' if episodes else ''}",
                paired_texts(pairs, preset, reference, episodes) if pairs else None,
                f"each run paired TC by TC with the {reference} reference (McNemar)",
            )
    best = best_vs_final_rows(root, preset)
    yield (
        f"paired_best_vs_final_{preset}",
        paired_texts(best, preset, FINAL_POLICY) if best else None,
        "each run's best learning-curve policy paired TC by TC with its final one (McNemar)",
    )
    if against is None:
        return
    cross = cross_preset_rows(root, preset, against)
    if not cross:
        raise UserInputError(
            f"--against {against}: no run of {Path(root) / preset} has a finished "
            f"counterpart (same task, method and seed) under {Path(root) / against}"
        )
    yield (
        f"paired_{preset}_vs_{against}",
        paired_texts(cross, preset, base_preset=against),
        f"each run paired TC by TC with the same run of the {against} preset (McNemar)",
    )


def _hardware_tables(root: str | Path, preset: str) -> list[Table]:
    """Table II and its noise table of the preset's trial files, and Table I + repair."""
    trial_files = select_trial_files(root, preset)
    hardware = hardware_rows(trial_files)
    repair_rows, repair_excluded = repair_table(root, preset)
    return [
        (
            f"table2_{preset}",
            hardware_texts(hardware, preset, trial_files.note()) if hardware else None,
            "Table II: hardware trials per method; rates with the exact 95 % binomial interval",
        ),
        (
            f"table2_noise_{preset}",
            noise_texts(hardware, preset),
            "digital twin success and collision against the sensor-noise level",
        ),
        (
            f"table1_repair_{preset}",
            repair_texts(repair_rows, preset, repair_excluded),
            "Table I + repair: the hardware safety layer in the loop in simulation "
            "(distgprl.report.repair)",
        ),
    ]
