"""Robust aggregates over seeds, rliable's by scipy.stats: means, IQMs and probabilities of
improvement (PoI) with stratified-bootstrap intervals ("The aggregates' statistics",
docs/findings/protocol.md)."""

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
BOOTSTRAP_SEED = 0
"""The seed of the committed tables (reproducible byte for byte)."""
CONFIDENCE = 0.95

PROPOSED = "dist-gprl"
PARTNERS = ("dist-gprl-global", "gprl-d", "gprl-h", "dist-gprl-nocov", "gprl", "promp-rrl")
"""The methods `PROPOSED` is compared with by PoI."""
ALL_TASKS = "all"
"""The task of the rows pooling every task (one stratum per task)."""
RATES = (("success_rate", "Success"), ("collision_rate", "Collision"))

HIGHER_IS_BETTER = {
    "success_rate": True,
    "collision_rate": False,
    "steps_to_gain": False,
    "learned_drop": False,
    "learning_auc": True,
    "mean_kinematic_retention": True,
}
"""Every score `run_scores` gives, and whether a higher value is an improvement."""

GAIN_MARGIN = 0.2
GAIN_POINTS = 2
"""`curve_measures`: the rise of curve success over the start that counts as learning, and the
consecutive points that must hold it."""

Scores = Mapping[tuple[str, str], Sequence[Mapping[str, float]]]
"""{(task, method): [`run_scores` per seed]}."""


@dataclass(frozen=True)
class Estimate:
    """A point estimate (nan without runs) with its interval (nan below two runs in a stratum);
    ``seeds``: runs per stratum (a PoI: the fewer of the two methods'); ``pairs``: a PoI's run
    pairs n_X n_Y per stratum."""

    point: float
    low: float
    high: float
    seeds: tuple[int, ...]
    pairs: tuple[int, ...] = ()

    @property
    def has_interval(self) -> bool:
        return bool(self.seeds) and min(self.seeds) >= 2

    def text(self, digits: int = 2) -> str:
        """``point [low, high]``, ``point (1 seed: no interval)``, or ``–`` without runs."""
        if not self.seeds:
            return "–"
        if not self.has_interval:
            return f"{self.point:.{digits}f} ({min(self.seeds)} seed: no interval)"
        return f"{self.point:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"

    def pairs_text(self) -> str:
        """A one-stratum PoI's run pairs favouring X (ties half): ``25/25 run pairs``."""
        if len(self.pairs) != 1 or not self.seeds:
            return ""
        won = self.point * self.pairs[0]
        count = f"{won:.0f}" if abs(won - round(won)) < 1e-9 else f"{won:.1f}"
        return f"{count}/{self.pairs[0]} run pairs"


_EMPTY = Estimate(math.nan, math.nan, math.nan, ())


def estimate_rng(seed: int, *names: str) -> np.random.Generator:
    """One estimate's generator, seeded by ``seed`` and the CRC-32 of its names."""
    key = zlib.crc32("/".join(names).encode())
    return np.random.default_rng(np.random.SeedSequence([seed, key]))


def mean_of_strata(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
    """rliable's ``aggregate_mean``: the mean over strata of each stratum's mean run."""
    return np.asarray(np.mean([s.mean(axis=axis) for s in samples], axis=0))


def iqm(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
    """rliable's ``aggregate_iqm``: the 25 % trimmed mean of all runs of all strata."""
    return np.asarray(stats.trim_mean(np.concatenate(samples, axis=axis), 0.25, axis=axis))


def improvement(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
    """P(X > Y) + P(X = Y) / 2 over run pairs (the Mann-Whitney U of X over n_x n_y), averaged
    over strata: samples X and Y of each stratum in turn, (reps, n) each -> (reps,)."""
    shares = [
        stats.mannwhitneyu(x, y, axis=axis, method="asymptotic", use_continuity=False).statistic
        / (x.shape[axis] * y.shape[axis])
        for x, y in zip(samples[::2], samples[1::2], strict=True)
    ]
    return np.asarray(np.mean(shares, axis=0))


def bootstrap_interval(
    samples: Sequence[np.ndarray],
    statistic: Callable[..., np.ndarray],
    rng: np.random.Generator,
    reps: int = BOOTSTRAP_REPS,
) -> tuple[np.ndarray, np.ndarray]:
    """The `CONFIDENCE` percentile interval (low, high) of ``statistic(*resamples, axis)`` by
    `scipy.stats.bootstrap`, each sample ((n_k,) or (n_k, m)) resampled on its own along axis 0."""
    result = stats.bootstrap(
        tuple(samples), statistic, n_resamples=reps, vectorized=True, method="percentile", rng=rng
    )
    tail = 100.0 * (1.0 - CONFIDENCE) / 2.0
    low, high = np.percentile(result.bootstrap_distribution, [tail, 100.0 - tail], axis=-1)
    return low, high


def interval_estimate(
    strata: Sequence[np.ndarray],
    statistic: Callable[..., np.ndarray],
    rng: np.random.Generator,
    reps: int = BOOTSTRAP_REPS,
) -> Estimate:
    """``statistic`` of the non-empty ``strata`` (1-D runs each) with its bootstrap interval."""
    arrays = [np.asarray(s, dtype=float) for s in strata if len(s)]
    if not arrays:
        return _EMPTY
    seeds = tuple(len(a) for a in arrays)
    point = float(statistic(*(a[None, :] for a in arrays), axis=-1)[0])
    if min(seeds) < 2:
        return Estimate(point, math.nan, math.nan, seeds)
    low, high = bootstrap_interval(arrays, statistic, rng, reps)
    return Estimate(point, float(low), float(high), seeds)


def newcombe_interval(theta: float, n_x: int, n_y: int) -> tuple[float, float]:
    """Newcombe's method-5 score interval of a PoI ``theta`` of ``n_x`` runs against ``n_y``."""
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


def probability_of_improvement(
    x_strata: Sequence[np.ndarray],
    y_strata: Sequence[np.ndarray],
    rng: np.random.Generator,
    higher_is_better: bool = True,
    reps: int = BOOTSTRAP_REPS,
) -> Estimate:
    """The PoI of X over Y averaged over the strata where both have runs, its independent
    bootstrap interval widened to the mean of the strata's `newcombe_interval`."""
    sign = 1.0 if higher_is_better else -1.0
    pairs = [
        (sign * np.asarray(x, dtype=float), sign * np.asarray(y, dtype=float))
        for x, y in zip(x_strata, y_strata, strict=True)
        if len(x) and len(y)
    ]
    if not pairs:
        return _EMPTY
    seeds = tuple(min(len(x), len(y)) for x, y in pairs)
    sizes = tuple(len(x) * len(y) for x, y in pairs)
    mean = interval_estimate([a for pair in pairs for a in pair], improvement, rng, reps)
    if not mean.has_interval:
        return Estimate(mean.point, math.nan, math.nan, seeds, sizes)
    bounds = [
        newcombe_interval(float(improvement(x[None, :], y[None, :])[0]), len(x), len(y))
        for x, y in pairs
    ]
    score_low, score_high = (float(bound) for bound in np.mean(bounds, axis=0))
    return Estimate(mean.point, min(mean.low, score_low), max(mean.high, score_high), seeds, sizes)


def curve_measures(points: pd.DataFrame) -> dict[str, float]:
    """``learning_auc``, ``steps_to_gain`` and ``learned_drop`` of one run's curve points
    (``step``, ``success_rate``; docs/findings/protocol.md), measured against the step-0
    point's success; empty without a step-0 point or with fewer than two points after it."""
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
    """One run's scores: its evaluation ``summary``'s rates and kinematic retention, the
    `curve_measures` of its curve ``points``."""
    keys = (*(key for key, _ in RATES), "mean_kinematic_retention")
    scores = {key: float(summary[key]) for key in keys if key in summary}
    return scores | curve_measures(points)


def strata(scores: Scores, tasks: Sequence[str], method: str, key: str) -> list[np.ndarray]:
    """Per task, ``method``'s runs' ``key`` scores (runs without it left out)."""
    return [
        np.array([run[key] for run in scores.get((task, method), ()) if key in run])
        for task in tasks
    ]


def tasks_of(scores: Scores) -> list[str]:
    """The tasks with runs, in the paper's order."""
    return sorted({task for task, _ in scores}, key=task_order)


def poi(scores: Scores, tasks: Sequence[str], x: str, y: str, key: str, seed: int) -> Estimate:
    """PoI of method ``x`` over ``y`` on score ``key`` over ``tasks``."""
    sides = (_key(scores, tasks, m, key) for m in (x, y))
    return _estimate("poi", seed, ("+".join(tasks), x, y, key), *sides)


def method_estimate(
    scores: Scores, tasks: Sequence[str], method: str, key: str, statistic: str, seed: int
) -> Estimate:
    """``statistic`` (``mean`` or ``iqm``) of ``method``'s ``key`` over ``tasks``."""
    side = _key(scores, tasks, method, key)
    return _estimate(statistic, seed, ("+".join(tasks), method, key), side)


def _key(scores: Scores, tasks: Sequence[str], method: str, key: str) -> tuple[bytes, ...]:
    """The strata as bytes, equal exactly when the scores are bit for bit: `_estimate`'s key."""
    return tuple(np.asarray(a, dtype=float).tobytes() for a in strata(scores, tasks, method, key))


@functools.cache  # claims and tables read one estimate several times: bootstrapped once
def _estimate(statistic: str, seed: int, names: tuple[str, ...], *sides: Any) -> Estimate:
    rng = estimate_rng(seed, statistic, *names)
    arrays = [[np.frombuffer(v) for v in side] for side in sides]
    if statistic == "poi":
        return probability_of_improvement(arrays[0], arrays[1], rng, HIGHER_IS_BETTER[names[-1]])
    return interval_estimate(arrays[0], {"mean": mean_of_strata, "iqm": iqm}[statistic], rng)


def estimate_cells(estimate: Estimate) -> dict[str, object]:
    """An estimate's CSV cells: ``value``, ``ci_low``, ``ci_high`` (empty without them) and the
    ``;``-separated ``seeds`` and ``pairs`` per stratum."""
    low, high = (estimate.low, estimate.high) if estimate.has_interval else ("", "")
    value = estimate.point if estimate.seeds else ""
    seeds, pairs = (";".join(map(str, counts)) for counts in (estimate.seeds, estimate.pairs))
    return {"value": value, "ci_low": low, "ci_high": high, "seeds": seeds, "pairs": pairs}


CSV_FIELDS = tuple("task method versus metric statistic value ci_low ci_high seeds".split())
"""Columns of ``aggregates_<preset>.csv``: ``statistic`` ``mean``, ``iqm`` or ``poi`` (of
``method`` over ``versus``; collision's PoI is that of fewer collisions)."""


def aggregate_rows(scores: Scores, seed: int) -> list[dict[str, Any]]:
    """The `CSV_FIELDS` rows (with the ``estimate``): per task group (each task, then
    `ALL_TASKS`) and method the mean and IQM of each rate, then the PoIs of `PROPOSED` over each
    partner with runs."""
    tasks = tasks_of(scores)
    groups = [(task, [task]) for task in tasks] + ([(ALL_TASKS, tasks)] if len(tasks) > 1 else [])
    rows: list[dict[str, Any]] = [
        dict(task=name, method=method, versus="", metric=key, statistic=statistic)
        | {"estimate": method_estimate(scores, group, method, key, statistic, seed)}
        for name, group in groups
        for method in TABLE_ORDER
        if any((task, method) in scores for task in group)
        for key, _ in RATES
        for statistic in ("mean", "iqm")
    ]
    rows += [
        dict(task=name, method=PROPOSED, versus=partner, metric=key, statistic="poi")
        | {"estimate": estimate}
        for name, group in groups
        for partner in PARTNERS
        for key, _ in RATES
        if (estimate := poi(scores, group, PROPOSED, partner, key, seed)).seeds
    ]
    return [row | estimate_cells(row["estimate"]) for row in rows]


def short_label(method: str) -> str:
    """The method's label without the paper's "(ours)"."""
    return METHODS[method].label.removesuffix(" (ours)")


def aggregate_texts(scores: Scores, preset: str) -> tuple[str, str]:
    """(CSV, Markdown) of `aggregate_rows`: a table of the means and IQMs per task group and
    method, and one of the PoIs per task group and partner."""
    rows = aggregate_rows(scores, BOOTSTRAP_SEED)
    caption = (
        f"Aggregates over seeds ({preset} preset): mean and IQM with 95 % stratified-bootstrap "
        f"intervals ({BOOTSTRAP_REPS} replicates, percentile; one stratum per task)"
    )
    header = ["Task", "Method", "Seeds"]
    header += [f"{label} {s}" for _, label in RATES for s in ("mean", "IQM")]
    markdown = markdown_table(caption, header, _table_rows(rows, "method"))
    poi_header = ["Task", "Dist-GPRL vs", "Seeds", "PoI success", "PoI fewer collisions"]
    poi_caption = (
        "Probability of improvement of Dist-GPRL over each ablation and baseline "
        "(P(X > Y) + P(X = Y)/2 over seed pairs, averaged over tasks; 95 % independent "
        "stratified-bootstrap interval; > 0.5 favours Dist-GPRL)"
    )
    if poi_table := _table_rows(rows, "versus"):
        markdown += "\n" + markdown_table(poi_caption, poi_header, poi_table)
    else:
        markdown += f"\n{poi_caption}: no runs of Dist-GPRL and a partner yet.\n"
    return csv_text(rows, CSV_FIELDS), markdown


def _table_rows(rows: list[dict[str, Any]], by: str) -> list[list[str]]:
    """Per task group and ``by`` (``method``: its means and IQMs; ``versus``: its PoIs) of
    `aggregate_rows`: its label, the method's, the seeds per stratum and the estimates."""
    table: dict[tuple[str, str], list[str]] = {}
    for row in rows:
        if (row["statistic"] == "poi") == (by == "versus"):
            task = "Both (stratified)" if row["task"] == ALL_TASKS else row["task"].upper()
            first = [task, METHODS[row[by]].label, row["seeds"].replace(";", "+")]
            table.setdefault((row["task"], row[by]), first).append(row["estimate"].text())
    return list(table.values())
