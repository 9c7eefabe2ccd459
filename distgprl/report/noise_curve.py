"""Where does each policy break? Per method with twin trials at two or more sensor-noise levels
(the safety layer's protocol, plan repair on), its success and collision rates (exact 95 %
binomial intervals) against the median over trials of each trial's largest marker position
error (mm; `distgprl.report.table2.hardware_rows`), each point labelled with its noise
level."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.figure_files import subplots, write_or_remove_figure

ERROR = "perception_error_mm_median"


def curve_series(rows: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """{method: its twin rows with repair ``retime`` and a perception error, by increasing
    error} for every method with at least two such rows (table order)."""
    series: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        error = row.get(ERROR, np.nan)
        if row["backend"] == "twin" and row["repair"] == "retime" and np.isfinite(error):
            series.setdefault(row["method"], []).append(row)
    ordered = sorted(series, key=lambda m: TABLE_ORDER.index(m) if m in TABLE_ORDER else 99)
    return {
        method: sorted(series[method], key=lambda r: r[ERROR])
        for method in ordered
        if len(series[method]) >= 2
    }


def write_noise_curve(rows: list[dict[str, Any]], out_dir: str | Path, preset: str) -> list[Path]:
    """Draw `curve_series` of Table II's ``rows`` into ``<out_dir>/table2_noise_<preset>``
    (PNG, PDF); with no method at two levels, remove an earlier figure instead."""
    series = curve_series(rows)
    fig, axes = subplots(1, 2, figsize=(10.0, 4.0), squeeze=False)
    for index, (method, points) in enumerate(series.items()):
        bold = method == "dist-gprl"
        x = np.array([p[ERROR] for p in points])
        for ax, key in zip(axes[0], ("success_rate", "collision_rate"), strict=True):
            y, low, high = (
                np.array([p[k] for p in points]) for k in (key, f"{key}_ci_low", f"{key}_ci_high")
            )
            ax.errorbar(
                x, y, yerr=[y - low, high - y], marker="o", capsize=2, lw=1.5 if bold else 1.0,
                color="black" if bold else f"C{index % 10}", label=METHODS[method].label,
            )  # fmt: skip
            for point, xi, yi in zip(points, x, y, strict=True) if index == 0 else ():
                ax.annotate(
                    f"{point['sensor_noise']}", (xi, yi), xytext=(4, 4),
                    textcoords="offset points", fontsize=7, alpha=0.6,
                )  # fmt: skip
    for ax, label in zip(axes[0], ("twin success rate", "twin collision rate"), strict=True):
        ax.set_xlabel("median perception error (mm)")
        ax.set_ylabel(label)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    trials = sorted({int(p["trials"]) for points in series.values() for p in points})
    fig.suptitle(
        f"Digital twin (DBM, {preset} preset policies, plan repair on): where each policy "
        f"breaks ({'/'.join(map(str, trials))} trials per point, exact 95 % intervals; "
        "numbers: sensor-noise level)",
        fontsize=9,
    )
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0.0, 0.08 + 0.04 * (len(labels) // 4), 1.0, 0.93))
    return write_or_remove_figure((fig, len(series)), Path(out_dir) / f"table2_noise_{preset}")
