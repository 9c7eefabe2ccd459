"""The benchmark figure (PNG), from a `run_benchmarks` JSON."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_results"]


def plot_results(document: dict[str, Any], path: Path) -> Path:
    """A 1x2 figure: the per-window adaptation components against the paper's and the naive
    ones; the suite's CPU-hours against its floor's. Written as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    a = document["adaptation"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    names = ["edf", "gp_conditioning", "policy"]
    ours = [a["per_window"][n]["median_us"] / 1e3 for n in names]
    paper = [a["paper_ms_per_window"][n] for n in names]
    naive = [
        a["naive_per_window"][k]["median_us"] / 1e3
        for k in ("edf_pybullet", "gp_resolve", "policy_sb3_predict")
    ]
    x = np.arange(len(names))
    ax = axes[0]
    ax.bar(x - 0.27, ours, 0.27, label="this package")
    ax.bar(x, naive, 0.27, label="naive (same run)")
    ax.bar(x + 0.27, paper, 0.27, label="paper (i7-1185G7)")
    ax.set_xticks(x, ["EDF query", "GP conditioning", "policy"])
    ax.set_yscale("log")
    ax.set_ylabel("ms per window (median)")
    ax.set_title("Adaptation compute per window")
    ax.legend(fontsize=8)

    ax = axes[1]
    suite = document["suite"]
    hours = [suite["cpu_hours"], suite["floor"]["cpu_hours"]]
    ax.bar([0, 1], hours, 0.5)
    ax.set_xticks([0, 1], ["suite (measured steps)", "floor (products + bare physics)"])
    ax.set_ylabel("CPU-hours")
    ax.set_title(f"Paper suite vs its floor (x{document['ratios']['suite_over_floor']:.2f})")
    load = document["machine"]["load_average"][0]
    fig.suptitle(f"distgprl bench — {document['machine']['cpu']}, load {load:.1f}", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
