"""The cells of the mechanism table (`distgprl.report.mechanisms`; protocol v6, rule 7 in
docs/findings/protocol.md): the shaping shares of the return, the regulariser shares of the
actor gradient, and the r_ga plateau with protocol v8 rule 1's two ratios measured
(docs/findings/environment-v8.md). Inputs are result CSVs as frames
(`distgprl.report.frame.csv_frame`: an empty cell NaN); a cell is a dict keyed by the table's
CSV columns (`distgprl.report.mechanisms.CSV_COLUMNS`; a share a fraction, None where there is
none) and the values behind them.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from distgprl.methods import METHODS

CRITERION = 0.05
"""The pre-registered share (rule 7): each shaping term ≥ 5 % of the return where it acts,
each regulariser's actor gradient ≥ 5 % of the Q term's (L_hap: outside C_safe)."""

NOT_RECORDED = "not recorded"
"""The verdict of a cell whose result files predate the columns it needs."""

POINTS = ("first", "middle", "last")
"""The learning-curve points of the gradient shares."""

RETURN_TERMS = {"r_ga": "return_ga", "r_sd": "return_sd"}
"""Shaping term -> its evaluation column (``return_ga`` holds lambda_ga r_ga), in row order."""

GRADIENT_ITEMS = {"l_sim": "grad_sim", "l_hap": "grad_hap", "l_hap_active": "grad_hap_active"}
"""Regulariser item (``l_hap_active``: L_hap over the samples outside C_safe) -> its
``progress.csv`` column, a share of ``grad_q``."""

ACTIVE = "hap_active_fraction"
"""The ``progress.csv`` column of the share of samples outside C_safe."""

IDLE_PROGRESS = 0.05
"""An episode that neither succeeded nor collided is idle if its r_tc is below this share of
the task's progress weight."""

Cell = dict[str, Any]


def _columns(frame: pd.DataFrame, columns: Iterable[str]) -> pd.DataFrame:
    """``frame`` with ``columns``, NaN where it lacks one."""
    return frame.assign(**{column: frame.get(column, np.nan) for column in columns})


def mean(values: Sequence[float] | np.ndarray) -> float | None:
    """The mean of ``values``; None if there are none."""
    return float(np.mean(values)) if len(values) else None


def judged(share: float) -> str:
    """``yes`` where ``share`` meets `CRITERION`, else ``no``."""
    return "yes" if share >= CRITERION else "no"


def return_cells(keys: Cell, episodes: pd.DataFrame) -> list[Cell]:
    """The r_ga and r_sd cells of one method's policy (``keys``: ``task``, ``method``,
    ``where``) from ``episodes``, the evaluation rows of its runs with the run's ``seed`` and
    ``d_min`` (m). Pooled over the runs that record the return's parts in every row
    (``recorded`` of ``seeds``, ``episodes`` theirs): ``shares`` the per-episode
    |Σ term| / |Σ r_tc| of the ``episodes_within_d_min`` (``min_clearance`` < d_min) less the
    ``episodes_zero_tc`` (Σ r_tc = 0, no ratio). ``meets_criterion``: the mean's verdict,
    ``not recorded``, or ``n/a`` (no ratio: the term never acted)."""
    needed = ["return_tc", *RETURN_TERMS.values()]
    parts = _columns(episodes, needed)
    complete = parts[needed].notna().all(axis=1)
    recorded = parts[complete.groupby(parts["seed"]).transform("all")]
    within = recorded["min_clearance"] < recorded["d_min"]
    paid = within & (recorded["return_tc"] != 0.0)
    counts = {"seeds": episodes["seed"].nunique(), "recorded": recorded["seed"].nunique()}
    counts |= {"episodes": len(recorded), "episodes_within_d_min": int(within.sum())}
    counts["episodes_zero_tc"] = int(within.sum() - paid.sum())
    cells = []
    for term, column in RETURN_TERMS.items():
        shares = (recorded[column].abs() / recorded["return_tc"].abs())[paid].to_numpy()
        share = mean(shares)
        verdict = "n/a" if share is None else judged(share)
        cells.append(
            {
                "section": "return_share",
                **keys,
                **counts,
                "item": term,
                "shares": shares,
                "share_mean": share,
            }
            | {"share_median": None if share is None else float(np.median(shares))}
            | {"meets_criterion": verdict if counts["recorded"] else NOT_RECORDED}
        )
    return cells


def plateau_cell(keys: Cell, episodes: pd.DataFrame) -> Cell | None:
    """How often one method's policy (``keys`` as `return_cells`) idles on the r_ga plateau,
    over its evaluation ``episodes`` that record r_tc (``episodes`` of ``seeds`` runs; rows as
    `return_cells`' with the run's ``progress_weight`` and, under its reward scale, a success's
    r_tc ``success_return`` and the demonstration's mean r_tc ``demo_return``): the ``idle``
    ones (no success, no collision, r_tc < `IDLE_PROGRESS` × progress weight) and their mean
    lambda_ga r_ga ``mean_ga``; rule 1's ratios ``ga_of_success`` (each episode's
    lambda_ga Σ r_ga over a success's r_tc) and ``idle_of_demo`` (each idle episode's
    r_tc + r_sd + lambda_ga r_ga over the demonstration's). None if no episode records r_tc."""
    rows = _columns(episodes, ["return_tc", "return_sd", "return_ga"])
    rows = rows[rows["return_tc"].notna()]
    if rows.empty:
        return None
    ga = rows["return_ga"].fillna(0.0)
    done = rows["success"].round().astype(bool) | rows["collision"].round().astype(bool)
    idle = ~done & (rows["return_tc"] < IDLE_PROGRESS * rows["progress_weight"])
    whole = rows["return_tc"] + rows["return_sd"].fillna(0.0) + ga
    return {
        **keys,
        "seeds": rows["seed"].nunique(),
        "episodes": len(rows),
        "idle": int(idle.sum()),
        "mean_ga": mean(ga[idle].to_numpy()),
        "ga_of_success": (ga / rows["success_return"]).to_numpy(),
        "idle_of_demo": (whole / rows["demo_return"])[idle].to_numpy(),
    }


def gradient_points(curve: pd.DataFrame) -> pd.DataFrame:
    """The first, middle (row (n - 1) // 2 of n) and last rows by step of one run's learning
    ``curve`` (``progress.csv`` rows) that recorded the actor's gradient norms (``grad_q`` > 0:
    not the step-0 point), indexed by `POINTS`; empty if none did."""
    recorded = curve[curve["grad_q"] > 0].sort_values("step", kind="stable")
    last = len(recorded) - 1
    return recorded.iloc[[0, last // 2, last]].set_axis(POINTS) if last >= 0 else recorded


def gradient_cells(task: str, method: str, curves: Sequence[pd.DataFrame]) -> list[Cell]:
    """The cells of every item the method uses (L_sim, L_hap) at each of `POINTS`, in that
    order, from the learning ``curves`` of its runs: ``step`` the point's RL steps over the
    ``seeds`` that have it; ``shares`` grad_item / grad_q per run recording it, ``share_mean``
    their mean; ``active_fraction`` (``l_hap_active``) the mean share of samples outside
    C_safe. ``meets_criterion``: the mean's verdict; ``n/a`` for ``l_hap`` (all samples:
    reported, not judged); ``inactive`` where every run lacks ``grad_hap_active`` with no
    sample outside C_safe; ``not recorded`` otherwise."""
    spec = METHODS[method]
    used = {"l_sim": spec.similarity_loss, "l_hap": spec.hap_prior, "l_hap_active": spec.hap_prior}
    columns = ["step", "grad_q", ACTIVE, *GRADIENT_ITEMS.values()]
    points = pd.concat([gradient_points(_columns(curve, columns)) for curve in curves])
    cells = []
    for point in POINTS:
        rows = points[points.index == point]
        for item in (item for item in GRADIENT_ITEMS if used[item]):
            value = rows[GRADIENT_ITEMS[item]]
            shares = (value / rows["grad_q"])[value.notna()].to_numpy()
            hap = item == "l_hap_active"
            inactive = int((value.isna() & (rows[ACTIVE] == 0.0)).sum()) if hap else 0
            missing = len(curves) - len(rows) + int(value.isna().sum()) - inactive
            share = mean(shares)
            verdict = "inactive" if inactive and not missing else NOT_RECORDED
            verdict = "n/a" if item == "l_hap" else verdict if share is None else judged(share)
            cells.append(
                {"section": "gradient_share", "task": task, "method": method, "item": item}
                | {"where": point}
                | {"step": _steps(rows["step"].astype(int)), "seeds": len(rows)}
                | {"shares": shares, "share_mean": share, "meets_criterion": verdict}
                | {"active_fraction": mean(rows[ACTIVE].dropna().to_numpy()) if hap else None}
            )
    return cells


def _steps(steps: pd.Series) -> str:
    """``1500`` or ``1500–3000``: the RL steps' range; empty without steps."""
    if steps.empty:
        return ""
    low, high = steps.min(), steps.max()
    return str(low) if low == high else f"{low}–{high}"
