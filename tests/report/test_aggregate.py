"""Stratified-bootstrap aggregates: rliable's statistics, reproducible intervals, PoI."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from distgprl.experiments.results import write_csv
from distgprl.experiments.runner import PROGRESS_FIELDS
from distgprl.report.aggregate import (
    aggregate_rows,
    aggregate_texts,
    curve_measures,
    estimate_rng,
    interval_estimate,
    iqm,
    mean_of_strata,
    probability_of_improvement,
)

CLEAR = [0.88, 0.9, 0.92, 0.91, 0.89]
WEAK = [0.28, 0.3, 0.32, 0.31, 0.29]


def test_point_statistics_are_rlibles():
    """The mean is the mean of per-stratum means; the IQM the 25 % trimmed mean of all runs
    pooled (scipy's ``trim_mean``, rliable's ``aggregate_iqm``)."""
    a, b = np.array([0.1, 0.2, 0.9, 1.0]), np.array([0.5, 0.5])
    assert mean_of_strata([a[None], b[None]])[0] == pytest.approx((0.55 + 0.5) / 2)
    pooled = np.concatenate([a, b])
    assert iqm([a[None], b[None]])[0] == pytest.approx(stats.trim_mean(pooled, 0.25))


def test_poi_point_is_the_mann_whitney_u_over_pairs():
    """PoI(X > Y) = U / (n_x n_y) with ties counted half; 1/2 for identical samples; for a
    lower-is-better score the PoI of X is that of -X over -Y."""
    x, y = np.array([0.1, 0.4, 0.4, 0.8]), np.array([0.4, 0.2, 0.9])
    rng = np.random.default_rng(0)
    u = stats.mannwhitneyu(x, y, alternative="greater").statistic
    assert probability_of_improvement([x], [y], rng).point == pytest.approx(u / 12)
    assert probability_of_improvement([x], [x], rng).point == 0.5
    lower = probability_of_improvement([x], [y], rng, higher_is_better=False).point
    assert lower == pytest.approx(1 - u / 12)


def test_clear_improvement_has_a_poi_interval_above_one_half():
    """5 seeds at 0.9 against 5 at 0.3: PoI 1 with its whole interval above 0.5; the same
    data for collisions (lower better) gives PoI 0 with its interval below 0.5."""
    estimate = probability_of_improvement([CLEAR], [WEAK], np.random.default_rng(0))
    assert estimate.point == 1.0 and estimate.low > 0.5 and estimate.seeds == (5,)
    fewer = probability_of_improvement(
        [CLEAR], [WEAK], np.random.default_rng(0), higher_is_better=False
    )
    assert fewer.point == 0.0 and fewer.high < 0.5


def test_identical_distributions_give_an_interval_around_one_half():
    """Two methods with the same five scores: PoI 1/2 and an interval containing 1/2."""
    estimate = probability_of_improvement([WEAK], [list(WEAK)], np.random.default_rng(3))
    assert estimate.point == 0.5 and estimate.low < 0.5 < estimate.high


def test_bootstrap_is_reproducible_for_a_seed_and_varies_with_it():
    """The same seed and estimate name give the same interval; another seed another one."""
    values = [np.array([0.2, 0.5, 0.6, 0.9, 0.4])]

    def estimate(seed):
        return interval_estimate(values, iqm, estimate_rng(seed, "iqm", "dcp", "gprl"))

    assert estimate(0) == estimate(0)
    assert estimate(0) != estimate(1)
    first = estimate(0)
    assert first.low <= first.point <= first.high


def test_strata_are_resampled_separately():
    """A stratum with constant runs contributes no bootstrap variation: the interval of the
    mean over a constant stratum and a varying one is half the varying one's alone."""
    varying, constant = np.array([0.0, 0.2, 0.6, 1.0]), np.full(4, 0.5)
    alone = interval_estimate([varying], mean_of_strata, np.random.default_rng(5))
    both = interval_estimate([varying, constant], mean_of_strata, np.random.default_rng(5))
    assert both.high - both.low == pytest.approx((alone.high - alone.low) / 2)


def test_one_seed_has_no_interval_and_says_so():
    """Below two runs in a stratum the estimate has a point but no interval, in the CSV
    (empty) and in the Markdown ("no interval")."""
    single = interval_estimate([[0.7]], iqm, np.random.default_rng(0))
    assert single.point == 0.7 and math.isnan(single.low) and not single.has_interval
    assert single.text() == "0.70 (1 seed: no interval)"
    scores = {("dcp", "demo"): [{"success_rate": 0.7, "collision_rate": 0.1}]}
    rows = aggregate_rows(scores, 0)
    assert {r["ci_low"] for r in rows} == {""}
    csv_text, markdown = aggregate_texts(scores, "p")
    assert "no interval" in markdown and "no runs of Dist-GPRL" in markdown
    assert csv_text.splitlines()[0].startswith("task,method,versus,metric,statistic")


def test_poi_rows_pair_the_proposed_method_with_each_partner_with_runs():
    """PoI rows exist for the partners with runs only, per task and pooled over both."""
    scores = {}
    for task in ("dcp", "dbm"):
        scores[(task, "dist-gprl")] = [{"success_rate": s, "collision_rate": 1 - s} for s in CLEAR]
        scores[(task, "gprl")] = [{"success_rate": s, "collision_rate": 1 - s} for s in WEAK]
    rows = [r for r in aggregate_rows(scores, 0) if r["statistic"] == "poi"]
    assert {(r["task"], r["versus"]) for r in rows} == {(t, "gprl") for t in ("dcp", "dbm", "all")}
    pooled = next(r for r in rows if r["task"] == "all" and r["metric"] == "success_rate")
    assert pooled["seeds"] == "5;5" and pooled["ci_low"] > 0.5


def _curve(path, successes, step=1000):
    rows = []
    for index, success in enumerate(successes):
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(step=step * index, success_rate=success, collision_rate=0.0)
        rows.append(row)
    write_csv(path, rows, PROGRESS_FIELDS)


def test_curve_measures_follow_their_stated_definitions(tmp_path):
    """steps_to_80: first trained step at >= 80 % of the final point; late variance over the
    last third of the trained points; AUC the trapezoid area over the steps covered."""
    path = tmp_path / "progress.csv"
    assert curve_measures(path) == {}
    curve = [0.0, 0.2, 0.5, 0.8, 0.6, 1.0, 0.9]  # steps 0..6000; final 0.9 -> threshold 0.72
    _curve(path, curve)
    measures = curve_measures(path)
    assert measures["steps_to_80"] == 3000.0
    assert measures["late_variance"] == pytest.approx(np.var([1.0, 0.9]))  # ceil(6/3) = 2
    expected_auc = np.trapezoid(curve, np.arange(7) * 1000.0) / 6000.0
    assert measures["curve_auc"] == pytest.approx(expected_auc)
    _curve(path, [0.5, 0.0, 0.0, 0.0])  # never succeeds: converges at the last step
    assert curve_measures(path)["steps_to_80"] == 3000.0
