"""Studies (`distgprl.studies`): each reading's preset sets the operator it is named for, and
a study name plans its readings' runs — and only those — for sweep and status."""

from __future__ import annotations

from dataclasses import asdict

import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.config import load_config, shipped_presets
from distgprl.errors import UserInputError
from distgprl.experiments.sweep import plan_jobs
from distgprl.studies import STUDIES, get_study


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_every_reading_differs_from_the_reference_in_exactly_its_stated_changes(name):
    """Each reading's preset is shipped and its configuration equals the reference preset's
    but for the (section.field, value) pairs the study states, on both tasks; each stated
    value differs from the reference's (a reading at Table I's own value re-runs Table I, as
    v7's reward-unit reading did once v8 made its unit Table I's)."""
    study = get_study(name)
    assert name not in shipped_presets()  # a study is not a preset: no run folder of its own
    for reading in study.all_readings:
        assert reading.preset in shipped_presets()
        for task in ("dcp", "dbm"):
            reference = asdict(load_config(study.reference.preset, task))
            config = asdict(load_config(reading.preset, task))
            stated = {}
            for key, value in reading.changes:
                section, field = key.split(".")
                assert config[section][field] == value, (reading.preset, key)
                assert reference[section][field] != value, (reading.preset, key, "Table I's")
                stated[(section, field)] = value
            for section in ("env", "sac", "run"):
                for field, value in reference[section].items():
                    if (section, field) not in stated:
                        assert config[section][field] == value, (reading.preset, field)


def test_a_study_plans_its_methods_under_each_reading_seed_by_seed(tmp_path):
    """operators, seeds 0-1: 3 readings and the control x 2 tasks x 2 seeds of Dist-GPRL, seed
    0 of every reading first, without follow-ups (twin trials, repair evaluations), named by
    preset."""
    jobs = plan_jobs("operators", seeds=[0, 1], root=tmp_path, twin_trials=10)
    study = get_study("operators")
    assert len(jobs) == len(study.presets) * 2 * 2
    assert {job.method for job in jobs} == {"dist-gprl"}
    assert {job.preset for job in jobs} == set(study.presets)
    assert [job.seed for job in jobs] == [0] * 8 + [1] * 8
    assert all(job.twin_trials == 0 and not job.repair_evaluations for job in jobs)
    assert jobs[0].name == "operator-unit/dcp/dist-gprl/seed0"
    more = plan_jobs("operators", methods=["dist-gprl", "gprl-d"], seeds=[0], root=tmp_path)
    assert {job.method for job in more} == {"dist-gprl", "gprl-d"}
    with pytest.raises(UserInputError):
        plan_jobs("operators", seeds=[], root=tmp_path)


def test_a_study_without_seeds_plans_its_seeds_then_its_rules_runs(tmp_path):
    """No seeds given: the study's seeds 0-4 for every reading, then each pre-registered
    rule's further runs (its reading, Dist-GPRL, its task) — none twice, none with
    follow-ups; a task or method filter that excludes a rule's excludes its runs."""
    study = get_study("operators")
    jobs = plan_jobs("operators", root=tmp_path)
    readings = len(study.presets) * 2 * len(study.seeds)
    assert len(jobs) == readings + 5 + 10
    assert {job.seed for job in jobs[:readings]} == set(study.seeds)
    extra = {(job.preset, job.task, job.method, job.seed) for job in jobs[readings:]}
    assert extra == {("operator-signal", "dcp", "dist-gprl", s) for s in range(5, 10)} | {
        ("operator-signal-uncoupled", "dcp", "dist-gprl", s) for s in range(5, 15)
    }
    assert all(job.twin_trials == 0 and not job.repair_evaluations for job in jobs)
    assert len(plan_jobs("operators", tasks=["dbm"], root=tmp_path)) == readings // 2
    assert len(plan_jobs("operators", methods=["gprl-d"], root=tmp_path)) == readings


def test_status_accepts_a_study(tmp_path):
    result = CliRunner().invoke(
        app, ["status", "--preset", "operators", "--seeds", "0", "--root", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    assert "operator-signal/dbm/dist-gprl/seed0" in result.output
    assert "operator-signal-uncoupled/dcp/dist-gprl/seed0" in result.output
    assert "0/8 done, 8 missing" in result.output
    result = CliRunner().invoke(app, ["status", "--preset", "operators", "--root", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "operator-signal-uncoupled/dcp/dist-gprl/seed14" in result.output
    assert "0/55 done, 55 missing" in result.output


def test_a_reading_preset_knows_its_study_and_a_reference_preset_none():
    """`study_of_reading`: each reading's (and control's) preset names its study, so `status
    --preset <reading>` can borrow the reference preset's pace; Table I's preset is none's."""
    from distgprl.studies import study_of_reading

    for study in STUDIES.values():
        for preset in study.presets:
            assert study_of_reading(preset) is study
    assert study_of_reading("paper") is None and study_of_reading("ci") is None


def test_a_rule_and_a_study_refuse_rules_that_could_not_be_applied():
    """at_most below at_least within the seed count; unique rule names; a needed rule that
    exists; one threshold and by_step per study (the onsets table's single early column)."""
    import dataclasses

    from distgprl.studies import OnsetRule, Reading, Study

    rule = OnsetRule("a", "dcp", 0.5, 4500, (0, 1, 2), 2, 1, "early", "late")
    for bad in ({"at_least": 4}, {"at_most": 2}, {"at_most": -1}):
        with pytest.raises(ValueError, match="at_most < at_least"):
            dataclasses.replace(rule, **bad)
    reference = Reading("paper", "Table I")

    def study(*rules):
        return Study(
            "s", reference, (Reading("operator-unit", "u", rules=rules),), ("dist-gprl",), "?"
        )

    assert [r.name for _, r in study(rule, dataclasses.replace(rule, name="b")).rules] == ["a", "b"]
    with pytest.raises(ValueError, match="repeat"):
        study(rule, rule)
    with pytest.raises(ValueError, match="unknown rule 'c'"):
        study(dataclasses.replace(rule, given="c"))
    with pytest.raises(ValueError, match="circle"):
        study(dataclasses.replace(rule, given="b"), dataclasses.replace(rule, name="b", given="a"))
    with pytest.raises(ValueError, match="threshold or by_step"):
        study(rule, dataclasses.replace(rule, name="b", by_step=3000))
    with pytest.raises(KeyError, match="no rule 'c'"):
        study(rule).rule("c")
    with pytest.raises(ValueError, match="a seed repeats"):
        dataclasses.replace(rule, seeds=(5, 5, 6))
    with pytest.raises(ValueError, match="not its reference"):
        Study("s", Reading("paper", "Table I", rules=(rule,)), (), ("dist-gprl",), "?")
    with pytest.raises(ValueError, match="distinct and some"):
        Study("s", reference, (), ("dist-gprl",), "?", seeds=())


def test_the_operator_controls_second_stage_reads_new_seeds_only():
    """Pre-registered (docs/findings/operator.md, stage 2): the control's seeds 5-14 and the
    signal reading's 5-9, none of the study's own 0-4, and stage 2 needs the replication."""
    study = get_study("operators")
    reading, stage2 = study.rule("stage 2")
    assert reading.control and stage2.seeds == tuple(range(5, 15))
    assert (stage2.at_least, stage2.at_most, stage2.given) == (8, 2, "stage 2 replication")
    signal, replication = study.rule("stage 2 replication")
    assert signal.preset == "operator-signal" and replication.seeds == (5, 6, 7, 8, 9)
    assert not set(stage2.seeds + replication.seeds) & set(study.seeds)
    assert study.rule("stage 1")[1].seeds == study.seeds
