"""Stratified-bootstrap aggregates: rliable's statistics, reproducible intervals, PoI."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from numpy.polynomial import Polynomial
from scipy import stats

from distgprl.report import aggregate
from distgprl.report.aggregate import (
    aggregate_rows,
    aggregate_texts,
    curve_measures,
    estimate_rng,
    improvement,
    interval_estimate,
    iqm,
    mean_of_strata,
    method_estimate,
    newcombe_interval,
    poi,
    probability_of_improvement,
)

CLEAR = [0.88, 0.9, 0.92, 0.91, 0.89]
WEAK = [0.28, 0.3, 0.32, 0.31, 0.29]


def test_point_statistics_are_rlibles():
    """The mean is the mean of per-stratum means; the IQM the 25 % trimmed mean of all runs
    pooled (scipy's ``trim_mean``, rliable's ``aggregate_iqm``)."""
    a, b = np.array([0.1, 0.2, 0.9, 1.0]), np.array([0.5, 0.5])
    assert mean_of_strata(a[None], b[None])[0] == pytest.approx((0.55 + 0.5) / 2)
    pooled = np.concatenate([a, b])
    assert iqm(a[None], b[None])[0] == pytest.approx(stats.trim_mean(pooled, 0.25))


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


TAIL = 100.0 * (1.0 - 0.95) / 2.0
"""The lower tail of a 95 % percentile interval, in percent, as the interval is computed."""


def _pair_counts(x, y):
    """P(X > Y) + P(X = Y) / 2 by counting the run pairs, per row: (reps, n_x), (reps, n_y)."""
    greater = (x[:, :, None] > y[:, None, :]).sum(axis=(1, 2))
    equal = (x[:, :, None] == y[:, None, :]).sum(axis=(1, 2))
    return (greater + equal / 2) / (x.shape[1] * y.shape[1])


def test_improvement_is_the_pair_count_exactly():
    """scipy's U over n_x n_y is the share of run pairs favouring X, ties half, to the bit."""
    rng = np.random.default_rng(1)
    x = rng.integers(0, 5, size=(200, 4)) / 4
    y = rng.integers(0, 5, size=(200, 3)) / 4
    assert np.array_equal(improvement(x, y), _pair_counts(x, y))


def test_the_stratified_bootstrap_resamples_each_stratum_on_its_own():
    """scipy's bootstrap with one sample per stratum is rliable's stratified bootstrap: the
    interval is the percentile interval of replicates drawn stratum by stratum from the
    same generator (n_k runs of stratum k with replacement), to the bit."""
    strata = [np.array([0.1, 0.5, 0.7, 0.2]), np.array([0.9, 0.3, 0.4])]
    estimate = interval_estimate(strata, mean_of_strata, np.random.default_rng(4), reps=500)
    rng = np.random.default_rng(4)
    resampled = [s[rng.integers(0, len(s), size=(500, len(s)))] for s in strata]
    replicates = np.mean([r.mean(axis=1) for r in resampled], axis=0)
    assert (estimate.low, estimate.high) == tuple(np.percentile(replicates, [TAIL, 100 - TAIL]))


def test_the_poi_bootstrap_resamples_both_methods_in_every_stratum_independently():
    """The PoI's percentile interval: per replicate, X's and Y's runs of each stratum drawn
    in turn from one generator, the pair shares averaged over strata; the interval widened
    to the mean of the strata's Newcombe bounds."""
    x = [np.array([0.2, 0.6, 0.6, 0.9]), np.array([0.5, 0.1, 0.7])]
    y = [np.array([0.3, 0.6, 0.1]), np.array([0.2, 0.4, 0.4, 0.8, 0.3])]
    estimate = probability_of_improvement(x, y, np.random.default_rng(2), reps=400)
    rng = np.random.default_rng(2)
    shares = []
    for a, b in zip(x, y, strict=True):
        resampled_a = a[rng.integers(0, len(a), size=(400, len(a)))]
        resampled_b = b[rng.integers(0, len(b), size=(400, len(b)))]
        shares.append(_pair_counts(resampled_a, resampled_b))
    low, high = np.percentile(np.mean(shares, axis=0), [TAIL, 100 - TAIL])
    points = [_pair_counts(a[None], b[None])[0] for a, b in zip(x, y, strict=True)]
    bounds = [newcombe_interval(p, len(a), len(b)) for p, a, b in zip(points, x, y, strict=True)]
    assert estimate.point == np.mean(points)
    assert estimate.low == min(low, np.mean([b[0] for b in bounds]))
    assert estimate.high == max(high, np.mean([b[1] for b in bounds]))


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


def test_an_estimate_of_scores_is_its_own_generators_and_bootstrapped_once(monkeypatch):
    """`method_estimate` and `poi` give what `interval_estimate` and
    `probability_of_improvement` give with the estimate's own generator; asked again for the
    same scores (in another mapping) they bootstrap nothing, and changed scores anew."""
    runs = {"dist-gprl": CLEAR, "gprl": WEAK}
    scores = {("dcp", m): [{"success_rate": s} for s in values] for m, values in runs.items()}
    seed = 12345  # no other test asks for this seed: nothing of it is cached yet
    iqm_rng = estimate_rng(seed, "iqm", "dcp", "dist-gprl", "success_rate")
    direct = interval_estimate([CLEAR], iqm, iqm_rng)
    poi_rng = estimate_rng(seed, "poi", "dcp", "dist-gprl", "gprl", "success_rate")
    direct_poi = probability_of_improvement([CLEAR], [WEAK], poi_rng)
    assert method_estimate(scores, ["dcp"], "dist-gprl", "success_rate", "iqm", seed) == direct
    assert poi(scores, ["dcp"], "dist-gprl", "gprl", "success_rate", seed) == direct_poi
    calls = []
    original = aggregate.bootstrap_interval

    def counting(*args, **kwargs):
        calls.append(args)
        return original(*args, **kwargs)

    monkeypatch.setattr(aggregate, "bootstrap_interval", counting)
    again = {key: [dict(run) for run in values] for key, values in scores.items()}
    assert method_estimate(again, ["dcp"], "dist-gprl", "success_rate", "iqm", seed) == direct
    assert poi(again, ["dcp"], "dist-gprl", "gprl", "success_rate", seed) == direct_poi
    assert calls == []
    again[("dcp", "gprl")] = [{"success_rate": s + 0.01} for s in WEAK]
    poi(again, ["dcp"], "dist-gprl", "gprl", "success_rate", seed)
    assert len(calls) == 1


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
    """PoI rows exist for the partners with runs only, per task and pooled over both; the
    collision PoI is that of fewer collisions."""
    scores = {}
    for task in ("dcp", "dbm"):
        scores[(task, "dist-gprl")] = [{"success_rate": s, "collision_rate": 1 - s} for s in CLEAR]
        scores[(task, "gprl")] = [{"success_rate": s, "collision_rate": 1 - s} for s in WEAK]
    rows = [r for r in aggregate_rows(scores, 0) if r["statistic"] == "poi"]
    assert {(r["task"], r["versus"]) for r in rows} == {(t, "gprl") for t in ("dcp", "dbm", "all")}
    pooled = next(r for r in rows if r["task"] == "all" and r["metric"] == "success_rate")
    assert pooled["seeds"] == "5;5" and pooled["ci_low"] > 0.5
    fewer = next(r for r in rows if r["task"] == "all" and r["metric"] == "collision_rate")
    assert fewer["value"] == 1.0  # every Dist-GPRL run collides less: collision is lower-better


def _curve(successes, step=1000):
    """One run's curve points as `distgprl.report.frame.curves_of` gives them."""
    steps = [step * index for index in range(len(successes))]
    return pd.DataFrame({"step": steps, "success_rate": successes, "collision_rate": 0.0})


def test_curve_measures_follow_their_stated_definitions():
    """Against the start s0 (step 0): learning_auc the trapezoid mean of (curve - s0);
    steps_to_gain the first step from which two points hold s0 + 0.2; learned_drop the mean
    drop per period from there."""
    assert curve_measures(_curve([])) == {}
    curve = [0.1, 0.2, 0.35, 0.5, 0.4, 0.7, 0.6]  # steps 0..6000; 0.3 first at 2000 then 3000
    measures = curve_measures(_curve(curve))
    expected_auc = np.trapezoid(np.array(curve) - 0.1, np.arange(7) * 1000.0) / 6000.0
    assert measures["learning_auc"] == pytest.approx(expected_auc)
    assert measures["steps_to_gain"] == 2000.0
    assert measures["learned_drop"] == pytest.approx((0.1 + 0.1) / 4)  # 4 periods from 2000


def test_a_flat_curve_neither_converges_nor_counts_as_stable():
    """A curve that stays at its start (or wanders within the margin) has no area above it,
    is censored one period past its last step and is the least stable (+inf); a curve that
    falls below its start has a negative area; a single point above the margin is noise."""
    flat = curve_measures(_curve([0.44, 0.44, 0.44, 0.44, 0.44]))
    assert flat == {"learning_auc": 0.0, "steps_to_gain": 5000.0, "learned_drop": math.inf}
    wander = curve_measures(_curve([0.4, 0.5, 0.3, 0.55, 0.45, 0.5]))
    assert wander["steps_to_gain"] == 6000.0 and wander["learned_drop"] == math.inf
    assert curve_measures(_curve([0.3, 0.0, 0.0, 0.0]))["learning_auc"] < 0
    one_point = curve_measures(_curve([0.1, 0.1, 0.5, 0.1, 0.1]))  # one above 0.3: not learned
    assert one_point["learned_drop"] == math.inf


def test_a_steady_riser_is_stable_and_earlier_learning_scores_more():
    """A curve rising without a drop has learned_drop 0; the same rise one period earlier has
    the larger area and the earlier steps_to_gain."""
    late = curve_measures(_curve([0.1, 0.2, 0.4, 0.6, 0.8, 0.8]))
    assert late["learned_drop"] == 0.0
    early = curve_measures(_curve([0.1, 0.4, 0.6, 0.8, 0.8, 0.8]))
    assert early["learning_auc"] > late["learning_auc"]
    assert early["steps_to_gain"] < late["steps_to_gain"]


def test_newcombe_interval_is_wilson_like():
    """The score interval of a PoI: never degenerate at 0 or 1 for finite samples
    (5 vs 5 at 1: lower bound about 0.64, above 1/2 like the exact Mann-Whitney test at
    p = 0.008; 2 vs 2 at 1: not above 1/2, like the exact p = 0.33), symmetric under
    θ -> 1 - θ, containing the estimate, narrowing as runs grow."""
    low, high = newcombe_interval(1.0, 5, 5)
    assert high == 1.0 and 0.6 < low < 0.7
    assert stats.mannwhitneyu([1, 2, 3, 4, 5], [-1, -2, -3, -4, -5]).pvalue < 0.01
    assert newcombe_interval(1.0, 2, 2)[0] < 0.5
    mirrored = newcombe_interval(0.0, 5, 5)
    assert mirrored == pytest.approx((1.0 - high, 1.0 - low))
    for theta in (0.1, 0.5, 0.8):
        low, high = newcombe_interval(theta, 5, 5)
        assert low < theta < high
    assert np.diff(newcombe_interval(0.8, 20, 20)) < np.diff(newcombe_interval(0.8, 5, 5))


def _newcombe_by_polynomial(theta, n_x, n_y):
    """Newcombe's method-5 interval found another way: (θ̂ − θ)² = z² V(θ) times
    (2 − θ)(1 + θ) n_x n_y is a quartic in θ; the interval runs between its real roots in
    [0, 1] around θ̂ (0 or 1 where the inequality already holds there)."""
    z = stats.norm.ppf(0.975)
    n = (n_x + n_y) / 2
    t = Polynomial([0.0, 1.0])
    shape = (2 - t) * (1 + t) + (n - 1) * (1 - t) * (1 + t) + (n - 1) * t * (2 - t)
    quartic = n_x * n_y * (theta - t) ** 2 * (2 - t) * (1 + t) - z**2 * t * (1 - t) * shape
    roots = [r.real for r in quartic.roots() if abs(r.imag) < 1e-12 and -1e-12 <= r.real <= 1]
    below = [r for r in roots if r < theta - 1e-9]  # θ̂ = 0 or 1 is itself a root: V(θ̂) = 0
    above = [r for r in roots if r > theta + 1e-9]
    low = 0.0 if quartic(0.0) <= 1e-12 else max(below)
    high = 1.0 if quartic(1.0) <= 1e-12 else min(above)
    return low, high


@pytest.mark.parametrize(
    ("theta", "n_x", "n_y"), [(1.0, 5, 5), (0.0, 5, 5), (0.8, 5, 5), (0.5, 3, 7), (0.92, 20, 20)]
)
def test_newcombe_interval_is_the_roots_of_its_quartic(theta, n_x, n_y):
    """The bisection interval and the polynomial roots of the same inequality agree."""
    assert newcombe_interval(theta, n_x, n_y) == pytest.approx(
        _newcombe_by_polynomial(theta, n_x, n_y), abs=1e-9
    )


def test_a_poi_interval_is_never_narrower_than_its_score_bound():
    """All 25 run pairs agreeing: the bootstrap percentile interval alone is [1, 1]; the
    PoI's interval is the Newcombe bound instead. Two strata with opposite decisive effects
    pool to 1/2 with an interval as wide as the strata's own, not [0.5, 0.5]."""
    rng = np.random.default_rng(0)
    x, y = np.array(CLEAR), np.array(WEAK)
    one = probability_of_improvement([x], [y], rng)
    assert one.point == 1.0 and one.pairs == (25,)
    assert (one.low, one.high) == pytest.approx(newcombe_interval(1.0, 5, 5))
    assert one.pairs_text() == "25/25 run pairs"
    both = probability_of_improvement([x, y], [y, x], np.random.default_rng(0))
    assert both.point == 0.5
    own_width = 1.0 - newcombe_interval(1.0, 5, 5)[0]
    assert both.low < 0.5 < both.high
    assert both.high - both.low == pytest.approx(own_width)


def test_a_score_without_a_known_direction_is_refused_not_guessed():
    scores = {("dcp", "dist-gprl"): [{"success_rate": 1.0}], ("dcp", "gprl"): [{}]}
    with pytest.raises(KeyError, match="no_such_score"):
        poi(scores, ["dcp"], "dist-gprl", "gprl", "no_such_score", 0)
