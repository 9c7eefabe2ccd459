"""Claims per reading (`distgprl.report.robustness`): which runs each reading reads, the
verdict across readings, and the claims_robustness files `write_tables` writes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from distgprl.report.aggregate import ALL_TASKS
from distgprl.report.claims import NO_RUNS, REFUTED, REPRODUCED
from distgprl.report.robustness import (
    NOT_RUN,
    OUTSIDE,
    across_readings,
    reading_scores,
    reference_reading,
    robustness_texts,
    study_verdicts,
)
from distgprl.studies import get_study

JITTER = np.array([-0.02, -0.01, 0.0, 0.01, 0.02])


def runs(success, collision, retention=0.5):
    return [
        {
            "success_rate": success + j,
            "collision_rate": collision + j,
            "mean_kinematic_retention": retention + j,
        }
        for j in JITTER
    ]


def by_reading(results):
    """{preset: {claim: its overall row}} of a `study_verdicts` frame."""
    groups = results[results.task == ALL_TASKS].groupby("preset", sort=False)
    return {preset: {row.claim: row for row in group.itertuples()} for preset, group in groups}


def both_tasks(methods):
    return {(task, m): r for task in ("dcp", "dbm") for m, r in methods.items()}


FIELD = {
    "gprl": runs(0.4, 0.5, 0.4),
    "promp-rrl": runs(0.2, 0.05, 0.3),
    "dist-gprl-global": runs(0.3, 0.3, 0.5),
    "gprl-d": runs(0.6, 0.2, 0.6),
    "gprl-h": runs(0.6, 0.35, 0.6),
    "dist-gprl": runs(0.9, 0.1, 0.7),
    "dist-gprl-nocov": runs(0.7, 0.15, 0.7),
}
GLOBAL = "Windowed adaptation beats global"
HAP = "The HAP prior raises final success"


def test_a_reading_replaces_only_the_methods_the_operator_acts_on():
    """Under a study reading Dist-GPRL's runs are the reading's, NoCov's and Global's Table
    I's (no operator), and GPRL-D/GPRL-H (operator, no run under the reading) are not
    borrowed from Table I but reported as not run."""
    reference = both_tasks(FIELD)
    study_runs = both_tasks({"dist-gprl": runs(0.1, 0.8)})
    scores, not_run = reading_scores(reference, study_runs, get_study("operators").acted_on)
    assert scores[("dcp", "dist-gprl")] is study_runs[("dcp", "dist-gprl")]
    assert scores[("dcp", "dist-gprl-nocov")] is reference[("dcp", "dist-gprl-nocov")]
    assert ("dcp", "gprl-d") not in scores and ("dbm", "gprl-h") not in scores
    assert not_run == ("gprl-d", "gprl-h")


def test_a_verdict_that_flips_with_the_reading_is_reading_dependent():
    """Dist-GPRL beats Global under Table I's operator (0.9 vs 0.3) and loses under one study
    reading (0.1): the claim is reproduced there, refuted here, and reading-dependent across;
    a claim needing GPRL-D is not run under the study readings, so it is never robust. Each
    reading keeps its per-task estimates, except a claim not run under it."""
    study = get_study("operators")
    reference = both_tasks(FIELD)
    worse = both_tasks({"dist-gprl": runs(0.1, 0.8)})
    same = both_tasks({"dist-gprl": FIELD["dist-gprl"]})
    runs_of = {
        "operator-unit": same,
        "operator-signal": worse,
        "operator-correlation": same,
        "operator-signal-uncoupled": worse,  # a control: no verdict reads it
    }
    results = study_verdicts([study], reference, runs_of.__getitem__, seed=0)
    assert list(dict.fromkeys(results.preset)) == ["paper", *study.presets[:3]]
    assert [r.preset for r in study.claim_readings] == list(study.presets[:3])
    verdict = by_reading(results)
    assert verdict["paper"][GLOBAL].verdict == REPRODUCED
    assert verdict["operator-unit"][GLOBAL].verdict == REPRODUCED
    assert verdict["operator-signal"][GLOBAL].verdict == REFUTED
    assert verdict["paper"][HAP].verdict == REPRODUCED
    assert verdict["operator-unit"][HAP].verdict == OUTSIDE  # the study trains Dist-GPRL only
    assert "GPRL-D under operator-unit" in verdict["operator-unit"][HAP].detail
    assert "trains Dist-GPRL only" in verdict["operator-unit"][HAP].detail
    signal = results[(results.preset == "operator-signal") & (results.claim == GLOBAL)]
    assert [(row.task, row.estimate.point) for row in signal.itertuples()][:2] == [
        ("dcp", 0.0),
        ("dbm", 0.0),
    ]  # each task's PoI under the reading: Dist-GPRL at 0.1 below Global at 0.3
    assert set(results[results.claim == HAP].task) == {"dcp", "dbm", ALL_TASKS}
    unit_hap = results[(results.preset == "operator-unit") & (results.claim == HAP)]
    assert list(unit_hap.task) == [ALL_TASKS]  # not run under the reading: its overall row alone
    csv_text, markdown = robustness_texts(results, "paper")
    across = {line.split(",")[0]: line for line in csv_text.splitlines() if ",across,," in line}
    assert (
        "reading-dependent: reproduced under zero-mean GP (Table I), unit variance (v4)"
        in (across[GLOBAL])
    )
    assert "refuted under per-axis signal (v5)" in across[GLOBAL]
    assert (
        "reproduced under every reading that tests it (1 of 4; untested: unit variance (v4), "
        "per-axis signal (v5), correlation only)" in across[HAP]
    )
    assert "under every reading," not in across[HAP]
    assert markdown.count("\n| ") == 1 + len(verdict["paper"])  # header + one row per claim
    assert "unit variance (v4): GPRL-D, GPRL-H" in markdown


def test_the_rule_across_readings():
    """Every reading alike: that verdict under every reading; a decided disagreement is
    reading-dependent even while another reading waits; otherwise incomplete."""
    assert across_readings([("a", REPRODUCED), ("b", REPRODUCED)]) == (
        "reproduced under every reading"
    )
    assert across_readings([("a", "reproduced on DCP"), ("b", "reproduced on DCP")]) == (
        "reproduced on DCP under every reading"
    )
    assert across_readings([("a", REPRODUCED), ("b", "inconclusive"), ("c", NO_RUNS)]) == (
        "reading-dependent: reproduced under a; inconclusive under b"
    )
    assert across_readings([("a", REFUTED), ("b", NOT_RUN)]) == (
        "incomplete: refuted under 1 of 2 readings; awaiting b"
    )
    assert across_readings([("a", NO_RUNS), ("b", NOT_RUN)]) == "incomplete: awaiting a, b"


def test_a_reading_that_does_not_test_a_claim_is_named_and_never_counts_as_agreeing():
    """A study reading that does not train a method the claim reads (OUTSIDE) neither agrees
    nor disagrees: the verdict says how many readings test the claim and names the others."""
    assert across_readings([("a", REPRODUCED), ("b", OUTSIDE), ("c", REPRODUCED)]) == (
        "reproduced under every reading that tests it (2 of 3; untested: b)"
    )
    assert across_readings([("a", REPRODUCED), ("b", OUTSIDE), ("c", REFUTED)]) == (
        "reading-dependent: reproduced under a; refuted under c; untested: b"
    )
    assert across_readings([("a", REPRODUCED), ("b", OUTSIDE), ("c", NOT_RUN)]) == (
        "incomplete: reproduced under 1 of 2 readings; awaiting c; untested: b"
    )


def test_a_method_the_study_trains_but_has_not_run_is_awaited_not_untested():
    """Under the operator readings Dist-GPRL is trained by the study: a claim reading it with
    no run under a reading is NOT_RUN (awaited), not OUTSIDE."""
    study = get_study("operators")
    results = study_verdicts([study], both_tasks(FIELD), lambda preset: {}, seed=0)
    verdict = by_reading(results)
    assert verdict["operator-unit"][GLOBAL].verdict == NOT_RUN
    assert verdict["operator-unit"][HAP].verdict == OUTSIDE


def test_a_study_of_every_trained_method_replaces_every_trained_method(unit_study_preset):
    """A reading of a reward constant changes every trained method's rewards: under it no
    Table I run of a trained method is kept (the references are), and a method without a run
    under it makes its claims not run."""
    study = unit_study_preset
    (reading,) = study.presets
    reference = both_tasks({**FIELD, "demo": runs(0.5, 0.3)})
    reading_runs = both_tasks({"dist-gprl": FIELD["dist-gprl"]})
    scores, not_run = reading_scores(reference, reading_runs, study.acted_on)
    assert {m for _, m in scores} == {"dist-gprl", "demo"}
    assert set(not_run) == set(FIELD) - {"dist-gprl"}
    results = study_verdicts([get_study("operators"), study], reference, lambda p: {}, seed=0)
    assert list(dict.fromkeys(results.preset)) == [
        "paper",
        "operator-unit",
        "operator-signal",
        "operator-correlation",
        reading,
    ]
    assert set(results[results.preset == reading].verdict) == {NOT_RUN}


def test_with_two_studies_each_has_its_own_column_beside_the_overall_one(unit_study_preset):
    """The operator study's verdict does not wait for another study's runs: with both read,
    each study's column judges Table I's reading and that study's readings only."""
    operators, unit = get_study("operators"), unit_study_preset
    reference = both_tasks(FIELD)
    same = both_tasks({"dist-gprl": FIELD["dist-gprl"]})
    runs_of = {p: same for p in operators.presets} | {unit.presets[0]: {}}
    results = study_verdicts([operators, unit], reference, runs_of.__getitem__, seed=0)
    csv_text, markdown = robustness_texts(results, "paper")
    rows = [line.split(",") for line in csv_text.splitlines()]
    of_global = {row[1]: row[3] for row in rows if row[0] == GLOBAL}
    assert of_global["across operators"] == "reproduced under every reading"
    assert of_global["across unit"].startswith("incomplete: reproduced under 1 of 2")
    assert of_global["across"].startswith("incomplete: reproduced under 4 of 5")
    assert "Across Table I and the operators study" in markdown
    assert "Across Table I and the unit study" in markdown


def test_with_two_studies_table_one_is_named_by_every_studied_constant(unit_study_preset):
    """With the operator and a unit study read together, Table I's reading is named by both
    constants' Table I values, never by one study's alone (a unit verdict naming "zero-mean
    GP" would name the operator); one study keeps its own reference label, and studies of
    different Table I presets are refused."""
    operators, unit = get_study("operators"), unit_study_preset
    both = reference_reading([operators, unit])
    assert both.preset == "paper"
    assert both.label == "Table I (zero-mean GP; r_tc in tenths of a task)"
    assert reference_reading([unit]) == unit.reference
    reference = both_tasks(FIELD)
    same = both_tasks({"dist-gprl": FIELD["dist-gprl"]})
    runs_of = {p: same for p in operators.presets} | {unit.presets[0]: {}}
    results = study_verdicts([operators, unit], reference, runs_of.__getitem__, seed=0)
    assert (results.reading[0], results.preset[0]) == (both.label, both.preset)
    csv_text, _ = robustness_texts(results, "paper")
    assert "zero-mean GP (Table I)" not in csv_text
    other = replace(unit, reference=replace(unit.reference, preset="ci"))
    with pytest.raises(ValueError, match="different Table I presets"):
        reference_reading([operators, other])


def test_a_verdict_across_readings_with_different_seed_counts_says_so():
    """While a study trains, Table I's reading can have five seeds of Dist-GPRL and a study
    reading two: a decided verdict across them ends 'at unequal seeds' (a narrower interval
    can decide where a wider one cannot), equal counts add nothing, and the table lists each
    reading's seeds of Dist-GPRL per task."""
    assert across_readings(
        [("a", REPRODUCED), ("b", "inconclusive")], {"a": (5, 5), "b": (2, 2)}
    ) == ("reading-dependent: reproduced under a; inconclusive under b; at unequal seeds")
    assert across_readings([("a", REPRODUCED), ("b", REPRODUCED)], {"a": (5,), "b": (5,)}) == (
        "reproduced under every reading"
    )
    assert across_readings(
        [("a", REPRODUCED), ("b", OUTSIDE), ("c", REPRODUCED)], {"a": (5,), "b": (0,), "c": (3,)}
    ) == ("reproduced under every reading that tests it (2 of 3; untested: b); at unequal seeds")
    assert across_readings([("a", REFUTED), ("b", NOT_RUN)], {"a": (5,), "b": (0,)}) == (
        "incomplete: refuted under 1 of 2 readings; awaiting b"
    )
    study = get_study("operators")
    reference = both_tasks(FIELD)
    two = {key: value[:2] for key, value in both_tasks({"dist-gprl": FIELD["dist-gprl"]}).items()}
    results = study_verdicts([study], reference, lambda preset: two, seed=0)
    seeds = dict(zip(results.preset, results.seeds, strict=True))
    assert seeds["paper"] == (("dcp", 5), ("dbm", 5))
    assert seeds["operator-unit"] == (("dcp", 2), ("dbm", 2))
    csv_text, markdown = robustness_texts(results, "paper")
    assert "at unequal seeds" in csv_text
    assert (
        "Seeds of Dist-GPRL per reading (DCP / DBM): zero-mean GP (Table I) 5 / 5; "
        "unit variance (v4) 2 / 2" in markdown
    )
