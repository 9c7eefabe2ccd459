"""Learning curves seed by seed and the panels a study reads them in: one source for the curve
figures, the onset tables and the onset figure."""

from __future__ import annotations

import numpy as np
import pandas as pd

from distgprl.methods import METHODS
from distgprl.report.aggregate import PROPOSED, short_label
from distgprl.studies import Study

PANELS = (
    ("success_rate", "success rate", "success rate (curve TCs)", True),
    ("collision_rate", "collision rate", "collision rate (curve TCs)", True),
    ("mean_return", "episode return", "mean episode return", False),
)
"""The curve metrics drawn: (``progress.csv`` column, title, y label, is a rate in [0, 1])."""

SEED_COLORS = ("C0", "C1", "C2", "C3", "C4", "C5", "C6", "C8", "C9")
"""Seed k's colour in the seed-by-seed figures: the k-th, cycling."""

SeedCurves = dict[int, tuple[np.ndarray, dict[str, np.ndarray]]]
"""{seed: (steps (k,), {`PANELS` metric: (k,)})}."""


def run_curves(frame: pd.DataFrame, task: str, method: str) -> SeedCurves:
    """The `SeedCurves` of ``task`` and ``method`` in a `distgprl.report.frame.curve_frame`."""
    mine = frame[(frame["task"] == task) & (frame["method"] == method)]
    return {
        int(str(seed)): (
            points["step"].to_numpy(),
            {k: points[k].to_numpy(dtype=float) for k, *_ in PANELS},
        )
        for seed, points in mine.groupby("seed")
    }


def reading_columns(study: Study) -> list[tuple[str, str, str]]:
    """(preset, method, title) per reading curve panel: the studied method (Dist-GPRL where
    trained) under each reading, then for an operator study Dist-GPRL-NoCov (no operator)."""
    method = PROPOSED if PROPOSED in study.methods else study.methods[0]
    columns = [(r.preset, method, f"{short_label(method)}: {r.label}") for r in study.all_readings]
    if study.reads_the_operator:
        nocov = "dist-gprl-nocov"
        columns.append((study.reference.preset, nocov, f"{METHODS[nocov].label} (no operator)"))
    return columns
