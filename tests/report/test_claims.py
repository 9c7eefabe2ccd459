"""The claims table: each claim's verdict follows its stated rule on synthetic runs."""

from __future__ import annotations

import numpy as np

from distgprl.experiments.results import write_csv, write_json
from distgprl.experiments.runner import PROGRESS_FIELDS
from distgprl.report.claims import (
    FEW_SEEDS,
    INCONCLUSIVE,
    NO_RUNS,
    POI_CLAIMS,
    REFUTED,
    REPRODUCED,
    evaluate_claims,
)
from distgprl.report.tables import write_tables
from distgprl.schema import read_csv

SEEDS = 5
JITTER = np.array([-0.02, -0.01, 0.0, 0.01, 0.02])


def runs(success, collision, curve=None, retention=0.5):
    """Five seeds' scores around ``success``, ``collision`` and kinematic ``retention`` (and
    curve measures)."""
    out = []
    for jitter in JITTER[:SEEDS]:
        run = {"success_rate": success + jitter, "collision_rate": collision + jitter}
        run["mean_kinematic_retention"] = retention + jitter
        run.update(curve or {})
        out.append(run)
    return out


def scores_of(methods):
    """{(task, method): runs} on both tasks from {method: runs}."""
    return {(task, m): r for task in ("dcp", "dbm") for m, r in methods.items()}


def by_claim(verdicts):
    return {v.claim: v for v in verdicts}


FIELD = {  # every trained method; Dist-GPRL best, GPRL collides most, ProMP-RRL conservative
    "gprl": runs(0.4, 0.5, retention=0.4),
    "promp-rrl": runs(0.2, 0.05, retention=0.3),
    "dist-gprl-global": runs(0.3, 0.3, retention=0.5),
    "gprl-d": runs(0.6, 0.2, retention=0.6),
    "gprl-h": runs(0.6, 0.35, retention=0.6),
    "dist-gprl": runs(0.9, 0.1, retention=0.7),
    "dist-gprl-nocov": runs(0.7, 0.15, retention=0.7),
}  # Dist-GPRL dominates GPRL, Global, GPRL-D/H on (collision, retention); nobody dominates it
BALANCE = "Dist-GPRL balances collisions and kinematic retention"


def test_a_clear_improvement_is_reproduced():
    """Dist-GPRL at 0.9 against Global at 0.3 (5 seeds, both tasks): PoI 1, interval above
    0.5, "reproduced"; so are the ranking claims the field was built to satisfy."""
    verdicts = by_claim(evaluate_claims(scores_of(FIELD), seed=0))
    windowed = verdicts["Windowed adaptation beats global"]
    assert windowed.estimate.point == 1.0 and windowed.estimate.low > 0.5
    assert windowed.estimate.seeds == (SEEDS, SEEDS)
    assert windowed.verdict == REPRODUCED
    assert verdicts["The distance rewards lower collisions"].verdict == REPRODUCED
    assert verdicts["Dist-GPRL has the best success"].verdict == REPRODUCED
    assert verdicts["GPRL collides most"].verdict == REPRODUCED
    assert verdicts["ProMP-RRL is conservative (few collisions, low success)"].verdict == (
        REPRODUCED
    )
    assert verdicts[BALANCE].verdict == REPRODUCED


def test_balance_is_refuted_by_a_dominating_method_and_inconclusive_without_dominance():
    """A method with fewer collisions *and* more kinematic retention (both intervals apart)
    refutes "balances"; when every method overlaps Dist-GPRL on one of the two scores, no
    one dominates anyone and the claim is inconclusive."""
    field = {**FIELD, "promp-rrl": runs(0.2, 0.05, retention=0.9)}
    verdict = by_claim(evaluate_claims(scores_of(field), seed=0))[BALANCE]
    assert verdict.verdict == REFUTED and "dominated by ProMP-RRL" in verdict.detail
    flat = {m: runs(0.5, 0.2, retention=0.5) for m in FIELD}
    flat["dist-gprl"] = runs(0.9, 0.2, retention=0.5)
    assert by_claim(evaluate_claims(scores_of(flat), seed=0))[BALANCE].verdict == INCONCLUSIVE


def test_identical_distributions_are_inconclusive():
    """Dist-GPRL and GPRL-D with the same scores: PoI 1/2, "inconclusive"; two methods with
    overlapping top success intervals leave "best success" inconclusive."""
    field = {**FIELD, "gprl-d": FIELD["dist-gprl"]}
    verdicts = by_claim(evaluate_claims(scores_of(field), seed=0))
    hap = verdicts["The HAP prior raises final success"]
    assert hap.estimate.point == 0.5 and hap.verdict == INCONCLUSIVE
    assert verdicts["Dist-GPRL has the best success"].verdict == INCONCLUSIVE


def test_a_clear_deterioration_is_refuted():
    """A partner clearly better than Dist-GPRL refutes the claim, by PoI and by ranking;
    a baseline colliding less than most refutes "GPRL collides most"."""
    field = {**FIELD, "dist-gprl-global": runs(0.95, 0.02), "gprl": runs(0.4, 0.01)}
    verdicts = by_claim(evaluate_claims(scores_of(field), seed=0))
    assert verdicts["Windowed adaptation beats global"].verdict == REFUTED
    assert verdicts["Dist-GPRL has the best success"].verdict == REFUTED
    assert verdicts["GPRL collides most"].verdict == REFUTED


def test_learning_curve_claims_use_their_measures():
    """Fewer steps to 80 % and lower late variance are improvements; a higher AUC is."""
    fast = {"steps_to_80": 3000.0, "late_variance": 0.001, "curve_auc": 0.8}
    slow = {"steps_to_80": 9000.0, "late_variance": 0.02, "curve_auc": 0.4}
    field = {**FIELD, "dist-gprl": runs(0.9, 0.1, fast)}
    field["gprl-d"] = runs(0.6, 0.2, slow)
    field["dist-gprl-nocov"] = runs(0.7, 0.15, slow)
    verdicts = evaluate_claims(scores_of(field), seed=0)
    curve_claims = {c.claim for c in POI_CLAIMS if c.key != "success_rate"} - {
        "The distance rewards lower collisions"
    }
    assert {v.verdict for v in verdicts if v.claim in curve_claims} == {REPRODUCED}
    swapped = {**field, "dist-gprl": runs(0.9, 0.1, slow), "gprl-d": runs(0.6, 0.2, fast)}
    swapped["dist-gprl-nocov"] = runs(0.7, 0.15, fast)
    verdicts = evaluate_claims(scores_of(swapped), seed=0)
    assert {v.verdict for v in verdicts if v.claim in curve_claims} == {REFUTED}


def test_no_runs_and_single_seeds_are_inconclusive_with_the_reason():
    """Without runs every verdict is "inconclusive (no runs)"; with one seed of a method the
    claims needing it say "fewer than 2 seeds"."""
    assert {v.verdict for v in evaluate_claims({}, seed=0)} == {NO_RUNS}
    field = {**FIELD, "dist-gprl-global": FIELD["dist-gprl-global"][:1]}
    verdicts = by_claim(evaluate_claims(scores_of(field), seed=0))
    assert verdicts["Windowed adaptation beats global"].verdict == FEW_SEEDS
    assert verdicts["Dist-GPRL has the best success"].verdict == FEW_SEEDS


def test_a_claim_without_runs_names_the_methods_it_waits_for():
    """ "(no runs)" says which needed methods have no run on any pooled task."""
    field = {m: r for m, r in FIELD.items() if m not in ("gprl-d", "gprl-h")}
    verdicts = by_claim(evaluate_claims(scores_of(field), seed=0))
    hap = verdicts["The HAP prior raises final success"]
    assert (hap.verdict, hap.detail) == (NO_RUNS, "no runs yet: GPRL-D")
    best = verdicts["Dist-GPRL has the best success"]
    assert best.verdict == NO_RUNS and best.detail.endswith("; no runs yet: GPRL-D, GPRL-H")
    assert verdicts["Windowed adaptation beats global"].verdict != NO_RUNS
    assert "no runs" not in verdicts["Windowed adaptation beats global"].detail
    nothing = by_claim(evaluate_claims({}, seed=0))["GPRL collides most"]
    assert nothing.detail.startswith("no runs yet: GPRL, ProMP-RRL, ")


def test_claims_are_reproducible_for_a_seed():
    """The same runs and seed give the same table; the bootstrap seed changes intervals."""
    field = {**FIELD, "gprl-d": runs(0.85, 0.12)}
    first, again = evaluate_claims(scores_of(field), 0), evaluate_claims(scores_of(field), 0)
    assert first == again
    assert first != evaluate_claims(scores_of(field), 1)


def _write_run(root, task, method, seed, success, curve):
    folder = root / "p" / task / method / f"seed{seed}"
    summary = {"success_rate": success, "collision_rate": 1.0 - success}
    summary.update(min_clearance_p5=0.01, min_signed_clearance_p5=0.01)
    summary.update(completion_rate=success, mean_kinematic_retention=0.9)
    write_json(folder / "summary.json", {"summary": summary})
    rows = []
    for index, point in enumerate(curve):
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(step=1000 * index, success_rate=point, collision_rate=0.0)
        rows.append(row)
    write_csv(folder / "progress.csv", rows, PROGRESS_FIELDS)


def test_write_tables_writes_the_aggregates_and_the_claims_from_a_result_tree(tmp_path):
    """A synthetic tree (Dist-GPRL 0.9, Global 0.3, 5 seeds, both tasks) gives the
    aggregates and claims files, CSVs with sidecars, the windowed claim reproduced."""
    for task in ("dcp", "dbm"):
        for seed in range(SEEDS):
            for method, success in (("dist-gprl", 0.9), ("dist-gprl-global", 0.3)):
                value = success + JITTER[seed]
                _write_run(tmp_path, task, method, seed, value, [0.0, value / 2, value, value])
    written = {p.name for p in write_tables(tmp_path, "p", tmp_path / "out")}
    for stem in ("aggregates_p", "claims_p"):
        assert {f"{stem}.csv", f"{stem}.csv.meta.json", f"{stem}.md"} <= written
    meta, rows = read_csv(tmp_path / "out" / "claims_p.csv")
    assert meta["kind"] == "table"
    windowed = next(r for r in rows if r["claim"] == "Windowed adaptation beats global")
    assert windowed["verdict"] == REPRODUCED and float(windowed["ci_low"]) > 0.5
    assert windowed["seeds"] == "5;5"
    markdown = (tmp_path / "out" / "claims_p.md").read_text()
    assert markdown.count("| inconclusive (no runs) |") == 9  # every other claim
    _, aggregates = read_csv(tmp_path / "out" / "aggregates_p.csv")
    pooled = [r for r in aggregates if r["task"] == "all" and r["statistic"] == "poi"]
    assert {r["versus"] for r in pooled} == {"dist-gprl-global"}


def test_a_pooled_poi_names_each_tasks_poi_and_says_when_the_tasks_disagree():
    """Dist-GPRL's curve area far above NoCov's on DCP and far below on DBM: the pooled PoI
    averages 1 and 0 (0.50 with no width), which alone reads as "no effect"; the detail
    gives each task's PoI and says the tasks disagree. The verdict stays the pooled rule's;
    where the tasks agree the detail says nothing more."""
    from distgprl.report.claims import TASKS_DISAGREE

    field = dict(FIELD)
    field["dist-gprl"] = runs(0.9, 0.1, curve={"curve_auc": 0.5})
    field["dist-gprl-nocov"] = runs(0.7, 0.15, curve={"curve_auc": 0.9})
    scores = scores_of(field)
    scores[("dcp", "dist-gprl-nocov")] = runs(0.7, 0.15, curve={"curve_auc": 0.1})
    verdicts = by_claim(evaluate_claims(scores, seed=0))
    efficiency = verdicts["The covariance transform improves sample efficiency"]
    assert efficiency.estimate.point == 0.5 and efficiency.verdict == INCONCLUSIVE
    assert efficiency.detail == (
        f"per task: DCP 1.00 [1.00, 1.00]; DBM 0.00 [0.00, 0.00] ({TASKS_DISAGREE})"
    )
    windowed = verdicts["Windowed adaptation beats global"]
    assert windowed.verdict == REPRODUCED
    assert windowed.detail == "per task: DCP 1.00 [1.00, 1.00]; DBM 1.00 [1.00, 1.00]"
    one_task = {key: value for key, value in scores.items() if key[0] == "dcp"}
    single = by_claim(evaluate_claims(one_task, seed=0))["Windowed adaptation beats global"]
    assert single.detail == ""
