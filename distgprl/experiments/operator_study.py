"""What each reading of a study does to a raw action: the x axis of the sensitivity figure.

For every reading of a study (`distgprl.studies`) and task, the study's method is built in the
environment its runs train in (`distgprl.experiments.factories.make_env`, so the layout is
exactly the one the runs use) and its raw-action reach is measured per position axis:

- ``mean_gain``: the operator's mean row gain sum_j |S_W,ij| over the adapted via-points and
  the steps — how much of a raw action of 1 on every via-point of a window reaches a via-point
  (1 for the identity; below 1 where the operator shrinks, Eq. transformed_action);
- ``one_step_mean_m``: ``mean_gain`` times the axis's action scale, m: the mean one-step
  reach of a via-point;
- ``one_step_min_m`` / ``one_step_max_m`` / ``episode_min_m`` / ``episode_max_m``: as in the
  mechanism table (`distgprl.experiments.mechanisms.layout_reach`);
- ``tc_range_m``: the task's TC range on the axis.

`write_study_reach` writes them to ``<root>/<study>/reach.json`` (a versioned result file, one
per study, rewritten by each study sweep); `distgprl.report.sensitivity` reads it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from distgprl.adaptation.layout import ActionLayout
from distgprl.data import TASK_NAMES
from distgprl.experiments.mechanisms import AXES, layout_reach, row_gains_and_moving
from distgprl.schema import write_json
from distgprl.studies import Study

__all__ = ["REACH_FILE", "layout_mean_gain", "reading_reach_rows", "write_study_reach"]

REACH_FILE = "reach.json"
"""The study's reach file, under ``<root>/<study name>/``."""


def layout_mean_gain(layout: ActionLayout) -> np.ndarray:
    """The mean row gain sum_j |S_ij| per position axis over the adapted (non-frozen)
    via-points of every step, shape (3,), dimensionless."""
    gains, moving = row_gains_and_moving(layout)
    mean: np.ndarray = gains.transpose(1, 0, 2)[:, moving].mean(axis=1)
    return mean


def reading_reach_rows(study: Study, tasks: tuple[str, ...] = TASK_NAMES) -> list[dict[str, Any]]:
    """One row per reading (the reference first), study method, task and position axis:
    ``preset``, ``reading``, ``task``, ``method``, ``axis`` and the module docstring's
    measures. Builds each environment once (one simulator client at a time)."""
    from distgprl.experiments.factories import make_env
    from distgprl.identity import resolve_run

    rows: list[dict[str, Any]] = []
    for reading in study.all_readings:
        for method in study.methods:
            for task in tasks:
                env = make_env(resolve_run(task, method, 0, reading.preset))
                try:
                    layout = env.layout
                    tc_range = np.asarray(env.spec_task.tc_range, dtype=float)
                finally:
                    env.close()
                reach = layout_reach(layout)
                gain = layout_mean_gain(layout)
                for axis, name in enumerate(AXES):
                    rows.append(
                        {
                            "preset": reading.preset,
                            "reading": reading.label,
                            "task": task,
                            "method": method,
                            "axis": name,
                            "mean_gain": float(gain[axis]),
                            "one_step_mean_m": float(gain[axis] * layout.scale[axis]),
                            **{f"{key}_m": float(value[axis]) for key, value in reach.items()},
                            "tc_range_m": float(tc_range[axis]),
                        }
                    )
    return rows


def write_study_reach(root: str | Path, study: Study) -> Path:
    """Measure `reading_reach_rows` and write them to ``<root>/<study.name>/reach.json``."""
    rows = reading_reach_rows(study)
    return write_json(
        Path(root) / study.name / REACH_FILE,
        {"study": study.name, "question": study.question, "rows": rows},
        kind="study_reach",
    )
