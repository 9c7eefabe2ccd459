"""Robust aggregates over seeds with stratified-bootstrap intervals (Agarwal et al. 2021).

Per task and method, over seeds: the mean and the interquartile mean (IQM) of the success and
collision rates, each with a 95 % percentile interval of the stratified bootstrap (one stratum
per task; rows of task ``all`` pool the tasks); per ablation pair (`PROPOSED` against each of
`PARTNERS`) the probability of improvement (PoI) with its interval, its score bound Newcombe's.
What each statistic computes, and why (rliable 1.2.0's, by scipy.stats): "The aggregates'
statistics" in docs/findings/protocol.md. Learning-curve measures per run (`curve_measures`)
are scored here too (`run_scores`).
"""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats
from scipy.optimize import brentq

from distgprl.data import task_order
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.markdown import csv_text, markdown_table

BOOTSTRAP_REPS = 2000
"""Bootstrap replicates per interval."""

BOOTSTRAP_SEED = 0
"""The seed `write_tables` passes in: the committed tables are reproducible byte for byte."""

CONFIDENCE = 0.95
"""Coverage of every interval."""

PROPOSED = "dist-gprl"
"""The method the ablation pairs compare against."""

PARTNERS = ("dist-gprl-global", "gprl-d", "gprl-h", "dist-gprl-nocov", "gprl", "promp-rrl")
"""The methods `PROPOSED` is compared with by probability of improvement."""

ALL_TASKS = "all"
"""The task name of the rows pooling every task (one stratum per task)."""

RATES = (("success_rate", "Success"), ("collision_rate", "Collision"))
"""The rates aggregated per task and method (key, label)."""

HIGHER_IS_BETTER: dict[str, bool] = {
    "success_rate": True,
    "collision_rate": False,
    "steps_to_gain": False,
    "learned_drop": False,
    "learning_auc": True,
    "mean_kinematic_retention": True,
}
"""Every score `run_scores` gives, and whether a higher value is an improvement."""

GAIN_MARGIN = 0.2
"""`curve_measures`: the rise in curve success above the untrained policy's that counts as
learning: two standard errors of the difference of two curve points at p = 1/2 on the paper's
50 curve TCs (docs/findings/protocol.md, "The aggregates' statistics")."""

GAIN_POINTS = 2
"""`curve_measures`: consecutive curve points that must all lie `GAIN_MARGIN` above the
start for the run to count as having learned (one point could be noise)."""

Strata = Sequence[np.ndarray]
"""One 1-D array of per-run scores per stratum (task)."""

Statistic = Callable[..., np.ndarray]
"""A statistic of strata, ``statistic(*strata, axis=-1)``: arrays (reps, n_k) -> values
(reps,), the runs along ``axis`` (`scipy.stats.bootstrap`'s vectorized form)."""


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its bootstrap interval.

    Attributes:
        point: the statistic on the data (nan with no runs).
        low, high: the `CONFIDENCE` interval (nan if a stratum has < 2 runs): the bootstrap
            percentile interval, for a PoI widened to its score bound (`newcombe_interval`).
        seeds: runs per stratum (for a PoI, the smaller of the two methods' per stratum).
        pairs: for a PoI, the run pairs (n_X n_Y) per stratum; empty otherwise.
    """

    point: float
    low: float
    high: float
    seeds: tuple[int, ...]
    pairs: tuple[int, ...] = ()

    @property
    def has_interval(self) -> bool:
        """Whether every stratum had at least two runs (so the interval exists)."""
        return bool(self.seeds) and min(self.seeds) >= 2

    def text(self, digits: int = 2) -> str:
        """``point [low, high]``; ``point (1 seed: no interval)`` below two runs in a
        stratum; ``–`` with no runs."""
        if not self.seeds:
            return "–"
        if not self.has_interval:
            return f"{self.point:.{digits}f} ({min(self.seeds)} seed: no interval)"
        return f"{self.point:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"

    def pairs_text(self) -> str:
        """For a PoI on one stratum, the run pairs that favour X (ties count half), e.g.
        ``25/25 run pairs``; empty otherwise."""
        if len(self.pairs) != 1 or not self.seeds:
            return ""
        won = self.point * self.pairs[0]
        count = f"{won:.0f}" if abs(won - round(won)) < 1e-9 else f"{won:.1f}"
        return f"{count}/{self.pairs[0]} run pairs"


def estimate_rng(seed: int, *names: str) -> np.random.Generator:
    """The generator of one estimate: seeded by ``seed`` and the estimate's names (CRC-32,
    stable across processes, unlike `hash`)."""
    key = zlib.crc32("/".join(names).encode())
    return np.random.default_rng(np.random.SeedSequence([seed, key]))


def mean_of_strata(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
    """rliable's ``aggregate_mean``: the mean over strata of each stratum's mean run."""
    return np.asarray(np.mean([s.mean(axis=axis) for s in samples], axis=0))


def iqm(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
    """rliable's ``aggregate_iqm``: the 25 % trimmed mean of all runs of all strata."""
    return np.asarray(stats.trim_mean(np.concatenate(samples, axis=axis), 0.25, axis=axis))


def improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """P(X > Y) + P(X = Y) / 2 over all run pairs, per replicate: (reps, n_x), (reps, n_y)
    -> (reps,): scipy's Mann-Whitney U of X over n_x n_y (rliable's
    ``probability_of_improvement``), 1/2 for identical samples."""
    u = stats.mannwhitneyu(x, y, axis=-1, method="asymptotic", use_continuity=False).statistic
    probability: np.ndarray = np.asarray(u) / (x.shape[-1] * y.shape[-1])
    return probability


def bootstrap_interval(
    samples: Sequence[np.ndarray],
    statistic: Statistic,
    rng: np.random.Generator,
    reps: int = BOOTSTRAP_REPS,
) -> tuple[np.ndarray, np.ndarray]:
    """The `CONFIDENCE` percentile interval (low, high) of ``statistic`` over ``samples``
    (each a (n_k,) or (n_k, m) array; statistic(*resamples, axis) -> values) by
    `scipy.stats.bootstrap`: ``reps`` replicates, each resampling every sample (stratum) with
    replacement on its own along its first axis; endpoints by `numpy.percentile` of scipy's
    bootstrap distribution."""
    result = stats.bootstrap(
        tuple(samples),
        statistic,
        n_resamples=reps,
        vectorized=True,
        axis=0,
        method="percentile",
        confidence_level=CONFIDENCE,
        rng=rng,
    )
    tail = 100.0 * (1.0 - CONFIDENCE) / 2.0
    low, high = np.percentile(result.bootstrap_distribution, [tail, 100.0 - tail], axis=-1)
    return low, high


def interval_estimate(
    strata: Strata, statistic: Statistic, rng: np.random.Generator, reps: int = BOOTSTRAP_REPS
) -> Estimate:
    """``statistic`` of ``strata`` (empty strata dropped) with its stratified-bootstrap
    percentile interval (`bootstrap_interval`; rliable ``get_interval_estimates``, one score
    array)."""
    arrays = [np.asarray(s, dtype=float) for s in strata if len(s)]
    seeds = tuple(len(a) for a in arrays)
    if not arrays:
        return Estimate(math.nan, math.nan, math.nan, ())
    point = float(statistic(*(a[None, :] for a in arrays), axis=-1)[0])
    if min(seeds) < 2:
        return Estimate(point, math.nan, math.nan, seeds)
    low, high = bootstrap_interval(arrays, statistic, rng, reps)
    return Estimate(point, float(low), float(high), seeds)


def newcombe_interval(theta: float, n_x: int, n_y: int) -> tuple[float, float]:
    """The `CONFIDENCE` score interval of a PoI ``theta`` (in [0, 1]) of ``n_x`` runs
    against ``n_y``: every θ with (theta - θ)² <= z² V(θ), V Newcombe's (2006) method-5
    Hanley-McNeil variance (docs/findings/protocol.md, "The aggregates' statistics"), so it is
    not degenerate at 0 or 1 (5 vs 5 runs at 1: [0.65, 1])."""
    z = stats.norm.ppf(0.5 + CONFIDENCE / 2.0)
    n = (n_x + n_y) / 2.0

    def outside(t: float) -> float:  # > 0 where t lies outside the interval
        shape = 1.0 + (n - 1.0) * (1.0 - t) / (2.0 - t) + (n - 1.0) * t / (1.0 + t)
        return (theta - t) ** 2 - z**2 * (t * (1.0 - t) * shape / (n_x * n_y))

    # At theta = 0 or 1 the variance vanishes there, so search from just inside the range.
    inner = min(max(theta, 1e-12), 1.0 - 1e-12)
    low = 0.0 if outside(0.0) <= 0.0 else brentq(outside, 0.0, inner)
    high = 1.0 if outside(1.0) <= 0.0 else brentq(outside, inner, 1.0)
    return float(low), float(high)


def mean_improvement(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
    """The mean over strata of `improvement`, a `Statistic` of X and Y of each stratum in
    turn ((reps, n) each, the runs along the last axis)."""
    pairs = zip(samples[::2], samples[1::2], strict=True)
    return np.asarray(np.mean([improvement(x, y) for x, y in pairs], axis=0))


def probability_of_improvement(
    x_strata: Strata,
    y_strata: Strata,
    rng: np.random.Generator,
    higher_is_better: bool = True,
    reps: int = BOOTSTRAP_REPS,
) -> Estimate:
    """The PoI of X over Y (P(X > Y) + P(X = Y) / 2 over run pairs, `improvement`) averaged
    over the strata where both have runs, with its independent stratified-bootstrap interval
    (`interval_estimate` of `mean_improvement`) widened to the mean of the strata's
    `newcombe_interval` bounds (docs/findings/protocol.md, "The aggregates' statistics")."""
    sign = 1.0 if higher_is_better else -1.0
    pairs = [
        (sign * np.asarray(x, dtype=float), sign * np.asarray(y, dtype=float))
        for x, y in zip(x_strata, y_strata, strict=True)
        if len(x) and len(y)
    ]
    if not pairs:
        return Estimate(math.nan, math.nan, math.nan, ())
    seeds = tuple(min(len(x), len(y)) for x, y in pairs)
    sizes = tuple(len(x) * len(y) for x, y in pairs)
    mean = interval_estimate([a for pair in pairs for a in pair], mean_improvement, rng, reps)
    if not mean.has_interval:
        return Estimate(mean.point, math.nan, math.nan, seeds, sizes)
    bounds = [
        newcombe_interval(float(improvement(x[None, :], y[None, :])[0]), len(x), len(y))
        for x, y in pairs
    ]
    score_low, score_high = (float(bound) for bound in np.mean(bounds, axis=0))
    return Estimate(mean.point, min(mean.low, score_low), max(mean.high, score_high), seeds, sizes)


def curve_measures(points: pd.DataFrame) -> dict[str, float]:
    """Learning-curve measures of one run's curve points (its rows of a
    `distgprl.report.frame.curves_of` frame: ``step``, ``success_rate`` on the fixed curve
    TCs), each against the run's start s0, the untrained policy's curve success at step 0
    (definitions and reasons: docs/findings/protocol.md, "The aggregates' statistics"):

    - ``learning_auc``: the mean gain over s0 during training (trapezoid area / steps), in
      [-1, 1]; higher is better.
    - ``steps_to_gain``: the first trained step from which `GAIN_POINTS` consecutive points
      reach s0 + `GAIN_MARGIN`, censored one curve period past the last step; lower is better.
    - ``learned_drop``: from that step on, the mean drop of curve success per curve period,
      +inf for a run that never learned; lower is better.

    Empty without a step-0 point or with fewer than two trained points.
    """
    if points.empty:
        return {}
    steps = points["step"].to_numpy(dtype=float)
    success = points["success_rate"].to_numpy(dtype=float)
    trained = steps > 0
    if trained.sum() < 2 or not np.any(steps == 0):
        return {}
    start = float(success[np.flatnonzero(steps == 0)[0]])
    t_steps, t_success = steps[trained], success[trained]
    auc = np.trapezoid(success - start, steps) / (steps[-1] - steps[0])  # mean gain
    above = t_success >= start + GAIN_MARGIN - 1e-12
    runs = np.lib.stride_tricks.sliding_window_view(above, GAIN_POINTS).all(axis=1)
    if runs.any():
        first = int(np.flatnonzero(runs)[0])
        steps_to = float(t_steps[first])
        drop = float(np.mean(np.maximum(0.0, -np.diff(t_success[first:]))))
    else:
        steps_to = float(t_steps[-1] + (t_steps[-1] - t_steps[-2]))  # censored: never
        drop = math.inf
    return {"learning_auc": float(auc), "steps_to_gain": steps_to, "learned_drop": drop}


def run_scores(summary: Mapping[str, float], points: pd.DataFrame) -> dict[str, float]:
    """Every `HIGHER_IS_BETTER` score of one run: its evaluation's rates and mean kinematic
    retention (velocity cosine to the demonstration; ``summary``) and the `curve_measures` of
    its curve ``points`` (none for an untrained reference)."""
    keys = (*(key for key, _ in RATES), "mean_kinematic_retention")
    scores = {key: float(summary[key]) for key in keys if key in summary}
    scores.update(curve_measures(points))
    return scores


Scores = Mapping[tuple[str, str], Sequence[Mapping[str, float]]]
"""{(task, method): [`run_scores` per seed]}."""


def strata(scores: Scores, tasks: Sequence[str], method: str, key: str) -> list[np.ndarray]:
    """One array per task in ``tasks``: ``method``'s runs' ``key`` score (runs without it
    left out)."""
    return [
        np.array([run[key] for run in scores.get((task, method), ()) if key in run])
        for task in tasks
    ]


def tasks_of(scores: Scores) -> list[str]:
    """The tasks with runs, in the paper's order."""
    return sorted({task for task, _ in scores}, key=task_order)


def task_groups(scores: Scores) -> list[tuple[str, list[str]]]:
    """(name, strata tasks): each task alone, then `ALL_TASKS` with every task if several."""
    tasks = tasks_of(scores)
    groups = [(task, [task]) for task in tasks]
    return groups + ([(ALL_TASKS, tasks)] if len(tasks) > 1 else [])


def poi(scores: Scores, tasks: Sequence[str], x: str, y: str, key: str, seed: int) -> Estimate:
    """PoI of method ``x`` over ``y`` on score ``key`` over ``tasks`` (its own generator)."""
    x_strata, y_strata = (_bytes(strata(scores, tasks, m, key)) for m in (x, y))
    return _poi(x_strata, y_strata, HIGHER_IS_BETTER[key], seed, "+".join(tasks), x, y, key)


def method_estimate(
    scores: Scores, tasks: Sequence[str], method: str, key: str, statistic: str, seed: int
) -> Estimate:
    """``statistic`` (``mean`` or ``iqm``) of ``method``'s ``key`` over ``tasks``."""
    values = _bytes(strata(scores, tasks, method, key))
    return _method_estimate(values, statistic, seed, "+".join(tasks), method, key)


def _bytes(arrays: list[np.ndarray]) -> tuple[bytes, ...]:
    """Each stratum's float64 scores as bytes: the key of the estimate caches below, equal
    exactly when the scores are (bit for bit, so -0.0 and each NaN stay apart)."""
    return tuple(np.asarray(a, dtype=float).tobytes() for a in arrays)


# An estimate is a function of its strata, seed and names (its generator's seed): cached, the
# claims and aggregates that read one estimate several times bootstrap it once.
@functools.cache
def _poi(
    x: tuple[bytes, ...], y: tuple[bytes, ...], higher_is_better: bool, seed: int, *names: str
) -> Estimate:
    rng = estimate_rng(seed, "poi", *names)
    x_strata, y_strata = ([np.frombuffer(v) for v in side] for side in (x, y))
    return probability_of_improvement(x_strata, y_strata, rng, higher_is_better)


@functools.cache
def _method_estimate(values: tuple[bytes, ...], statistic: str, seed: int, *names: str) -> Estimate:
    rng = estimate_rng(seed, statistic, *names)
    function = {"mean": mean_of_strata, "iqm": iqm}[statistic]
    return interval_estimate([np.frombuffer(v) for v in values], function, rng)


def estimate_cells(estimate: Estimate) -> dict[str, object]:
    """An estimate's CSV cells: ``value`` (empty without runs), ``ci_low`` and ``ci_high``
    (empty below two runs in a stratum), ``seeds`` (runs per task stratum) and ``pairs`` (a
    PoI's run pairs per stratum), each ``;``-separated."""
    interval = (estimate.low, estimate.high) if estimate.has_interval else ("", "")
    return {
        "value": estimate.point if estimate.seeds else "",
        "ci_low": interval[0],
        "ci_high": interval[1],
        "seeds": ";".join(map(str, estimate.seeds)),
        "pairs": ";".join(map(str, estimate.pairs)),
    }


CSV_FIELDS = tuple("task method versus metric statistic value ci_low ci_high seeds".split())
"""Columns of ``aggregates_<preset>.csv``, one row per estimate: ``statistic`` is ``mean``,
``iqm`` or ``poi`` (of ``method`` over ``versus``, on ``metric``: collision's PoI is that of
fewer collisions); the estimate's cells as `estimate_cells` writes them."""


def aggregate_rows(scores: Scores, seed: int) -> list[dict[str, Any]]:
    """Every estimate of the aggregates table (`CSV_FIELDS`, the `Estimate` beside as
    ``estimate``): per task group and method (table order) the mean and IQM of each rate,
    then per task group the PoI of `PROPOSED` over each of `PARTNERS` that both have runs
    of."""
    rows: list[dict[str, Any]] = []
    for name, tasks in task_groups(scores):
        for method in TABLE_ORDER:
            if any((task, method) in scores for task in tasks):
                for key, _ in RATES:
                    for statistic in ("mean", "iqm"):
                        estimate = method_estimate(scores, tasks, method, key, statistic, seed)
                        rows.append(_row(name, method, "", key, statistic, estimate))
    for name, tasks in task_groups(scores):
        for partner in PARTNERS:
            for key, _ in RATES:
                estimate = poi(scores, tasks, PROPOSED, partner, key, seed)
                if estimate.seeds:
                    rows.append(_row(name, PROPOSED, partner, key, "poi", estimate))
    return rows


def _row(
    task: str, method: str, versus: str, key: str, statistic: str, estimate: Estimate
) -> dict[str, Any]:
    """One `aggregate_rows` row."""
    names = dict(task=task, method=method, versus=versus, metric=key, statistic=statistic)
    return names | estimate_cells(estimate) | {"estimate": estimate}


def short_label(method: str) -> str:
    """The method's label without the paper's "(ours)"."""
    return METHODS[method].label.removesuffix(" (ours)")


def aggregate_texts(scores: Scores, preset: str, seed: int = BOOTSTRAP_SEED) -> tuple[str, str]:
    """(CSV, Markdown) of the aggregates table (`aggregate_rows`): a table of the means and
    IQMs per task group and method, and one of the PoIs per task group and partner."""
    rows = aggregate_rows(scores, seed)
    frame = pd.DataFrame(rows, columns=[*CSV_FIELDS, "estimate"])
    frame["text"] = frame["estimate"].map(Estimate.text)
    frame["label"] = frame["task"].map(
        lambda t: "Both (stratified)" if t == ALL_TASKS else t.upper()
    )
    frame["seeds"] = frame["seeds"].str.replace(";", "+")
    is_poi = frame["statistic"] == "poi"
    table = [
        [group["label"].iloc[0], METHODS[str(method)].label, group["seeds"].iloc[0], *group["text"]]
        for (_, method), group in frame[~is_poi].groupby(["task", "method"], sort=False)
    ]
    poi_table = [
        [group["label"].iloc[0], METHODS[str(partner)].label, group["seeds"].iloc[0]]
        + [group.set_index("metric")["text"].get(key, "–") for key, _ in RATES]
        for (_, partner), group in frame[is_poi].groupby(["task", "versus"], sort=False)
    ]
    caption = (
        f"Aggregates over seeds ({preset} preset): mean and IQM with 95 % stratified-bootstrap "
        f"intervals ({BOOTSTRAP_REPS} replicates, percentile; one stratum per task)"
    )
    header = ["Task", "Method", "Seeds"]
    header += [f"{label} {s}" for _, label in RATES for s in ("mean", "IQM")]
    markdown = markdown_table(caption, header, table)
    poi_header = ["Task", "Dist-GPRL vs", "Seeds", "PoI success", "PoI fewer collisions"]
    poi_caption = (
        "Probability of improvement of Dist-GPRL over each ablation and baseline "
        "(P(X > Y) + P(X = Y)/2 over seed pairs, averaged over tasks; 95 % independent "
        "stratified-bootstrap interval; > 0.5 favours Dist-GPRL)"
    )
    if poi_table:
        markdown += "\n" + markdown_table(poi_caption, poi_header, poi_table)
    else:
        markdown += f"\n{poi_caption}: no runs of Dist-GPRL and a partner yet.\n"
    return csv_text(rows, CSV_FIELDS), markdown
