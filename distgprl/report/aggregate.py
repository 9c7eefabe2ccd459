"""Robust aggregates over seeds with stratified-bootstrap intervals (Agarwal et al. 2021).

Per task and method, over seeds: the mean and the interquartile mean (IQM, the 25 %
trimmed mean) of the success and collision rates, each with a 95 % percentile interval of
the stratified bootstrap; per ablation pair (`PROPOSED` against each of `PARTNERS`) the
probability of improvement (PoI) with its interval, on success (higher is better) and on
collision (lower is better). Rows of task ``all`` pool both tasks, one stratum per task.

This is `rliable` 1.2.0's ``get_interval_estimates`` (``method="percentile"``), written out
here because rliable cannot be imported in this environment: it requires ``arch<8``, and
arch 7.2.0 fails at import under pandas 3 (``deprecate_kwarg``). What it computes, following
rliable's ``StratifiedBootstrap``, ``StratifiedIndependentBootstrap`` and ``metrics``:

- a bootstrap replicate resamples, with replacement, the runs (seeds) of every stratum
  (task) on its own, the same number as the stratum has;
- the mean is the mean over strata of the per-stratum means (``aggregate_mean``), the IQM
  is the 25 % trimmed mean of all the runs' scores pooled (``aggregate_iqm``);
- the PoI of X over Y is, per stratum, P(X > Y) + P(X = Y) / 2 over every pair of a run of
  X and a run of Y (the Mann-Whitney U statistic over n_X n_Y, ``probability_of_improvement``)
  averaged over strata; its bootstrap resamples X and Y independently, each stratified;
  "lower is better" scores are negated first;
- the interval is the 2.5th and 97.5th percentile of `BOOTSTRAP_REPS` replicates.

Unlike rliable's matrices, strata may hold different numbers of runs (runs still
accumulating). A stratum of fewer than two runs has no interval (`Estimate.text` says so).
Randomness is passed in: each estimate draws from its own generator, seeded by the table's
seed and the estimate's name (`estimate_rng`), so adding a method or a run of another
method leaves every other interval unchanged.

Learning-curve measures per run (`curve_measures`, from ``progress.csv``; the claims table's,
fixed before any v5 run was looked at) are scored here too (`run_scores`).
"""

from __future__ import annotations

import csv
import io
import math
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from distgprl.data import task_order
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.markdown import markdown_table
from distgprl.schema import read_csv

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
    "steps_to_80": False,
    "late_variance": False,
    "curve_auc": True,
    "mean_kinematic_retention": True,
}
"""Every score `run_scores` gives, and whether a higher value is an improvement."""

CONVERGENCE_FRACTION = 0.8
"""`curve_measures`' ``steps_to_80``: the share of the run's final curve success to reach."""

LATE_FRACTION = 1.0 / 3.0
"""`curve_measures`' ``late_variance``: the share of the last curve points it is over."""

Strata = Sequence[np.ndarray]
"""One 1-D array of per-run scores per stratum (task)."""

Statistic = Callable[[list[np.ndarray]], np.ndarray]
"""A statistic of resampled strata: arrays (reps, n_k) -> values (reps,)."""


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its bootstrap interval.

    Attributes:
        point: the statistic on the data (nan with no runs).
        low, high: the `CONFIDENCE` percentile interval (nan if a stratum has < 2 runs).
        seeds: runs per stratum (for a PoI, the smaller of the two methods' per stratum).
    """

    point: float
    low: float
    high: float
    seeds: tuple[int, ...]

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


def estimate_rng(seed: int, *names: str) -> np.random.Generator:
    """The generator of one estimate: seeded by ``seed`` and the estimate's names (CRC-32,
    stable across processes, unlike `hash`)."""
    key = zlib.crc32("/".join(names).encode())
    return np.random.default_rng(np.random.SeedSequence([seed, key]))


def mean_of_strata(samples: list[np.ndarray]) -> np.ndarray:
    """rliable's ``aggregate_mean``: the mean over strata of each stratum's mean run."""
    return np.mean([s.mean(axis=1) for s in samples], axis=0)


def iqm(samples: list[np.ndarray]) -> np.ndarray:
    """rliable's ``aggregate_iqm``: the 25 % trimmed mean of all runs of all strata."""
    return stats.trim_mean(np.concatenate(samples, axis=1), proportiontocut=0.25, axis=1)


def _improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """P(X > Y) + P(X = Y) / 2 over all run pairs, per replicate: (reps, n_x), (reps, n_y)
    -> (reps,). Equals rliable's U / (n_x n_y), and 1/2 for identical samples."""
    greater = (x[:, :, None] > y[:, None, :]).mean(axis=(1, 2))
    equal = (x[:, :, None] == y[:, None, :]).mean(axis=(1, 2))
    return greater + 0.5 * equal


def _resample(values: np.ndarray, reps: int, rng: np.random.Generator) -> np.ndarray:
    """``reps`` resamples with replacement of one stratum's runs: (n,) -> (reps, n)."""
    return values[rng.integers(0, len(values), size=(reps, len(values)))]


def _percentiles(replicates: np.ndarray) -> tuple[float, float]:
    tail = 100.0 * (1.0 - CONFIDENCE) / 2.0
    low, high = np.percentile(replicates, [tail, 100.0 - tail])
    return float(low), float(high)


def interval_estimate(
    strata: Strata, statistic: Statistic, rng: np.random.Generator, reps: int = BOOTSTRAP_REPS
) -> Estimate:
    """``statistic`` of ``strata`` (empty strata dropped) with its stratified-bootstrap
    percentile interval (rliable ``get_interval_estimates``, one score array)."""
    arrays = [np.asarray(s, dtype=float) for s in strata if len(s)]
    seeds = tuple(len(a) for a in arrays)
    if not arrays:
        return Estimate(math.nan, math.nan, math.nan, ())
    point = float(statistic([a[None, :] for a in arrays])[0])
    if min(seeds) < 2:
        return Estimate(point, math.nan, math.nan, seeds)
    low, high = _percentiles(statistic([_resample(a, reps, rng) for a in arrays]))
    return Estimate(point, low, high, seeds)


def probability_of_improvement(
    x_strata: Strata,
    y_strata: Strata,
    rng: np.random.Generator,
    higher_is_better: bool = True,
    reps: int = BOOTSTRAP_REPS,
) -> Estimate:
    """The PoI of X over Y (module docstring), averaged over the strata where both have
    runs, with its independent stratified-bootstrap interval (rliable
    ``get_interval_estimates`` on ``[scores_x, scores_y]``)."""
    sign = 1.0 if higher_is_better else -1.0
    pairs = [
        (sign * np.asarray(x, dtype=float), sign * np.asarray(y, dtype=float))
        for x, y in zip(x_strata, y_strata, strict=True)
        if len(x) and len(y)
    ]
    if not pairs:
        return Estimate(math.nan, math.nan, math.nan, ())
    seeds = tuple(min(len(x), len(y)) for x, y in pairs)
    point = float(np.mean([_improvement(x[None, :], y[None, :])[0] for x, y in pairs]))
    if min(seeds) < 2:
        return Estimate(point, math.nan, math.nan, seeds)
    replicates = np.mean(
        [_improvement(_resample(x, reps, rng), _resample(y, reps, rng)) for x, y in pairs],
        axis=0,
    )
    low, high = _percentiles(replicates)
    return Estimate(point, low, high, seeds)


def curve_measures(path: Path) -> dict[str, float]:
    """Learning-curve measures of one run's ``progress.csv`` (points: step, curve success
    on the fixed curve TCs); empty if it has none or fewer than two trained points.

    - ``steps_to_80``: the first step > 0 whose curve success reaches `CONVERGENCE_FRACTION`
      of the last point's (the final curve success); the last step if the final curve
      success is 0 (never converged). Lower is better (faster convergence).
    - ``late_variance``: the variance (ddof = 0) of curve success over the last
      `LATE_FRACTION` of the trained points (at least two). Lower is better (stability).
    - ``curve_auc``: the area under curve success over steps, all points (step 0 too),
      divided by the steps covered: a mean success in [0, 1]. Higher is better (sample
      efficiency).
    """
    if not path.exists():
        return {}
    _, rows = read_csv(path)
    steps = np.array([float(r["step"]) for r in rows])
    success = np.array([float(r["success_rate"]) for r in rows])
    trained = steps > 0
    if trained.sum() < 2:
        return {}
    t_steps, t_success = steps[trained], success[trained]
    final = t_success[-1]
    if final > 0:
        reached = np.flatnonzero(t_success >= CONVERGENCE_FRACTION * final)[0]
        steps_to = float(t_steps[reached])
    else:
        steps_to = float(t_steps[-1])
    late = max(2, math.ceil(len(t_success) * LATE_FRACTION))
    auc = np.trapezoid(success, steps) / (steps[-1] - steps[0])  # mean success over steps
    return {
        "steps_to_80": steps_to,
        "late_variance": float(np.var(t_success[-late:])),
        "curve_auc": float(auc),
    }


def run_scores(folder: Path, summary: Mapping[str, float]) -> dict[str, float]:
    """Every `HIGHER_IS_BETTER` score of one run: its evaluation's rates and mean kinematic
    retention (``summary``) and its `curve_measures` (``folder/progress.csv``; none for an
    untrained reference)."""
    scores = {key: float(summary[key]) for key, _ in RATES if key in summary}
    if "mean_kinematic_retention" in summary:  # velocity cosine to the demonstration
        scores["mean_kinematic_retention"] = float(summary["mean_kinematic_retention"])
    scores.update(curve_measures(folder / "progress.csv"))
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
    rng = estimate_rng(seed, "poi", "+".join(tasks), x, y, key)
    return probability_of_improvement(
        strata(scores, tasks, x, key), strata(scores, tasks, y, key), rng, HIGHER_IS_BETTER[key]
    )


def method_estimate(
    scores: Scores, tasks: Sequence[str], method: str, key: str, statistic: str, seed: int
) -> Estimate:
    """``statistic`` (``mean`` or ``iqm``) of ``method``'s ``key`` over ``tasks``."""
    rng = estimate_rng(seed, statistic, "+".join(tasks), method, key)
    function = {"mean": mean_of_strata, "iqm": iqm}[statistic]
    return interval_estimate(strata(scores, tasks, method, key), function, rng)


CSV_FIELDS = ("task", "method", "versus", "metric", "statistic", "value", "ci_low", "ci_high")
CSV_FIELDS += ("seeds",)
"""Columns of ``aggregates_<preset>.csv``, one row per estimate: ``statistic`` is ``mean``,
``iqm`` or ``poi`` (of ``method`` over ``versus``, on ``metric``: collision's PoI is that of
fewer collisions); ``seeds`` the runs per task stratum, ``;``-separated; the interval is
empty below two runs in a stratum."""


def aggregate_rows(scores: Scores, seed: int) -> list[dict]:
    """Every estimate of the aggregates table (`CSV_FIELDS`): per task group and method
    (table order) the mean and IQM of each rate, then per task group the PoI of
    `PROPOSED` over each of `PARTNERS` that both have runs of."""
    rows = []

    def row(task, method, versus, key, statistic, estimate):
        interval = estimate.has_interval
        rows.append(
            {
                "task": task,
                "method": method,
                "versus": versus,
                "metric": key,
                "statistic": statistic,
                "value": estimate.point,
                "ci_low": estimate.low if interval else "",
                "ci_high": estimate.high if interval else "",
                "seeds": ";".join(str(n) for n in estimate.seeds),
                "estimate": estimate,
            }
        )

    for name, tasks in task_groups(scores):
        for method in TABLE_ORDER:
            if not any((task, method) in scores for task in tasks):
                continue
            for key, _ in RATES:
                for statistic in ("mean", "iqm"):
                    estimate = method_estimate(scores, tasks, method, key, statistic, seed)
                    row(name, method, "", key, statistic, estimate)
    for name, tasks in task_groups(scores):
        for partner in PARTNERS:
            for key, _ in RATES:
                estimate = poi(scores, tasks, PROPOSED, partner, key, seed)
                if estimate.seeds:
                    row(name, PROPOSED, partner, key, "poi", estimate)
    return rows


def _task_label(task: str) -> str:
    return "Both (stratified)" if task == ALL_TASKS else task.upper()


def aggregate_texts(scores: Scores, preset: str, seed: int = BOOTSTRAP_SEED) -> tuple[str, str]:
    """(CSV, Markdown) of the aggregates table (`aggregate_rows`)."""
    rows = aggregate_rows(scores, seed)
    buffer = io.StringIO()
    writer = csv.DictWriter(
        buffer, fieldnames=list(CSV_FIELDS), lineterminator="\n", extrasaction="ignore"
    )
    writer.writeheader()
    writer.writerows(rows)
    cells = {(r["task"], r["method"], r["versus"], r["metric"], r["statistic"]): r for r in rows}
    caption = (
        f"Aggregates over seeds ({preset} preset): mean and IQM with 95 % stratified-bootstrap "
        f"intervals ({BOOTSTRAP_REPS} replicates, percentile; one stratum per task)"
    )
    header = ["Task", "Method", "Seeds"]
    header += [f"{label} {s}" for _, label in RATES for s in ("mean", "IQM")]
    table = []
    for name, _ in task_groups(scores):
        for method in TABLE_ORDER:
            first = cells.get((name, method, "", RATES[0][0], "mean"))
            if first is None:
                continue
            line = [_task_label(name), METHODS[method].label, first["seeds"].replace(";", "+")]
            for key, _ in RATES:
                for statistic in ("mean", "iqm"):
                    line.append(cells[(name, method, "", key, statistic)]["estimate"].text())
            table.append(line)
    markdown = markdown_table(caption, header, table)
    poi_header = ["Task", "Dist-GPRL vs", "Seeds", "PoI success", "PoI fewer collisions"]
    poi_table = []
    for name, _ in task_groups(scores):
        for partner in PARTNERS:
            found = [cells.get((name, PROPOSED, partner, key, "poi")) for key, _ in RATES]
            if all(cell is None for cell in found):
                continue
            seeds = next(c for c in found if c is not None)["seeds"].replace(";", "+")
            texts = ["–" if c is None else c["estimate"].text() for c in found]
            poi_table.append([_task_label(name), METHODS[partner].label, seeds, *texts])
    poi_caption = (
        "Probability of improvement of Dist-GPRL over each ablation and baseline "
        "(P(X > Y) + P(X = Y)/2 over seed pairs, averaged over tasks; 95 % independent "
        "stratified-bootstrap interval; > 0.5 favours Dist-GPRL)"
    )
    if poi_table:
        markdown += "\n" + markdown_table(poi_caption, poi_header, poi_table)
    else:
        markdown += f"\n{poi_caption}: no runs of Dist-GPRL and a partner yet.\n"
    return buffer.getvalue(), markdown
