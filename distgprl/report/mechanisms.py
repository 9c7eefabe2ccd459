"""The mechanism table (docs/findings/protocol.md, rule 7; issue 48 item 7).

Whether the paper's mechanisms act, for a preset's runs, in three parts:

1. **Reach** per trainable method, task and position axis: one-step and one-episode reach (m)
   of a raw action in [-1, 1] against the task's TC range, and whether the smallest
   one-episode reach covers the TC range on x and y. Computed from the methods' environments
   by `distgprl.experiments.mechanisms.reach_rows` and passed in as rows (this module reads
   result files only).
2. **Shaping shares of the return**, per method with distance rewards and policy (final,
   best): over the evaluation episodes that pass within d_min (``min_clearance`` <
   ``sd_d_min`` of the run's config), the per-episode |sum r_sd| / |sum r_tc| and
   |sum lambda_ga r_ga| / |sum r_tc| (``return_sd``, ``return_ga``, ``return_tc`` of the
   evaluation rows), their mean and median over the episodes of every seed. An episode whose
   r_tc sums to 0 has no ratio: it is counted and left out. Evaluation files written before
   these columns: "not recorded".
3. **Regulariser shares of the actor gradient**, per method with L_sim or L_hap: at the
   first, middle and last learning-curve points that recorded gradients (``grad_q`` > 0 in
   ``progress.csv``), grad_sim / grad_q and grad_hap / grad_q, and L_hap's share where it
   acts (``grad_hap_active`` / grad_q over the samples outside C_safe, with the share of
   such samples ``hap_active_fraction``), each the mean over seeds.

Each share is marked against the pre-registered criterion (`CRITERION`: ≥ 5 %; for L_hap
outside C_safe) and each term gets a one-line verdict. Written as
``mechanisms_<preset>.csv`` (with its metadata sidecar, as `distgprl.report.tables` writes
tables) and ``.md``. The cells are computed by `distgprl.report.mechanism_shares` (pure
functions of rows), the texts by `distgprl.report.mechanisms_text`; this module reads the
files. Imports neither torch nor pybullet.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from distgprl.config_types import EnvConfig
from distgprl.errors import UserInputError
from distgprl.methods import METHODS
from distgprl.report.markdown import write_table_files
from distgprl.report.mechanism_shares import (
    CRITERION,
    GradientCell,
    MechanismTable,
    PlateauCell,
    ReturnCell,
    gradient_cells,
    plateau_cell,
    return_cells,
)
from distgprl.report.mechanisms_text import mechanism_texts
from distgprl.report.runs import select_runs
from distgprl.schema import evaluation_file_names, read_csv


def _env(folder: Path, field: str) -> float:
    """An `EnvConfig` field of the run's recorded config (its default if absent)."""
    document = json.loads((folder / "config.json").read_text())
    env = document.get("run", {}).get("config", {}).get("env", {})
    return float(env.get(field, getattr(EnvConfig, field)))


def _d_min(folder: Path) -> float:
    """``sd_d_min`` (m) of the run's recorded config (`EnvConfig`'s default if absent)."""
    return _env(folder, "sd_d_min")


def _key(folder: Path) -> tuple[str, str]:
    return folder.parent.parent.name, folder.parent.name


def mechanism_table(
    root: str | Path, preset: str, reach: Sequence[Mapping[str, Any]]
) -> MechanismTable:
    """The `MechanismTable` of the preset's runs under ``root`` (evaluated runs of the
    current configuration for the return shares, trained ones for the gradient shares:
    `distgprl.report.runs.select_runs`), with the ``reach`` rows of
    `distgprl.experiments.mechanisms.reach_rows`."""
    evaluated = select_runs(root, preset)
    trained = select_runs(root, preset, marker="done.json")
    returns: list[ReturnCell] = []
    by_method: dict[tuple[str, str], list[Path]] = {}
    for folder in sorted(evaluated.current):
        if METHODS[_key(folder)[1]].distance_rewards:
            by_method.setdefault(_key(folder), []).append(folder)
    plateau: list[PlateauCell] = []
    for (task, method), folders in sorted(by_method.items()):
        for policy in ("final", "best"):
            name = evaluation_file_names(None, policy)[0]
            found = [f for f in folders if (f / name).exists()]
            rows = {f: read_csv(f / name)[1] for f in found}
            runs = [(rows[f], _d_min(f)) for f in found]
            if runs:
                returns += return_cells(task, method, policy, runs)
            cell = plateau_cell(
                task, method, policy, [(rows[f], _env(f, "progress_weight")) for f in found]
            )
            if cell is not None:
                plateau.append(cell)
    gradients: list[GradientCell] = []
    progress: dict[tuple[str, str], list[Path]] = {}
    for folder in sorted(trained.current):
        spec = METHODS[_key(folder)[1]]
        if spec.trainable and (spec.similarity_loss or spec.hap_prior):
            progress.setdefault(_key(folder), []).append(folder)
    for (task, method), folders in sorted(progress.items()):
        runs_rows = [read_csv(f / "progress.csv")[1] for f in folders]
        gradients += gradient_cells(task, method, runs_rows)
    if not (reach or returns or gradients):
        raise UserInputError(f"{Path(root) / preset}: no runs to tabulate; run a sweep first")
    note = ". ".join(dict.fromkeys(part for part in (evaluated.note(), trained.note()) if part))
    return MechanismTable(
        preset, tuple(reach), tuple(returns), tuple(gradients), note, tuple(plateau)
    )


DESCRIPTION = (
    "the mechanism table (FINDINGS Protocol v6 rule 7): reach against the TC range, shaping "
    "shares of the return, regulariser shares of the actor gradient (distgprl.report.mechanisms)"
)


def write_mechanisms(
    root: str | Path, preset: str, out_dir: str | Path, reach: Sequence[Mapping[str, Any]]
) -> tuple[list[Path], list[str]]:
    """Write ``<out_dir>/mechanisms_<preset>.csv`` (with its sidecar, `write_table_files`)
    and ``.md``; returns (the paths written, the one-line verdicts per term)."""
    csv_text, markdown, verdicts = mechanism_texts(mechanism_table(root, preset, reach))
    stem = Path(out_dir) / f"mechanisms_{preset}"
    texts = (csv_text, markdown)
    written = write_table_files(
        stem, (".csv", ".md"), texts, preset, DESCRIPTION, criterion=CRITERION
    )
    return written, verdicts
