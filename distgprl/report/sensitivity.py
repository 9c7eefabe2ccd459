"""The sensitivity figure of an operator study (docs/findings/operator.md, "The operator study
and the noise curve"): per task and score (`PANELS`; evaluation TCs, Table I's policy) the
studied method's mean over seeds (95 % interval) per reading at x = its mean operator gain on a
raw action (1 passes it through); `REFERENCES` dashed; a control hollow, shifted right of the
gain it shares. Reads ``<root>/<study>/reach.json`` and the runs' result files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from distgprl.data import task_order
from distgprl.methods import METHODS
from distgprl.report.aggregate import BOOTSTRAP_SEED, Estimate, Scores, method_estimate, short_label
from distgprl.report.figure_files import subplots, write_or_remove_figure
from distgprl.schema import read_json
from distgprl.studies import Reading, Study

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PANELS = (
    ("success_rate", "success rate"),
    ("collision_rate", "collision rate"),
    ("mean_kinematic_retention", "kinematic retention"),  # velocity cosine to the demonstration
)
REFERENCES = ("dist-gprl-nocov", "demo")
"""Methods drawn as horizontal reference bands: no operator, no adaptation."""


def reading_gains(reach: dict[str, Any], method: str) -> dict[tuple[str, str], float]:
    """{(preset, task): ``method``'s mean operator gain over the axes the task's TCs vary} of a
    study's reach document."""
    gains: dict[tuple[str, str], list[float]] = {}
    for row in reach["rows"]:
        if row["method"] == method and row["tc_range_m"] > 0:
            gains.setdefault((row["preset"], row["task"]), []).append(row["mean_gain"])
    return {key: float(np.mean(values)) for key, values in gains.items()}


def write_sensitivity(
    root: str | Path, study: Study, scores_of: dict[str, Scores], out_dir: str | Path
) -> list[Path]:
    """Draw `plot_sensitivity` into ``<out_dir>/sensitivity_<study>_<reference preset>.{png,pdf}``
    (``scores_of``: {reading preset: its scores}); with nothing to draw, remove an earlier one."""
    stem = Path(out_dir) / f"sensitivity_{study.name}_{study.reference.preset}"
    fig = plot_sensitivity(root, study, scores_of)
    return write_or_remove_figure(None if fig is None else (fig, 1), stem)


def plot_sensitivity(root: str | Path, study: Study, scores_of: dict[str, Scores]) -> Figure | None:
    """The study's sensitivity figure, or None without a reach file or a run to draw."""
    reach_path = Path(root) / study.name / "reach.json"
    if not reach_path.exists():
        return None
    method = study.methods[0]
    gains = reading_gains(read_json(reach_path), method)

    def mean(preset: str, task: str, of: str, key: str) -> Estimate:
        return method_estimate(scores_of.get(preset, {}), [task], of, key, "mean", BOOTSTRAP_SEED)

    tasks = sorted(
        sorted({task for scores in scores_of.values() for task, _ in scores}), key=task_order
    )
    panels = {  # {(task, score): [(reading, gain, estimate)] in reading order}
        (task, key): [
            (reading, gain, estimate)
            for reading in study.all_readings
            if (gain := gains.get((reading.preset, task))) is not None
            and (estimate := mean(reading.preset, task, method, key)).seeds
        ]
        for task in tasks
        for key, _ in PANELS
    }
    tasks = [task for task in tasks if any(panels[task, key] for key, _ in PANELS)]
    if not tasks:
        return None
    fig, axes = subplots(
        len(tasks), len(PANELS), figsize=(4.2 * len(PANELS), 3.2 * len(tasks)), squeeze=False
    )
    markers = {r.preset: m for r, m in zip(study.all_readings, "o^sDvP", strict=False)}
    for row, task in enumerate(tasks):
        for col, (key, label) in enumerate(PANELS):
            ax = axes[row][col]
            for index, ref in enumerate(REFERENCES):  # dashed, the interval a band
                if (estimate := mean(study.reference.preset, task, ref, key)).seeds:
                    color = f"C{index + 1}"
                    ax.axhline(
                        estimate.point, color=color, lw=1.2, ls="--", label=METHODS[ref].label
                    )
                    if estimate.has_interval:
                        ax.axhspan(estimate.low, estimate.high, color=color, alpha=0.15, lw=0)
            for reading, gain, estimate in panels[task, key]:
                name = f"{short_label(method)}: {reading.label}"
                _draw_reading(ax, markers.get(reading.preset, "o"), name, reading, gain, estimate)
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
    fig.legend(
        list(legend.values()), list(legend), loc="lower center", ncol=3, fontsize=8, frameon=False
    )
    control = any(r.control for r in study.readings)
    fig.suptitle(
        f"Operator study: {short_label(method)} per reading of K_tt"
        f"{' and control (hollow, drawn beside its gain)' if control else ''} "
        f"(means over seeds, 95 % bootstrap intervals; {study.reference.preset} preset's "
        "references dashed)",
        fontsize=10,
    )
    fig.tight_layout(rect=(0.0, 0.04 + 0.035 * ((len(legend) + 2) // 3), 1.0, 0.95))
    return fig


def _draw_reading(
    ax: Any, marker: str, name: str, reading: Reading, gain: float, estimate: Estimate
) -> None:
    """A reading's estimate at its gain with its interval; a control hollow, shifted right."""
    from matplotlib.transforms import offset_copy

    yerr = None
    if estimate.has_interval:
        yerr = [[estimate.point - estimate.low], [estimate.high - estimate.point]]
    seeds = min(estimate.seeds)
    transform = ax.transData
    if reading.control:
        transform = offset_copy(transform, fig=ax.figure, x=9.0, units="points")
    ax.errorbar(
        [gain],
        [estimate.point],
        yerr=yerr,
        fmt=marker,
        color="0.5" if reading.control else "black",
        markerfacecolor="white" if reading.control else None,
        transform=transform,
        capsize=3,
        label=f"{name} ({seeds} seed{'s' if seeds != 1 else ''})",
    )
