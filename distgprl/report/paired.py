"""Each run against a reference, TC by TC: discordant TCs and exact McNemar p-values.

Every run of a preset is evaluated on the same TCs, so two runs' outcomes on one TC form a
pair. Seeds are tested one by one, never pooled; p-values are per comparison, not corrected
for multiple comparisons.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any, cast

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
REFERENCES = (UNADAPTED, "dist-gprl")
"""The methods `write_tables` pairs runs with (``paired_vs_<reference>_<preset>``)."""

FINAL_POLICY = "final"
"""The reference of each run's best learning-curve policy: its own final policy."""

OUTCOMES = {"success": "Success", "collision": "Collision", "safe_success": "SafeSucc"}
"""Per-episode outcomes compared (each 0 or 1) and their Markdown labels."""

FIELDS = tuple(
    "task method seed outcome tcs run_rate reference_rate only_run only_reference p_value".split()
)


def mcnemar_exact(only_run: int, only_reference: int) -> float:
    """Exact two-sided McNemar p-value from the two discordant counts (1 if both are 0)."""
    discordant = only_run + only_reference
    return float(stats.binomtest(only_run, discordant).pvalue) if discordant else 1.0


def supplementary_sizes(root: str | Path, preset: str) -> list[int]:
    """The N of a preset's supplementary evaluations (``evaluation_n<N>.csv``), ascending."""
    paths = (Path(root) / preset).glob("*/*/seed*/evaluation_n*.csv")
    digits = (path.stem.removeprefix("evaluation_n") for path in paths)
    return sorted({int(n) for n in digits if n.isdigit()})


def evaluated_runs(runs: Iterable[Path], *names: str) -> list[Path]:
    """The run folders ``.../<task>/<method>/seed<k>`` of a method among ``runs`` that hold
    every file of ``names``, in task, table and seed order."""
    evaluated = [
        r for r in runs if r.parent.name in METHODS and all((r / n).exists() for n in names)
    ]
    return sorted(evaluated, key=_run_order)


def _run_order(run: Path) -> tuple[int, str, int, int]:
    task, method, seed = run.parts[-3:]
    return task_order(task), task, TABLE_ORDER.index(method), int(seed.removeprefix("seed"))


def paired_rows(
    root: str | Path,
    preset: str,
    reference: str = UNADAPTED,
    episodes: int | None = None,
    base_preset: str | None = None,
) -> list[dict[str, Any]]:
    """`FIELDS` rows per run of ``preset`` that counts and outcome (`evaluated_runs` and
    `OUTCOMES` order) against ``reference``'s run of the task (`UNADAPTED`: its seed 0; a
    method: the same seed), on the preset's TCs or its supplementary evaluation on
    ``episodes`` TCs; `FINAL_POLICY`: the run's best policy against its final one;
    ``base_preset``: against the same run there. No rows of `UNADAPTED` or ``reference``, nor
    of a run whose counterpart does not count or lacks the evaluation.

    Raises:
        ValueError: ``reference`` is neither a method nor `FINAL_POLICY`; a pair's TCs differ.
        UserInputError: ``base_preset`` is ``preset``; a cross-preset pair's TCs differ.
    """
    if reference not in METHODS and reference != FINAL_POLICY:
        raise ValueError(f"unknown reference method {reference!r}")
    if base_preset == preset:
        raise UserInputError(f"--against {base_preset}: pair a preset with another preset")
    final = evaluation_file_names(episodes)[0]
    name = evaluation_file_names(episodes, "best")[0] if reference == FINAL_POLICY else final
    runs = select_runs(root, preset).current
    references = select_runs(root, base_preset).current if base_preset else runs
    pairs = []
    for run in evaluated_runs(runs, name):
        task, method, seed = run.parts[-3:]
        if base_preset:
            other = Path(root) / base_preset / task / method / seed
        elif reference == FINAL_POLICY:
            other = run
        else:
            other = run.parents[1] / reference / ("seed0" if reference == UNADAPTED else seed)
        counted = other in references and (other / final).exists()
        if counted and method not in (UNADAPTED, reference):
            pairs.append((run / name, other / final))
    try:
        return [
            row for run_file, other_file in pairs for row in pair_evaluations(run_file, other_file)
        ]
    except ValueError as exc:
        if base_preset is None:
            raise
        message = f"{exc}; presets {preset} and {base_preset} do not evaluate on the same TCs"
        raise UserInputError(message) from None


def pair_evaluations(
    run_file: Path, reference_file: Path, outcomes: tuple[str, ...] = tuple(OUTCOMES)
) -> list[dict[str, Any]]:
    """The `FIELDS` rows of two evaluations of the same TCs, one per ``outcomes`` (of
    `OUTCOMES` and ``refused``).

    Raises:
        ValueError: the two files hold different TCs.
    """
    mine, theirs = csv_frame(run_file, {}), csv_frame(reference_file, {})
    if len(mine) != len(theirs):
        raise ValueError(
            f"{run_file}: {len(mine)} evaluation TCs, the reference {reference_file} has "
            f"{len(theirs)}; re-evaluate one of them on the preset's TCs"
        )
    tcs = list(EVALUATION_FIELDS[:5])  # episode index and the four offsets (m)
    differs = (mine[tcs] != theirs[tcs]).any(axis=1)
    if differs.any():
        raise ValueError(
            f"{run_file}: evaluation TC {mine['episode'][differs].iloc[0]} differs from the "
            f"reference's ({reference_file}); the pairs would compare different TCs"
        )
    run, reference = (_outcomes(episodes)[list(outcomes)] for episodes in (mine, theirs))
    task, method, seed = run_file.parts[-4:-1]
    pairs = pd.DataFrame(
        {
            "task": task,
            "method": method,
            "seed": int(seed.removeprefix("seed")),
            "outcome": list(outcomes),
            "tcs": len(run),
            "run_rate": run.sum() / len(run),
            "reference_rate": reference.sum() / len(run),
            "only_run": (run > reference).sum(),
            "only_reference": (run < reference).sum(),
        }
    )
    pairs["p_value"] = list(map(mcnemar_exact, pairs["only_run"], pairs["only_reference"]))
    return cast(list[dict[str, Any]], pairs.to_dict("records"))


def _outcomes(episodes: pd.DataFrame) -> pd.DataFrame:
    """`OUTCOMES` and ``refused`` of one evaluation's episodes, 0 or 1 per TC (no ``refused``
    column: nothing refused)."""
    flags = episodes.reindex(columns=["success", "collision", "refused"], fill_value=0)
    safe = flags.apply(is_safe_success, axis=1)
    return flags.astype(int).assign(safe_success=safe.astype(int))


def paired_table(
    root: str | Path,
    preset: str,
    reference: str = UNADAPTED,
    episodes: int | None = None,
    base_preset: str | None = None,
) -> tuple[str, tuple[str, str] | None, str]:
    """(file stem, (CSV, Markdown: a line per run) or None without rows, sidecar description)
    of `paired_rows` (arguments as there).

    Raises:
        UserInputError: no run has a counterpart in ``base_preset``.
    """
    rows = paired_rows(root, preset, reference, episodes, base_preset)
    if base_preset:
        stem = f"paired_{preset}_vs_{base_preset}"
        about = f"each run paired TC by TC with the same run of the {base_preset} preset (McNemar)"
        against = f"the run of the same task, method and seed in the {base_preset} preset"
        if not rows:
            raise UserInputError(
                f"--against {base_preset}: no run of {Path(root) / preset} has a finished "
                f"counterpart (same task, method and seed) under {Path(root) / base_preset}"
            )
    elif reference == FINAL_POLICY:
        stem = f"paired_best_vs_final_{preset}"
        about = "each run's best learning-curve policy paired TC by TC with its final one (McNemar)"
        against = (
            "its own final policy (run: its best learning-curve policy, "
            "`distgprl evaluate --policy best`, Table I's; reference: its final policy, "
            "`table1_final`)"
        )
    else:
        stem = f"paired_vs_{reference}_{preset}{f'_n{episodes}' if episodes else ''}"
        about = f"each run paired TC by TC with the {reference} reference (McNemar)"
        label = METHODS[reference].label
        against = (
            "the unadapted reference" if reference == UNADAPTED else f"{label} of the same seed"
        )
    if not rows:
        return stem, None, about
    supplementary = f"; supplementary evaluation on the first {episodes} TCs" if episodes else ""
    title = (
        f"Each run against {against} on the same evaluation TCs ({preset} preset"
        f"{supplementary})\n\nRates of the run and of the reference; discordant TCs (only the "
        "run / only the reference has the outcome); exact two-sided McNemar p-value, per "
        "comparison (not corrected for multiple comparisons)."
    )
    header = ["Task", "Method", "Seed", "TCs"]
    for label in OUTCOMES.values():
        header += [f"{label} run / ref", f"{label} only run / only ref", f"{label} p"]
    table = []
    for start in range(0, len(rows), len(OUTCOMES)):
        first = rows[start]
        cells = [first["task"].upper(), METHODS[first["method"]].label]
        cells += [str(first["seed"]), str(first["tcs"])]
        for row in rows[start : start + len(OUTCOMES)]:
            p = row["p_value"]
            cells += [
                f"{row['run_rate']:.2f} / {row['reference_rate']:.2f}",
                f"{row['only_run']} / {row['only_reference']}",
                "< 0.001" if p < 0.001 else f"{p:.3f}",
            ]
        table.append(cells)
    return stem, (csv_text(rows, FIELDS), markdown_table(title, header, table)), about
