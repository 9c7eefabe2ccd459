"""The benchmark figure (PNG), from a `run_benchmarks` JSON."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_results"]


def plot_results(document: dict[str, Any], path: Path) -> Path:
    """A 2x2 figure: per-window components vs paper and naive; via-point and obstacle scaling;
    training-time breakdown. Written as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    a = document["adaptation"]
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    names = ["edf", "gp_conditioning", "policy"]
    ours = [a["per_window"][n]["median_us"] / 1e3 for n in names]
    paper = [a["paper_ms_per_window"][n] for n in names]
    naive = [
        a["naive_per_window"][k]["median_us"] / 1e3
        for k in ("edf_pybullet", "gp_resolve", "policy_sb3_predict")
    ]
    x = np.arange(len(names))
    ax = axes[0, 0]
    ax.bar(x - 0.27, ours, 0.27, label="this package")
    ax.bar(x, naive, 0.27, label="naive (same run)")
    ax.bar(x + 0.27, paper, 0.27, label="paper (i7-1185G7)")
    ax.set_xticks(x, ["EDF query", "GP conditioning", "policy"])
    ax.set_yscale("log")
    ax.set_ylabel("ms per window (median)")
    ax.set_title("Adaptation compute per window")
    ax.legend(fontsize=8)

    ax = axes[0, 1]
    rows = document["scaling"]["via_points"]
    n = [r["n_via_points"] for r in rows]
    for key, label in (
        ("episode", "per episode"),
        ("edf_window", "EDF / window"),
        ("gp_window", "GP / window"),
        ("policy_window", "policy / window"),
    ):
        ax.plot(n, [r[key]["median_us"] / 1e3 for r in rows], "o-", label=label)
    ax.set_xlabel("via-points N (windows of N // 3)")
    ax.set_ylabel("ms (median)")
    ax.set_title("Adaptation compute vs via-points")
    ax.legend(fontsize=8)

    ax = axes[1, 0]
    rows = document["scaling"]["obstacles"]
    k = [r["n_obstacles"] for r in rows]
    for key, label in (
        ("episode", "adaptation per episode"),
        ("edf_window", "EDF query / window"),
        ("pybullet_window", "PyBullet closest points / window"),
    ):
        ax.plot(k, [r[key]["median_us"] / 1e3 for r in rows], "o-", label=label)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("obstacles (boxes)")
    ax.set_ylabel("ms (median)")
    ax.set_title("Adaptation compute vs obstacles")
    ax.legend(fontsize=8)

    ax = axes[1, 1]
    breakdown = sorted(document["training"]["breakdown"].items(), key=lambda kv: kv[1]["fraction"])
    ax.barh([name for name, _ in breakdown], [p["ms_per_step"] for _, p in breakdown])
    ax.tick_params(axis="y", labelsize=7)
    ax.set_xlabel("ms per training step")
    ax.set_title(f"Training step ({document['training']['steps_per_s']:.1f} steps/s)")
    load = document["machine"]["load_average"][0]
    fig.suptitle(f"distgprl bench — {document['machine']['cpu']}, load {load:.1f}", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
