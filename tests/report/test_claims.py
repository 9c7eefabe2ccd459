"""The claims table: each claim's verdict follows its stated rule on synthetic runs."""

from __future__ import annotations

import numpy as np

from distgprl.report.aggregate import ALL_TASKS
from distgprl.report.claims import (
    BALANCE,
    FEW_SEEDS,
    INCONCLUSIVE,
    NO_RUNS,
    REFUTED,
    REPRODUCED,
    TASKS_DISAGREE,
    combine,
    evaluate_claims,
)
from distgprl.report.tables import write_tables
from distgprl.schema import PROGRESS_FIELDS, read_csv, write_csv, write_json

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


def by_claim(frame):
    """{claim: its `ALL_TASKS` row}: the overall verdict and detail, the pooled estimate."""
    return {row.claim: row for row in frame[frame.task == ALL_TASKS].itertuples()}


def per(frame, claim):
    """The claim's row on each task, in the frame's order."""
    return list(frame[(frame.claim == claim) & (frame.task != ALL_TASKS)].itertuples())


FIELD = {  # every trained method; Dist-GPRL best, GPRL collides most, ProMP-RRL conservative
    "gprl": runs(0.4, 0.5, retention=0.4),
    "promp-rrl": runs(0.2, 0.05, retention=0.3),
    "dist-gprl-global": runs(0.3, 0.3, retention=0.5),
    "gprl-d": runs(0.6, 0.2, retention=0.6),
    "gprl-h": runs(0.6, 0.35, retention=0.6),
    "dist-gprl": runs(0.9, 0.1, retention=0.7),
    "dist-gprl-nocov": runs(0.7, 0.15, retention=0.7),
}  # Dist-GPRL dominates every other method on (success, collision, retention)


def test_a_clear_improvement_is_reproduced():
    """Dist-GPRL at 0.9 against Global at 0.3 (5 seeds, both tasks): PoI 1, interval above
    0.5, "reproduced"; so are the ranking claims the field was built to satisfy."""
    frame = evaluate_claims(scores_of(FIELD), seed=0)
    verdicts = by_claim(frame)
    windowed = verdicts["Windowed adaptation beats global"]
    assert [t.task for t in per(frame, windowed.claim)] == ["dcp", "dbm"]
    for task in per(frame, windowed.claim):
        assert task.estimate.point == 1.0 and task.estimate.low > 0.5
        assert task.estimate.seeds == (SEEDS,) and task.verdict == REPRODUCED
        assert task.detail == "25/25 run pairs favour Dist-GPRL"
    assert windowed.estimate.seeds == (SEEDS, SEEDS)
    assert windowed.verdict == REPRODUCED
    assert verdicts["The distance rewards lower collisions"].verdict == REPRODUCED
    assert verdicts["Dist-GPRL has the best success"].verdict == REPRODUCED
    assert verdicts["GPRL collides most"].verdict == REPRODUCED
    assert verdicts["ProMP-RRL is conservative (few collisions, low success)"].verdict == (
        REPRODUCED
    )
    assert verdicts[BALANCE].verdict == REPRODUCED


def test_a_method_better_on_all_three_axes_dominates_and_refutes_balance():
    """A method with more success, fewer collisions and more kinematic retention (intervals
    apart) dominates Dist-GPRL: "balances" is refuted and Dist-GPRL leaves the
    non-dominated set."""
    field = {**FIELD, "promp-rrl": runs(0.95, 0.02, retention=0.9)}
    frame = evaluate_claims(scores_of(field), seed=0)
    assert by_claim(frame)[BALANCE].verdict == REFUTED
    for task in per(frame, BALANCE):
        assert "dominated by ProMP-RRL" in task.detail
        assert task.detail.endswith("non-dominated: ProMP-RRL")


def test_balance_counts_success():
    """Equal collisions and retention but decisively more success is dominance: a rival
    better on success alone (ties elsewhere) refutes the balance, which a rule over
    collisions and retention only could not see."""
    field = {**FIELD, "gprl-d": runs(0.99, 0.1, retention=0.7)}
    assert by_claim(evaluate_claims(scores_of(field), seed=0))[BALANCE].verdict == REFUTED


def test_balance_is_inconclusive_when_nobody_is_apart():
    """Every method overlapping Dist-GPRL on every axis: no one dominates anyone, and a
    non-dominated Dist-GPRL that dominates no one does not "balance" anything."""
    flat = {m: runs(0.5, 0.2, retention=0.5) for m in FIELD}
    frame = evaluate_claims(scores_of(flat), seed=0)
    assert by_claim(frame)[BALANCE].verdict == INCONCLUSIVE
    assert "dominates none; dominated by none" in per(frame, BALANCE)[0].detail


def test_identical_distributions_are_inconclusive():
    """Dist-GPRL and GPRL-D with the same scores: PoI 1/2, "inconclusive"; two methods with
    overlapping top success intervals leave "best success" inconclusive."""
    field = {**FIELD, "gprl-d": FIELD["dist-gprl"]}
    frame = evaluate_claims(scores_of(field), seed=0)
    verdicts = by_claim(frame)
    hap = verdicts["The HAP prior raises final success"]
    dcp = per(frame, hap.claim)[0].estimate
    assert dcp.point == 0.5 and hap.verdict == INCONCLUSIVE
    assert dcp.low < 0.5 < dcp.high
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
    """Fewer steps to the gain and a smaller drop once learned are improvements; a larger
    learning area is; never learning (drop +inf) is the worst stability."""
    fast = {"steps_to_gain": 3000.0, "learned_drop": 0.001, "learning_auc": 0.4}
    slow = {"steps_to_gain": 9000.0, "learned_drop": float("inf"), "learning_auc": 0.0}
    field = {**FIELD, "dist-gprl": runs(0.9, 0.1, fast)}
    field["gprl-d"] = runs(0.6, 0.2, slow)
    field["dist-gprl-nocov"] = runs(0.7, 0.15, slow)
    verdicts = by_claim(evaluate_claims(scores_of(field), seed=0)).values()
    curve_claims = {
        "The HAP prior speeds convergence",
        "The covariance transform improves stability",
        "The covariance transform improves sample efficiency",
    }
    assert {v.verdict for v in verdicts if v.claim in curve_claims} == {REPRODUCED}
    swapped = {**field, "dist-gprl": runs(0.9, 0.1, slow), "gprl-d": runs(0.6, 0.2, fast)}
    swapped["dist-gprl-nocov"] = runs(0.7, 0.15, fast)
    verdicts = by_claim(evaluate_claims(scores_of(swapped), seed=0)).values()
    assert {v.verdict for v in verdicts if v.claim in curve_claims} == {REFUTED}


def test_no_runs_and_single_seeds_are_inconclusive_with_the_reason():
    """Without runs every verdict is "inconclusive (no runs)"; with one seed of a method the
    claims needing it say "fewer than 2 seeds"."""
    assert set(evaluate_claims({}, seed=0).verdict) == {NO_RUNS}
    field = {**FIELD, "dist-gprl-global": FIELD["dist-gprl-global"][:1]}
    verdicts = by_claim(evaluate_claims(scores_of(field), seed=0))
    assert verdicts["Windowed adaptation beats global"].verdict == FEW_SEEDS
    assert verdicts["Dist-GPRL has the best success"].verdict == FEW_SEEDS


def test_a_claim_without_runs_names_the_methods_it_waits_for():
    """ "(no runs)" says which needed methods have no run, and on which task when they
    have runs on another."""
    field = {m: r for m, r in FIELD.items() if m not in ("gprl-d", "gprl-h")}
    verdicts = by_claim(evaluate_claims(scores_of(field), seed=0))
    hap = verdicts["The HAP prior raises final success"]
    assert (hap.verdict, hap.detail) == (NO_RUNS, "no runs yet: GPRL-D")
    best = verdicts["Dist-GPRL has the best success"]
    assert (best.verdict, best.detail) == (NO_RUNS, "no runs yet: GPRL-D, GPRL-H")
    partial = {**scores_of(field), ("dbm", "gprl-d"): FIELD["gprl-d"]}
    hap = by_claim(evaluate_claims(partial, seed=0))["The HAP prior raises final success"]
    assert (hap.verdict, hap.detail) == (NO_RUNS, "no runs yet: GPRL-D (DCP)")
    assert verdicts["Windowed adaptation beats global"].verdict != NO_RUNS
    assert "no runs" not in verdicts["Windowed adaptation beats global"].detail
    nothing = by_claim(evaluate_claims({}, seed=0))["GPRL collides most"]
    assert nothing.detail.startswith("no runs yet: GPRL, ProMP-RRL, ")


def test_claims_are_reproducible_for_a_seed():
    """The same runs and seed give the same table; the bootstrap seed changes intervals."""
    field = {**FIELD, "gprl-d": runs(0.85, 0.12)}
    first, again = evaluate_claims(scores_of(field), 0), evaluate_claims(scores_of(field), 0)
    assert first.equals(again)
    assert not first.equals(evaluate_claims(scores_of(field), 1))


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
    windowed = [r for r in rows if r["claim"] == "Windowed adaptation beats global"]
    assert [r["task"] for r in windowed] == ["dcp", "dbm", "all"]
    assert {r["verdict"] for r in windowed} == {REPRODUCED}
    assert all(float(r["ci_low"]) > 0.5 for r in windowed)
    assert windowed[-1]["seeds"] == "5;5" and windowed[-1]["pairs"] == "25;25"
    markdown = (tmp_path / "out" / "claims_p.md").read_text()
    assert markdown.count("| **inconclusive (no runs)** |") == 9  # every other claim
    _, aggregates = read_csv(tmp_path / "out" / "aggregates_p.csv")
    pooled = [r for r in aggregates if r["task"] == "all" and r["statistic"] == "poi"]
    assert {r["versus"] for r in pooled} == {"dist-gprl-global"}


def test_opposite_decisive_effects_read_tasks_disagree_with_a_real_interval():
    """Dist-GPRL's learning area far above NoCov's on DCP and far below on DBM: each task
    decides its own way (25/25 and 0/25 run pairs), the overall verdict is "the tasks
    disagree", and the pooled PoI beside them is 0.5 with an interval as wide as a task's,
    not [0.5, 0.5]. No interval has zero width although every seed pair agrees."""
    field = dict(FIELD)
    field["dist-gprl"] = runs(0.9, 0.1, curve={"learning_auc": 0.5})
    field["dist-gprl-nocov"] = runs(0.7, 0.15, curve={"learning_auc": 0.9})
    scores = scores_of(field)
    scores[("dcp", "dist-gprl-nocov")] = runs(0.7, 0.15, curve={"learning_auc": 0.1})
    frame = evaluate_claims(scores, seed=0)
    efficiency = by_claim(frame)["The covariance transform improves sample efficiency"]
    assert efficiency.verdict == TASKS_DISAGREE
    dcp, dbm = per(frame, efficiency.claim)
    assert (dcp.task, dcp.verdict, dbm.task, dbm.verdict) == ("dcp", REPRODUCED, "dbm", REFUTED)
    assert dcp.detail.startswith("25/25 run pairs")
    assert dbm.detail.startswith("0/25 run pairs")
    pooled = efficiency.estimate
    assert pooled.point == 0.5 and pooled.high - pooled.low > 0.3
    for task in (dcp, dbm, efficiency):
        assert task.estimate.high - task.estimate.low > 0.3
    one_task = {key: value for key, value in scores.items() if key[0] == "dcp"}
    single = by_claim(evaluate_claims(one_task, seed=0))["Windowed adaptation beats global"]
    assert not single.estimate.seeds and single.verdict == REPRODUCED  # nothing pooled


def test_the_overall_rule_combines_the_tasks():
    """Reproduced only where every task reproduces; "reproduced on T" where the others are
    inconclusive; the same for refuted; one each way disagrees; missing runs win."""
    assert combine([("dcp", REPRODUCED), ("dbm", REPRODUCED)]) == REPRODUCED
    assert combine([("dcp", REPRODUCED), ("dbm", INCONCLUSIVE)]) == ("reproduced on DCP")
    assert combine([("dcp", INCONCLUSIVE), ("dbm", REFUTED)]) == "refuted on DBM"
    assert combine([("dcp", REFUTED), ("dbm", REFUTED)]) == REFUTED
    assert combine([("dcp", REPRODUCED), ("dbm", REFUTED)]) == TASKS_DISAGREE
    assert combine([("dcp", INCONCLUSIVE), ("dbm", INCONCLUSIVE)]) == INCONCLUSIVE
    assert combine([("dcp", REPRODUCED), ("dbm", FEW_SEEDS)]) == FEW_SEEDS
    assert combine([("dcp", NO_RUNS), ("dbm", FEW_SEEDS)]) == NO_RUNS


def test_flat_curves_cannot_reproduce_the_curve_claims(tmp_path):
    """End to end from progress files: Dist-GPRL's curves flat at the demo's level, NoCov's
    falling to 0 and then learning to 0.8. A flat curve has learned nothing (0/5 runs), so
    stability and sample efficiency are refuted, not reproduced."""
    for task in ("dcp", "dbm"):
        for seed in range(SEEDS):
            flat = [0.44] * 11
            riser = [0.3, 0.0, 0.0, 0.2, 0.4, 0.6, 0.8, 0.8, 0.8, 0.8, 0.8]
            _write_run(tmp_path, task, "dist-gprl", seed, 0.44, flat)
            _write_run(tmp_path, task, "dist-gprl-nocov", seed, 0.8 + JITTER[seed], riser)
    write_tables(tmp_path, "p", tmp_path / "out")
    _, rows = read_csv(tmp_path / "out" / "claims_p.csv")
    overall = {r["claim"]: r for r in rows if r["task"] == "all"}
    assert overall["The covariance transform improves stability"]["verdict"] == REFUTED
    assert overall["The covariance transform improves sample efficiency"]["verdict"] == REFUTED
    dcp = next(r for r in rows if r["task"] == "dcp" and r["claim"].endswith("sample efficiency"))
    assert "runs that learned: Dist-GPRL 0/5, Dist-GPRL-NoCov 5/5" in dcp["detail"]
