"""Studies (`distgprl.studies`): each reading's preset sets the operator it is named for, and
a study name plans its readings' runs — and only those — for sweep and status."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.config import load_config, shipped_presets
from distgprl.errors import UserInputError
from distgprl.experiments.sweep import plan_jobs
from distgprl.studies import STUDIES, get_study


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_every_reading_is_a_shipped_preset_with_its_operator(name):
    study = get_study(name)
    for reading in study.all_readings:
        assert reading.preset in shipped_presets()
        assert load_config(reading.preset).env.covariance_scale == reading.covariance_scale
    assert name not in shipped_presets()  # a study is not a preset: no run folder of its own


def test_a_study_plans_its_methods_under_each_reading_seed_by_seed(tmp_path):
    """operators, seeds 0-1: 3 readings x 2 tasks x 2 seeds of Dist-GPRL, seed 0 of every
    reading first, without follow-ups (twin trials, repair evaluations), named by preset."""
    jobs = plan_jobs("operators", seeds=[0, 1], root=tmp_path, twin_trials=10)
    study = get_study("operators")
    assert len(jobs) == len(study.presets) * 2 * 2
    assert {job.method for job in jobs} == {"dist-gprl"}
    assert {job.preset for job in jobs} == set(study.presets)
    assert [job.seed for job in jobs] == [0] * 6 + [1] * 6
    assert all(job.twin_trials == 0 and not job.repair_evaluations for job in jobs)
    assert jobs[0].name == "operator-unit/dcp/dist-gprl/seed0"
    more = plan_jobs("operators", methods=["dist-gprl", "gprl-d"], seeds=[0], root=tmp_path)
    assert {job.method for job in more} == {"dist-gprl", "gprl-d"}
    with pytest.raises(UserInputError):
        plan_jobs("operators", seeds=[], root=tmp_path)


def test_status_accepts_a_study(tmp_path):
    result = CliRunner().invoke(
        app, ["status", "--preset", "operators", "--seeds", "0", "--root", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    assert "operator-signal/dbm/dist-gprl/seed0" in result.output
    assert "0/6 done, 6 missing" in result.output
