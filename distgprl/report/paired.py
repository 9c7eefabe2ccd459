"""Each run against a reference, TC by TC (exact McNemar tests).

Every run of a preset is evaluated on the same fixed evaluation TCs, so two runs' outcomes on
one TC form a pair: these tables say whether a rate difference of Table I is more than the
luck of 100 TCs. References (`REFERENCES`): the unadapted `demo` (its seed 0, paired with
every run) and `dist-gprl` (paired with every other method's run of the same seed); also each
run's best policy against its final one (`best_vs_final_rows`), a preset against the one it
varies (`cross_preset_rows`) and supplementary evaluations on N TCs (`supplementary_sizes`).
Per run and outcome (`OUTCOMES`) the discordant TCs and the exact two-sided McNemar p-value
(`mcnemar_exact`); seeds share the TCs and are tested one by one, never pooled; p-values are
per comparison, not corrected for the number of comparisons. The ``*_rows`` functions pair runs
that count (`select_runs`) on both sides and return `FIELDS` rows in task, table and seed order,
outcomes in `OUTCOMES` order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from distgprl.data import task_order
from distgprl.errors import UserInputError
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.frame import csv_frame
from distgprl.report.markdown import csv_text, markdown_table
from distgprl.report.runs import select_runs
from distgprl.schema import EVALUATION_FIELDS, evaluation_file_names, is_safe_success

UNADAPTED = "demo"
"""The unadapted reference: evaluated once per task (seed 0), paired with every seed."""

REFERENCES = (UNADAPTED, "dist-gprl")
"""The methods `write_tables` pairs runs with (``paired_vs_<reference>_<preset>``)."""

FINAL_POLICY = "final"
"""`paired_texts`' reference for `best_vs_final_rows`: each run's own final policy."""

TC_FIELDS = EVALUATION_FIELDS[:5]
"""The columns that identify an evaluation TC: episode index and the four offsets (m)."""

OUTCOMES = (
    ("success", "Success"),
    ("collision", "Collision"),
    ("safe_success", "SafeSucc"),
)
"""Per-episode outcomes compared (each 0 or 1)."""

FIELDS = tuple(
    "task method seed outcome tcs run_rate reference_rate only_run only_reference p_value".split()
)
"""Columns of ``paired_vs_<reference>_<preset>.csv``: one row per (run, outcome)."""


def mcnemar_exact(only_run: int, only_reference: int) -> float:
    """Exact two-sided McNemar p-value from the two discordant counts (1 if both are 0)."""
    discordant = only_run + only_reference
    if discordant == 0:
        return 1.0
    return float(stats.binomtest(only_run, discordant, 0.5).pvalue)


def _outcomes(episodes: pd.DataFrame) -> pd.DataFrame:
    """`OUTCOMES` of one evaluation's episodes (a `csv_frame`): a column each, 0 or 1 per TC."""
    outcomes = episodes[["success", "collision"]].astype(int)
    pairs = zip(outcomes["success"], outcomes["collision"], strict=True)
    safe = [is_safe_success({"success": s, "collision": c}) for s, c in pairs]
    return outcomes.assign(safe_success=np.array(safe, dtype=int))


def _check_same_tcs(run: Path, reference: Path, mine: pd.DataFrame, theirs: pd.DataFrame) -> None:
    """Raise ValueError unless both evaluations hold the same TCs in the same order."""
    if len(mine) != len(theirs):
        raise ValueError(
            f"{run}: {len(mine)} evaluation TCs, the reference {reference} has "
            f"{len(theirs)}; re-evaluate one of them on the preset's TCs"
        )
    same = mine[list(TC_FIELDS)].to_numpy(float) == theirs[list(TC_FIELDS)].to_numpy(float)
    if not same.all():
        episode = mine["episode"].iloc[int(np.flatnonzero(~same.all(axis=1))[0])]
        raise ValueError(
            f"{run}: evaluation TC {episode} differs from the reference's "
            f"({reference}); the pairs would compare different TCs"
        )


def supplementary_sizes(root: str | Path, preset: str) -> list[int]:
    """The N of the supplementary evaluations (``evaluation_n<N>.csv``) under
    ``<root>/<preset>``, ascending."""
    paths = (Path(root) / preset).glob("*/*/seed*/evaluation_n*.csv")
    digits = (path.stem.removeprefix("evaluation_n") for path in paths)
    return sorted({int(n) for n in digits if n.isdigit()})


def paired_rows(
    root: str | Path, preset: str, reference: str = UNADAPTED, episodes: int | None = None
) -> list[dict[str, Any]]:
    """Every run under ``<root>/<preset>`` paired with ``reference``'s evaluated run on the
    same task (`UNADAPTED`: its seed 0; any other method: the same seed); the reference's own
    runs and `UNADAPTED` are not rows. ``episodes``: None pairs the preset's evaluations; N
    the supplementary evaluations on N TCs.

    Raises:
        ValueError: ``reference`` is not a method; a run's evaluation TCs differ from its
            reference's.
    """
    if reference not in METHODS:
        raise ValueError(f"unknown reference method {reference!r}")
    file_name = evaluation_file_names(episodes)[0]
    current = select_runs(root, preset).current
    pairs = []
    for task, method, folder in _evaluated(current, file_name):
        seed = "seed0" if reference == UNADAPTED else folder.name
        if method not in (reference, UNADAPTED):
            reference_file = Path(root) / preset / task / reference / seed / file_name
            pairs.append((folder / file_name, reference_file))
    return _paired_files(pairs, current)


def _evaluated(current: frozenset[Path], file_name: str) -> list[tuple[str, str, Path]]:
    """(task, method, folder) of every run folder ``.../<task>/<method>/seed<k>`` of a method
    among ``current`` that holds ``file_name``, in folder order."""
    return [
        (folder.parent.parent.name, folder.parent.name, folder)
        for folder in sorted(current)
        if folder.parent.name in METHODS and (folder / file_name).exists()
    ]


def cross_preset_rows(root: str | Path, preset: str, base_preset: str) -> list[dict[str, Any]]:
    """Every run of ``preset`` (the "run" columns) paired with the run of the same task,
    method and seed in ``base_preset`` (the "reference" columns) on the preset's evaluation
    TCs: an exploration preset against the configuration it varies (``correlated`` against
    ``paper``). Runs without a counterpart and the `demo` reference are not rows.

    Raises:
        UserInputError: the two presets are the same; a pair's evaluation TCs differ (the
            presets evaluate on different TCs, e.g. ``ci`` against ``paper``).
    """
    if preset == base_preset:
        raise UserInputError(f"--against {base_preset}: pair a preset with another preset")
    file_name = evaluation_file_names()[0]
    pairs = [
        (folder / file_name, Path(root) / base_preset / task / method / folder.name / file_name)
        for task, method, folder in _evaluated(select_runs(root, preset).current, file_name)
        if method != UNADAPTED
    ]
    try:
        return _paired_files(pairs, select_runs(root, base_preset).current)
    except ValueError as exc:
        raise UserInputError(
            f"{exc}; presets {preset} and {base_preset} do not evaluate on the same TCs"
        ) from None


def best_vs_final_rows(root: str | Path, preset: str) -> list[dict[str, Any]]:
    """Per run that has one, the evaluation of its best learning-curve policy
    (``evaluation_best.csv``, ``distgprl evaluate --policy best``; the "run" columns) paired
    with its own final policy's on the same TCs (``evaluation.csv``; the "reference" columns).

    Raises:
        ValueError: the two evaluations of a run hold different TCs.
    """
    best_name = evaluation_file_names(None, "best")[0]
    current = select_runs(root, preset).current
    pairs = [
        (folder / best_name, folder / evaluation_file_names()[0])
        for _, _, folder in _evaluated(current, best_name)
    ]
    return _paired_files(pairs, current)


def _paired_files(
    pairs: list[tuple[Path, Path]], reference_runs: frozenset[Path]
) -> list[dict[str, Any]]:
    """The rows of each (run, reference) pair of evaluation files of runs
    ``.../<task>/<method>/seed<k>/`` whose reference file exists in a run folder of
    ``reference_runs``, TC by TC (each file's episodes a `csv_frame`); a reference shared by
    several runs is read once.

    Raises:
        ValueError: the two files of a pair hold different TCs.
    """
    references: dict[Path, pd.DataFrame] = {}
    rows = []
    for run_file, reference_file in sorted(pairs, key=lambda pair: _run_order(pair[0])):
        if reference_file.parent not in reference_runs or not reference_file.exists():
            continue
        if reference_file not in references:
            references[reference_file] = csv_frame(reference_file, {})
        theirs = references[reference_file]
        mine = csv_frame(run_file, {})
        _check_same_tcs(run_file, reference_file, mine, theirs)
        task, method, folder = run_file.parts[-4:-1]
        run = {"task": task, "method": method, "seed": int(folder.removeprefix("seed"))}
        rows += _pair(run, _outcomes(mine), _outcomes(theirs))
    return rows


def _run_order(run_file: Path) -> tuple[int, str, int, int]:
    """The sort key of a run's file ``.../<task>/<method>/seed<k>/<file>``: task, table and
    seed order."""
    task, method, folder = run_file.parts[-4:-1]
    return task_order(task), task, TABLE_ORDER.index(method), int(folder.removeprefix("seed"))


def _pair(
    run: dict[str, Any], outcomes: pd.DataFrame, reference_outcomes: pd.DataFrame
) -> list[dict[str, Any]]:
    """One `FIELDS` row per outcome: a run's episodes (``run`` its task, method and seed)
    against the reference's, TC by TC (both `_outcomes` frames)."""
    mine, theirs = outcomes.to_numpy(), reference_outcomes.to_numpy()  # (TCs, outcomes)
    only_run = ((mine == 1) & (theirs == 0)).sum(axis=0)
    only_reference = ((mine == 0) & (theirs == 1)).sum(axis=0)
    return [
        {
            **run,
            "outcome": outcome,
            "tcs": len(mine),
            "run_rate": int(mine[:, k].sum()) / len(mine),
            "reference_rate": int(theirs[:, k].sum()) / len(theirs),
            "only_run": int(only_run[k]),
            "only_reference": int(only_reference[k]),
            "p_value": mcnemar_exact(int(only_run[k]), int(only_reference[k])),
        }
        for k, (outcome, _) in enumerate(OUTCOMES)
    ]


def paired_texts(
    rows: list[dict[str, Any]],
    preset: str,
    reference: str = UNADAPTED,
    episodes: int | None = None,
    base_preset: str | None = None,
) -> tuple[str, str]:
    """(CSV, Markdown) of `paired_rows` against ``reference`` (``episodes`` as there), or,
    with ``base_preset``, of `cross_preset_rows` against that preset; the Markdown has one
    line per run."""
    header = ["Task", "Method", "Seed", "TCs"]
    for _, label in OUTCOMES:
        header += [f"{label} run / ref", f"{label} only run / only ref", f"{label} p"]
    against = (
        f"the run of the same task, method and seed in the {base_preset} preset"
        if base_preset
        else _reference_text(reference)
    )
    supplementary = f"; supplementary evaluation on the first {episodes} TCs" if episodes else ""
    title = (
        f"Each run against {against} on the same evaluation TCs ({preset} preset"
        f"{supplementary})\n\nRates of the run and of the reference; discordant TCs (only the "
        "run / only the reference has the outcome); exact two-sided McNemar p-value, per "
        "comparison (not corrected for multiple comparisons)."
    )
    table = []
    for start in range(0, len(rows), len(OUTCOMES)):
        run = rows[start : start + len(OUTCOMES)]
        first = run[0]
        cells = [first["task"].upper(), METHODS[first["method"]].label]
        cells += [str(first["seed"]), str(first["tcs"])]
        for row in run:
            p = row["p_value"]
            cells += [
                f"{row['run_rate']:.2f} / {row['reference_rate']:.2f}",
                f"{row['only_run']} / {row['only_reference']}",
                "< 0.001" if p < 0.001 else f"{p:.3f}",
            ]
        table.append(cells)
    return csv_text(rows, FIELDS), markdown_table(title, header, table)


def _reference_text(reference: str) -> str:
    if reference == FINAL_POLICY:
        return (
            "its own final policy (run: its best learning-curve policy, "
            "`distgprl evaluate --policy best`; reference: the final policy Table I evaluates)"
        )
    if reference == UNADAPTED:
        return "the unadapted reference"
    return f"{METHODS[reference].label} of the same seed"
