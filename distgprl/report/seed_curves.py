"""Learning curves seed by seed (``progress.csv``) and the panels in which a study reads them:
one source for the curve figures, the onset tables and the onset figure."""

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
"""The learning-curve metrics read and drawn: (``progress.csv`` column, panel title, y-axis
label, whether it is a rate, its axis [0, 1]); evaluations on the fixed curve TCs, the
deterministic policy."""

SEED_COLORS = ("C0", "C1", "C2", "C3", "C4", "C5", "C6", "C8", "C9")
"""A seed's colour in the seed-by-seed figures (seed k: the k-th, cycling)."""

SeedCurves = dict[int, tuple[np.ndarray, dict[str, np.ndarray]]]
"""{seed: (steps (k,), {`PANELS` metric: (k,)})}, each seed on its own steps."""


def run_curves(frame: pd.DataFrame, task: str, method: str) -> SeedCurves:
    """`SeedCurves` of ``task`` and ``method`` from a `distgprl.report.frame.curve_frame`
    (finished runs of the current configuration), seeds ascending."""
    mine = frame[(frame["task"] == task) & (frame["method"] == method)]
    return {
        int(str(seed)): (
            points["step"].to_numpy(),
            {k: points[k].to_numpy(dtype=float) for k, *_ in PANELS},
        )
        for seed, points in mine.groupby("seed")
    }


def reading_columns(study: Study) -> list[tuple[str, str, str]]:
    """The panels of `distgprl.report.curves.plot_reading_curves`, left to right: (preset,
    method, title) — the studied method (Dist-GPRL where the study trains it) under each
    reading, the reference's first, and for an operator study Dist-GPRL-NoCov from the
    reference preset (no operator, so no reading changes it)."""
    method = PROPOSED if PROPOSED in study.methods else study.methods[0]
    columns = [(r.preset, method, f"{short_label(method)}: {r.label}") for r in study.all_readings]
    if study.reads_the_operator:
        nocov = "dist-gprl-nocov"
        columns.append((study.reference.preset, nocov, f"{METHODS[nocov].label} (no operator)"))
    return columns
