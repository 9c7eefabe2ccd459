"""The sensitivity figure of a study: the studied method's scores per reading.

A row of panels per task, a panel per score (`PANELS`; kinematic retention: the mean velocity
cosine to the demonstration) on the 100 evaluation TCs, Table I's policy
(`distgprl.report.runs.TABLE_POLICY`). Each reading is a point at x = its mean operator gain on
a raw action (``mean_gain`` of `distgprl.experiments.operator_study` over the position axes the
task's TCs vary: 1 passes a raw action through, below 1 shrinks it), y = the mean over seeds
with its 95 % stratified-bootstrap interval (`distgprl.report.aggregate`, one stratum: the
task). `REFERENCES` are dashed lines, their intervals bands, from the reference preset's runs.
A control (`distgprl.studies.Reading.control`) is hollow and grey, drawn `CONTROL_SHIFT_POINTS`
right of its x: the uncoupled-signal control has the signal reading's gain, so the two points
at one gain differ by the coupling alone. Reads ``<root>/<study>/reach.json`` (written by the
study's sweep) and the runs' result files only.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from distgprl.data import task_order
from distgprl.methods import METHODS
from distgprl.report.aggregate import (
    BOOTSTRAP_SEED,
    Estimate,
    Scores,
    method_estimate,
    short_label,
)
from distgprl.report.figure_files import remove_figure, subplots, write_or_remove_figure
from distgprl.schema import read_json
from distgprl.studies import Study

if TYPE_CHECKING:
    from matplotlib.figure import Figure


PANELS = (
    ("success_rate", "success rate"),
    ("collision_rate", "collision rate"),
    ("mean_kinematic_retention", "kinematic retention"),
)
"""(score, axis label) per panel."""

CONTROL_SHIFT_POINTS = 9.0
"""How far (typographic points) a control's point is drawn right of its x, so that it does not
hide a reading's point at the same gain."""

REFERENCES = ("dist-gprl-nocov", "demo")
"""Methods drawn as horizontal reference bands: no operator, no adaptation."""


def reading_gains(reach: dict[str, Any], method: str) -> dict[tuple[str, str], float]:
    """{(preset, task): mean operator gain of ``method`` over the axes the task's TCs vary}
    from a study's reach document."""
    gains: dict[tuple[str, str], list[float]] = {}
    for row in reach["rows"]:
        if row["method"] == method and row["tc_range_m"] > 0:
            gains.setdefault((row["preset"], row["task"]), []).append(row["mean_gain"])
    return {key: float(np.mean(values)) for key, values in gains.items()}


def sensitivity_points(
    study: Study,
    method: str,
    scores_of: dict[str, Scores],
    gains: dict[tuple[str, str], float],
    tasks: list[str],
    seed: int = BOOTSTRAP_SEED,
) -> list[dict[str, Any]]:
    """One entry per reading, task and score with runs: ``reading`` (the `Reading`),
    ``task``, ``score``, ``gain`` and the `Estimate` (mean over seeds, 95 % interval)."""
    return [
        {"reading": reading, "task": task, "score": key, "gain": gain, "estimate": estimate}
        for reading in study.all_readings
        for task in tasks
        if (gain := gains.get((reading.preset, task))) is not None
        for key, _ in PANELS
        if (estimate := _mean(scores_of.get(reading.preset, {}), task, method, key, seed))
        is not None
    ]


def _mean(scores: Scores, task: str, method: str, key: str, seed: int) -> Estimate | None:
    """``method``'s mean ``key`` over its seeds on ``task`` with its interval, or None without
    runs."""
    if not scores.get((task, method)):
        return None
    estimate = method_estimate(scores, [task], method, key, "mean", seed)
    return estimate if estimate.seeds else None


def write_sensitivity(
    root: str | Path,
    study: Study,
    scores_of: dict[str, Scores],
    out_dir: str | Path,
    seed: int = BOOTSTRAP_SEED,
) -> list[Path]:
    """Draw the study's sensitivity figure (module docstring, `plot_sensitivity`) into
    ``<out_dir>/sensitivity_<study>_<reference preset>.{png,pdf}``; with nothing to draw,
    remove an earlier one. ``scores_of`` maps each reading's preset to its scores
    (`distgprl.report.table1.collect_scores`)."""
    stem = Path(out_dir) / f"sensitivity_{study.name}_{study.reference.preset}"
    fig = plot_sensitivity(root, study, scores_of, seed)
    if fig is None:
        remove_figure(stem)
        return []
    return write_or_remove_figure((fig, 1), stem)


def plot_sensitivity(
    root: str | Path,
    study: Study,
    scores_of: dict[str, Scores],
    seed: int = BOOTSTRAP_SEED,
) -> Figure | None:
    """The study's sensitivity figure (module docstring), or None with nothing to draw (no
    reach file, or no run of the studied method)."""

    reach_path = Path(root) / study.name / "reach.json"
    if not reach_path.exists():
        return None
    method = study.methods[0]
    tasks = sorted({task for scores in scores_of.values() for task, _ in scores})
    tasks.sort(key=task_order)
    gains = reading_gains(read_json(reach_path), method)
    points = sensitivity_points(study, method, scores_of, gains, tasks, seed)
    if not points:
        return None
    tasks = [t for t in tasks if any(p["task"] == t for p in points)]
    reference = scores_of.get(study.reference.preset, {})
    fig, axes = subplots(
        len(tasks), len(PANELS), figsize=(4.2 * len(PANELS), 3.2 * len(tasks)), squeeze=False
    )
    markers = {r.preset: m for r, m in zip(study.all_readings, "o^sDvP", strict=False)}
    for row, task in enumerate(tasks):
        for col, (key, label) in enumerate(PANELS):
            ax = axes[row][col]
            _draw_references(ax, reference, task, key, seed)
            panel = [p for p in points if (p["task"], p["score"]) == (task, key)]
            _draw_readings(ax, fig, method, panel, markers)
            if key != "mean_kinematic_retention":
                ax.set_ylim(-0.02, 1.02)
            ax.set_xlabel("mean operator gain on a raw action")
            ax.set_ylabel(label)
            ax.set_title(f"{task.upper()}: {label}")
            ax.grid(alpha=0.3)
    legend: dict[str, Any] = {}  # each label once, its first handle
    for ax in axes.flat:
        for handle, text in zip(*ax.get_legend_handles_labels(), strict=True):
            legend.setdefault(text, handle)
    labels = list(legend)
    fig.legend(list(legend.values()), labels, loc="lower center", ncol=3, fontsize=8, frameon=False)
    control = any(r.control for r in study.readings)
    fig.suptitle(
        f"Operator study: {short_label(method)} per reading of K_tt"
        f"{' and control (hollow, drawn beside its gain)' if control else ''} "
        f"(means over seeds, 95 % bootstrap intervals; {study.reference.preset} preset's "
        "references dashed)",
        fontsize=10,
    )
    legend_rows = (len(labels) + 2) // 3
    fig.tight_layout(rect=(0.0, 0.04 + 0.035 * legend_rows, 1.0, 0.95))
    return fig


def _draw_references(ax: Any, reference: Scores, task: str, key: str, seed: int) -> None:
    """One panel's reference methods: a dashed line at each one's estimate, its interval
    shaded."""
    for index, ref in enumerate(REFERENCES):
        estimate = _mean(reference, task, ref, key, seed)
        if estimate is None:
            continue
        color = f"C{index + 1}"
        ax.axhline(estimate.point, color=color, lw=1.2, ls="--", label=METHODS[ref].label)
        if estimate.has_interval:
            ax.axhspan(estimate.low, estimate.high, color=color, alpha=0.15, lw=0)


def _draw_readings(
    ax: Any, fig: Figure, method: str, points: list[dict[str, Any]], markers: dict[str, str]
) -> None:
    """One panel's readings (``points`` of `sensitivity_points`, in the study's reading
    order): each reading's estimate at its operator gain with its interval, a control drawn
    hollow beside the reading whose gain it shares."""
    from matplotlib.transforms import offset_copy

    for point in points:
        reading, estimate = point["reading"], point["estimate"]
        yerr = None
        if estimate.has_interval:
            yerr = [[estimate.point - estimate.low], [estimate.high - estimate.point]]
        seeds = min(estimate.seeds)
        plural = "s" if seeds != 1 else ""
        transform = ax.transData
        if reading.control:  # beside the reading with its gain, same x value
            transform = offset_copy(transform, fig=fig, x=CONTROL_SHIFT_POINTS, units="points")
        ax.errorbar(
            [point["gain"]],
            [estimate.point],
            yerr=yerr,
            fmt=markers.get(reading.preset, "o"),
            color="0.5" if reading.control else "black",
            markerfacecolor="white" if reading.control else None,
            transform=transform,
            capsize=3,
            label=f"{short_label(method)}: {reading.label} ({seeds} seed{plural})",
        )
