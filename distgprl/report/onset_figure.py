"""A study's onset table drawn (``onsets_<study>_<preset>.{png,pdf}``): a panel per task, a
line per table row, a marker per finished run at its onset step or in a "never" band, filled
for the study's seeds; a dashed line at a rule's ``by_step`` on its task."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from distgprl.config import load_config
from distgprl.report.figure_files import subplots
from distgprl.report.onsets import onset_rows, run_label, seeds_text, step_text, study_rule
from distgprl.report.seed_curves import SEED_COLORS
from distgprl.studies import Study

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

NEVER_X = 1.125  # where a run that never reaches the threshold sits, in run lengths
NEVER_BAND = (1.05, 1.2)  # the shaded "never" band, in run lengths (its right end the axis's)
SEED_SHAPES = ("o", "s", "D", "^")  # one per round of `SEED_COLORS`: distinct up to 36 seeds


def seed_offsets(seeds: list[int]) -> dict[int, float]:
    """{seed: vertical offset in rows}: spread evenly over 0.7 rows, the smallest seed highest
    (the rows' axis points down); a single seed on the row's line."""
    ordered, spread = sorted(set(seeds)), 0.7
    if len(ordered) < 2:
        return dict.fromkeys(ordered, 0.0)
    step = spread / (len(ordered) - 1)
    return {seed: -spread / 2 + step * index for index, seed in enumerate(ordered)}


def seed_marker(seed: int, study: Study) -> dict[str, Any]:
    """`Line2D` keywords of ``seed``'s marker: its colour and shape, hollow beyond the study's."""
    color = SEED_COLORS[seed % len(SEED_COLORS)]
    shape = SEED_SHAPES[(seed // len(SEED_COLORS)) % len(SEED_SHAPES)]
    fill = color if seed in study.seeds else "none"
    return {"marker": shape, "ms": 6, "mew": 1.3, "ls": "none", "color": color, "mfc": fill}


def _x_axis(ax: Axes, length: int, threshold: float) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.axvspan(NEVER_BAND[0] * length, NEVER_BAND[1] * length, color="0.9", lw=0, zorder=0)
    locator = MaxNLocator(nbins=4, steps=[1, 1.5, 2, 2.5, 3, 5, 10])
    ticks = [float(t) for t in locator.tick_values(0, length) if 0 <= t <= length]
    ax.set_xticks([*ticks, NEVER_X * length], [*map(step_text, ticks), "never"])
    ax.set_xlim(-0.03 * length, NEVER_BAND[1] * length)
    ax.set_xlabel(f"training step at which the curve first reaches {threshold:g}", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(axis="x", alpha=0.3, lw=0.5)


def _draw_task(
    ax: Axes, rows: list[dict[str, Any]], panels: list[tuple[str, str]], study: Study, length: int
) -> None:
    """One task's ``rows`` on ``ax``, each run in its row of ``panels`` ((preset, method)); its
    marker's ``gid``: "onset <preset> <method> <task> seed<seed>"."""
    offsets = seed_offsets([int(r["seed"]) for r in rows])
    for index, panel in enumerate(panels):
        runs = [r for r in rows if (r["preset"], r["method"]) == panel]
        if not runs:
            ax.text(length / 2, index, "no finished run", ha="center", va="center", fontsize=7,
                    color="0.5")  # fmt: skip
        for run in runs:
            seed, onset = int(run["seed"]), run["onset_step"]
            x = NEVER_X * length if onset == "" else int(onset)
            gid = f"onset {' '.join(panel)} {run['task']} seed{seed}"
            ax.plot([x], [index + offsets[seed]], zorder=3, gid=gid, **seed_marker(seed, study))
    for boundary in range(len(panels) - 1):
        ax.axhline(boundary + 0.5, color="0.8", lw=0.6, zorder=1)


def plot_onset_figure(
    root: str | Path, study: Study, tasks: list[str], preset: str
) -> tuple[Figure, int]:
    """``study``'s onset figure beside ``preset`` (a panel per task, x to the presets' longest
    ``run.total_steps`` or a later onset; a row per panel with a run) and the markers drawn."""
    from matplotlib.lines import Line2D

    rows = onset_rows(root, study, tasks)
    if not rows:
        return subplots(1, 1)[0], 0
    (rule, threshold), rule_tasks = study_rule(study), {own.task for _, own in study.rules}
    panels = list(dict.fromkeys((r["preset"], r["method"], r["reading"]) for r in rows))
    seeds = sorted({int(r["seed"]) for r in rows})
    presets = sorted({p for p, _, _ in panels})
    row_height = max(0.42, 0.07 * len(seeds))  # inches: room for every seed's offset
    fig, axes = subplots(
        1, len(tasks), figsize=(3.4 + 4.4 * len(tasks), 2.1 + row_height * len(panels)),
        squeeze=False, sharey=True,
    )  # fmt: skip
    for ax, task in zip(axes[0], tasks, strict=True):
        mine = [r for r in rows if r["task"] == task]
        onsets = [int(r["onset_step"]) for r in mine if r["onset_step"] != ""]
        length = max([*(load_config(p, task).run.total_steps for p in presets), *onsets])
        _draw_task(ax, mine, [(p, m) for p, m, _ in panels], study, length)
        if rule is not None and task in rule_tasks:
            ax.axvline(rule.by_step, color="0.2", ls="--", lw=1.1, zorder=2, gid="rule")
            ax.text(rule.by_step, 1.005, f" early: ≤ {step_text(rule.by_step)}", fontsize=7,
                    ha="left", va="bottom", transform=ax.get_xaxis_transform())  # fmt: skip
        _x_axis(ax, length, threshold)
        ax.set_title(f"{task.upper()} (runs of {step_text(length)} steps)", fontsize=9, pad=12)
    axes[0, 0].set_yticks(range(len(panels)), [run_label(study, m, r) for _, m, r in panels])
    axes[0, 0].set_ylim(len(panels) - 0.5, -0.5)  # the table's first row at the top
    axes[0, 0].tick_params(axis="y", labelsize=8, length=0)
    fig.suptitle(
        f"When each run first reaches {threshold:g} success ({study.name} study, {preset} preset)"
    )
    handles = [Line2D([], [], label=f"seed {seed}", **seed_marker(seed, study)) for seed in seeds]
    columns = min(len(handles), 8)
    fig.legend(
        handles=handles, loc="lower center", ncol=columns, fontsize=7, frameon=False,
        title_fontsize=7,
        title="one marker per run, its colour its seed's; filled: the study's seeds "
        f"({seeds_text(study.seeds)}); hollow: a further seed, read only by a rule",
    )  # fmt: skip
    height = fig.get_figheight()
    bottom = (0.25 + 0.2 * -(-len(handles) // columns)) / height
    fig.tight_layout(rect=(0.0, bottom, 1.0, 1.0 - 0.05 / height))
    return fig, len(rows)
