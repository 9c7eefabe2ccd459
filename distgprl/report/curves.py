"""Learning curves from ``progress.csv`` files only (paper Figs. HAP and covariance effect).

Each panel shows the mean over seeds and a ± std band of success rate, collision rate and
episode return against training steps. The band is the sample standard deviation over seeds
(ddof = 1, as in Table I); a single seed has no band. Seeds are aligned on their common
steps.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from distgprl.io import atomic_write_bytes
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.runs import select_runs
from distgprl.schema import read_csv

PANELS = (
    ("success_rate", "success rate"),
    ("collision_rate", "collision rate"),
    ("mean_return", "episode return"),
)
#: Figure titles (the paper's captions, shortened).
TITLES = {
    "hap_effect": "Effect of the HAP subspace prior",
    "covariance_effect": "Effect of the covariance-based action transform",
    "all_methods": "All methods",
}
FIGURES = {
    "hap_effect": ("dist-gprl", "gprl-d"),
    "covariance_effect": ("dist-gprl", "dist-gprl-nocov"),
    "all_methods": tuple(m for m in TABLE_ORDER if METHODS[m].trainable),
}


def load_curves(root: str | Path, preset: str, task: str, method: str):
    """(steps (k,), {metric: (seeds, k)}) over the finished seeds of a run of the current
    configuration (`select_runs`), on their common steps. Runs still in progress are left
    out."""
    current = select_runs(root, preset, marker="done.json").current
    files = sorted(
        path
        for path in (Path(root) / preset / task / method).glob("seed*/progress.csv")
        if path.parent in current
    )
    series = []
    for path in files:
        _, rows = read_csv(path)
        if rows:
            series.append(rows)
    if not series:
        return None
    common = sorted(set.intersection(*[{int(r["step"]) for r in rows} for rows in series]))
    if not common:
        return None
    out = {}
    for key, _ in PANELS:
        out[key] = np.array(
            [
                [float(next(r[key] for r in rows if int(r["step"]) == s)) for s in common]
                for rows in series
            ]
        )
    return np.array(common), out


def mean_and_band(values: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(mean, sample std with ddof = 1) over seeds (axis 0) of a (seeds, k) array; the std
    is None (no band) for a single seed."""
    mean = values.mean(axis=0)
    if values.shape[0] < 2:
        return mean, None
    return mean, values.std(axis=0, ddof=1)


def plot_figure(root, preset: str, tasks: list[str], methods: tuple[str, ...], title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(tasks), len(PANELS), figsize=(12, 3.2 * len(tasks)), squeeze=False)
    drawn = 0
    for row, task in enumerate(tasks):
        for index, method in enumerate(methods):
            data = load_curves(root, preset, task, method)
            if data is None:
                continue
            steps, values = data
            drawn += 1
            for col, (key, label) in enumerate(PANELS):
                ax = axes[row, col]
                mean, std = mean_and_band(values[key])
                color = f"C{index}"
                seeds = values[key].shape[0]
                plural = "s" if seeds != 1 else ""
                label_text = f"{METHODS[method].label} ({seeds} seed{plural})"
                ax.plot(steps, mean, color=color, label=label_text)
                if std is not None:
                    ax.fill_between(steps, mean - std, mean + std, color=color, alpha=0.2, lw=0)
                ax.set_title(f"{task.upper()}: {label}")
                ax.set_xlabel("training steps")
        if axes[row, 0].get_legend_handles_labels()[0]:
            axes[row, 0].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return fig, drawn


def write_curves(root: str | Path, preset: str, out_dir: str | Path) -> list[Path]:
    """Write the HAP-effect, covariance-effect and all-methods figures as PNG and PDF.

    A figure none of whose methods has a finished run is not drawn, and an earlier file of
    it is removed (figures are functions of the current results only).

    Raises:
        UserInputError: if ``<root>/<preset>`` holds no task folder (wrong preset or root).
    """
    import matplotlib.pyplot as plt

    from distgprl.data import TASK_NAMES
    from distgprl.errors import UserInputError

    folder = Path(root) / preset
    tasks = [t for t in TASK_NAMES if (folder / t).is_dir()]
    if not tasks:
        raise UserInputError(
            f"{folder}: no results of any task ({', '.join(TASK_NAMES)}); run a sweep first"
        )
    written = []
    for name, methods in FIGURES.items():
        fig, drawn = plot_figure(root, preset, tasks, methods, f"{TITLES[name]} ({preset} preset)")
        if drawn:
            for suffix in ("png", "pdf"):
                buffer = io.BytesIO()
                # Fixed metadata keeps the files byte-identical when regenerated.
                metadata = (
                    {"Software": None}
                    if suffix == "png"
                    else {"CreationDate": None, "Producer": None}
                )
                fig.savefig(buffer, format=suffix, dpi=90, metadata=metadata)
                written.append(
                    atomic_write_bytes(
                        Path(out_dir) / f"{name}_{preset}.{suffix}", buffer.getvalue()
                    )
                )
        else:  # nothing to draw: an earlier figure would no longer match the results
            for suffix in ("png", "pdf"):
                (Path(out_dir) / f"{name}_{preset}.{suffix}").unlink(missing_ok=True)
        plt.close(fig)
    return written
