"""Learning-curve figures (paper Figs. HAP and covariance effect): per panel a `PANELS` metric's
mean over seeds on their common steps and its 95 % bootstrap band (own `estimate_rng` per
curve), `HIGHLIGHT` bold on top; per study beside a preset its seed-by-seed, onset and
(operator study) sensitivity figures."""

from __future__ import annotations

from functools import reduce
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from distgprl.data import TASK_NAMES
from distgprl.errors import UserInputError
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.aggregate import BOOTSTRAP_SEED, bootstrap_interval, estimate_rng
from distgprl.report.figure_files import subplots, write_or_remove_figure
from distgprl.report.frame import curve_frame, load_frames
from distgprl.report.noise_curve import write_noise_curve
from distgprl.report.onset_figure import plot_onset_figure
from distgprl.report.seed_curves import PANELS, SEED_COLORS, SeedCurves, reading_columns, run_curves
from distgprl.report.sensitivity import write_sensitivity
from distgprl.report.table1 import collect_scores
from distgprl.report.table2 import hardware_rows, select_trial_files
from distgprl.studies import Study, studies_of

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

#: The proposed method, drawn bold and on top of the others.
HIGHLIGHT = "dist-gprl"
#: The method-comparison figures: {file name: (title, methods)}.
FIGURES = {
    "hap_effect": ("Effect of the HAP subspace prior", ("dist-gprl", "gprl-d")),
    "covariance_effect": (
        "Effect of the covariance-based action transform",
        ("dist-gprl", "dist-gprl-nocov"),
    ),
    "all_methods": ("All methods", tuple(m for m in TABLE_ORDER if METHODS[m].trainable)),
}


def common_curves(seeds: SeedCurves) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """``seeds``' curves on the steps every seed has: (steps (k,), {metric: (seeds, k)}), or
    None without a seed or a common step."""
    series = list(seeds.values())
    if not series:
        return None
    common = reduce(np.intersect1d, [steps for steps, _ in series], series[0][0])
    if not len(common):
        return None
    return common, {
        key: np.array([values[key][np.searchsorted(steps, common)] for steps, values in series])
        for key, *_ in PANELS
    }


def mean_and_band(
    values: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """(mean (k,), (low, high) (k,) each) over the seeds of a (seeds, k) array: the mean curve
    and its `bootstrap_interval` band (whole curves resampled); no band for a single seed."""
    mean = values.mean(axis=0)
    if values.shape[0] < 2:
        return mean, None
    return mean, bootstrap_interval([values], np.mean, rng)


def _seed_note(seeds: dict[str, int]) -> str:
    """``3 seeds`` ({task: seeds}), or per task (``DCP 3, DBM 2 seeds``) when the tasks differ."""
    counts = set(seeds.values())
    if len(counts) == 1:
        (count,) = counts
        return f"{count} seed{'s' if count != 1 else ''}"
    return ", ".join(f"{task.upper()} {n}" for task, n in seeds.items()) + " seeds"


def _style(
    ax: Axes, title: str, ylabel: str | None, rate: bool, fontsize: int | None = None
) -> None:
    """A panel's title, labels, grid, [0, 1] limits for a ``rate``, ``fontsize`` (ticks 1 less)."""
    font: dict[str, Any] = {} if fontsize is None else {"fontsize": fontsize}
    ax.set_title(title, **font)
    ax.set_xlabel("training steps", **font)
    if ylabel is not None:
        ax.set_ylabel(ylabel, **font)
    if rate:
        ax.set_ylim(-0.03, 1.03)
    if fontsize is not None:
        ax.tick_params(labelsize=fontsize - 1)
    ax.grid(alpha=0.3, lw=0.5)


def plot_figure(
    root: str | Path, preset: str, tasks: list[str], methods: tuple[str, ...], title: str
) -> tuple[Figure, int]:
    """The learning curves of ``methods``: a row per task, a column per `PANELS` entry, one
    legend below. Returns (figure, (task, method) curves drawn)."""
    fig, axes = subplots(len(tasks), len(PANELS), figsize=(12, 3.2 * len(tasks)), squeeze=False)
    frame = curve_frame(root, preset)
    handles: dict[str, Line2D] = {}
    seeds_of: dict[str, dict[str, int]] = {}
    for row, task in enumerate(tasks):
        for method in methods:
            data = common_curves(run_curves(frame, task, method))
            if data is None:
                continue
            steps, values = data
            bold = method == HIGHLIGHT
            color = "black" if bold else f"C{TABLE_ORDER.index(method) % 10}"
            seeds_of.setdefault(method, {})[task] = len(values["success_rate"])
            for ax, (key, *_) in zip(axes[row], PANELS, strict=True):
                rng = estimate_rng(BOOTSTRAP_SEED, "curve", task, method, key)
                mean, band = mean_and_band(values[key], rng)
                (line,) = ax.plot(
                    steps, mean, color=color, lw=2.4 if bold else 1.3, zorder=4 if bold else 2
                )
                handles.setdefault(method, line)
                if band is not None:
                    ax.fill_between(
                        steps, *band, color=color, alpha=0.18 if bold else 0.12, lw=0,
                        zorder=3 if bold else 1,
                    )  # fmt: skip
        for ax, (_, label, ylabel, rate) in zip(axes[row], PANELS, strict=True):
            _style(ax, f"{task.upper()}: {label}", ylabel, rate)
    fig.suptitle(title)
    order = [m for m in methods if m in handles]
    if not order:  # nothing drawn: the figure is not written
        return fig, 0
    columns = min(len(order), 4)
    labels = [f"{METHODS[m].label} ({_seed_note(seeds_of[m])})" for m in order]
    legend = fig.legend(
        [handles[m] for m in order], labels, loc="lower center", ncol=columns,
        fontsize=8, frameon=False, bbox_to_anchor=(0.5, 0.0),
    )  # fmt: skip
    for text, method in zip(legend.get_texts(), order, strict=True):
        if method == HIGHLIGHT:
            text.set_fontweight("bold")
    bottom = (0.08 + 0.18 * -(-len(order) // columns)) / fig.get_figheight()
    fig.tight_layout(rect=(0.0, bottom, 1.0, 1.0 - 0.1 / fig.get_figheight()))
    return fig, sum(len(counts) for counts in seeds_of.values())


def plot_reading_curves(root: str | Path, study: Study, tasks: list[str]) -> tuple[Figure, int]:
    """A study's success curves (a row per task, a panel per `reading_columns` entry: each
    finished seed in its colour, their mean in black) and the panels drawn."""
    columns = reading_columns(study)
    fig, axes = subplots(
        len(tasks), len(columns), figsize=(3.4 * len(columns), 2.9 * len(tasks)),
        squeeze=False, sharey=True,
    )  # fmt: skip
    drawn = 0
    seed_lines: dict[int, Line2D] = {}
    mean_lines: list[Line2D] = []
    frames = {p: curve_frame(root, p, study.seeds) for p in dict.fromkeys(p for p, _, _ in columns)}
    for row, task in enumerate(tasks):
        for col, (preset, method, title) in enumerate(columns):
            ax = axes[row, col]
            seeds = run_curves(frames[preset], task, method)
            for seed, (steps, values) in seeds.items():
                (line,) = ax.plot(
                    steps, values["success_rate"], lw=0.9, alpha=0.85,
                    color=SEED_COLORS[seed % len(SEED_COLORS)],
                )  # fmt: skip
                seed_lines.setdefault(seed, line)
            common = common_curves(seeds)
            if common is not None and len(seeds) > 1:
                steps, values = common
                mean_lines += ax.plot(
                    steps, values["success_rate"].mean(axis=0), color="black", lw=2.2
                )
            drawn += bool(seeds)
            if not seeds:
                ax.text(0.5, 0.5, "no finished runs", ha="center", va="center", fontsize=8,
                        transform=ax.transAxes, color="0.4")  # fmt: skip
            count = _seed_note({task: len(seeds)}) if seeds else "no runs"
            ylabel = PANELS[0][2] if col == 0 else None  # the success rate's
            _style(ax, f"{task.upper()}: {title}\n({preset}, {count})", ylabel, True, fontsize=8)
    fig.suptitle(f"The {study.name} study: success rate during training, seed by seed")
    if not drawn:  # the figure is not written
        return fig, 0
    key = {f"seed {seed}": line for seed, line in sorted(seed_lines.items())}
    if mean_lines:
        key["mean over seeds"] = mean_lines[0]
    fig.legend(
        list(key.values()), list(key), loc="lower center", ncol=len(key), fontsize=8, frameon=False
    )
    height = fig.get_figheight()
    fig.tight_layout(rect=(0.0, 0.3 / height, 1.0, 1.0 - 0.1 / height))
    return fig, drawn


def write_curves(root: str | Path, preset: str, out_dir: str | Path) -> list[Path]:
    """Write (or, with nothing to draw, remove) the `FIGURES`, each study's figures and Table
    II's noise curve; the paths written. `UserInputError` if ``<root>/<preset>`` holds no task
    folder (a wrong preset or root)."""
    folder, out = Path(root) / preset, Path(out_dir)
    tasks = [t for t in TASK_NAMES if (folder / t).is_dir()]
    if not tasks:
        raise UserInputError(
            f"{folder}: no results of any task ({', '.join(TASK_NAMES)}); run a sweep first"
        )
    written = []
    for name, (title, methods) in FIGURES.items():
        figure = plot_figure(root, preset, tasks, methods, f"{title} ({preset} preset)")
        written += write_or_remove_figure(figure, out / f"{name}_{preset}")
    for study in studies_of(preset):
        stem = out / f"curves_{study.name}_{preset}"
        written += write_or_remove_figure(plot_reading_curves(root, study, tasks), stem)
        if study.reads_the_operator:
            scores_of = {
                r.preset: collect_scores(load_frames(root, r.preset, seeds=study.seeds))
                for r in study.all_readings
            }
            written += write_sensitivity(root, study, scores_of, out_dir)
        onsets = plot_onset_figure(root, study, tasks, preset)
        written += write_or_remove_figure(onsets, out / f"onsets_{study.name}_{preset}")
    written += write_noise_curve(hardware_rows(select_trial_files(root, preset)), out_dir, preset)
    return written
