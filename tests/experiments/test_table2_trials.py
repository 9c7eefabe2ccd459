"""The Table II twin trials of one policy: which settings are due, and the sweep running
them while the policy is on disk (`distgprl.experiments.table2_trials`, `experiments.sweep`)."""

from __future__ import annotations

import pytest

from distgprl.experiments import sweep
from distgprl.experiments.follow_ups import run_job_trials, trials_due
from distgprl.experiments.jobs import Job
from distgprl.experiments.table2_trials import (
    PAPER_SETTING,
    TrialSetting,
    missing_settings,
    model_path,
    run_table2_trials,
    table2_settings,
)
from distgprl.identity import resolve_run
from distgprl.schema import TRIAL_FIELDS, read_csv, write_csv, write_json


def test_every_method_gets_the_papers_protocol_first_then_the_safety_layer_settings():
    """Every method of Table I and both references run the paper's protocol first (Table II's
    primary: no pre-flight check), then the safety layer with repair on and off, and at every
    sensor-noise level (issue 50 item 5: where does each policy break?), ProMP-RRL's residual
    RL and its nominal included (checked one 0.1 s step at a time)."""
    from distgprl.hardware.twin import SENSOR_NOISE
    from distgprl.methods import TABLE_ORDER

    noisy = {TrialSetting(True, level) for level in SENSOR_NOISE if level > 0}
    assert {"promp-rrl", "promp-nominal", "demo"} <= set(TABLE_ORDER)
    for method in TABLE_ORDER:
        settings = table2_settings(method)
        assert settings[0] == TrialSetting(False, 0, "paper")
        assert set(settings) == {
            TrialSetting(False, 0, "paper"),
            TrialSetting(True, 0),
            TrialSetting(False, 0),
            *noisy,
        }
    assert len(noisy) == 4


def test_the_cli_admits_every_twin_noise_level():
    from typer.testing import CliRunner

    from distgprl.cli import app
    from distgprl.hardware.twin import SENSOR_NOISE

    result = CliRunner().invoke(app, ["hardware", "--help"])
    assert f"0<=x<={max(SENSOR_NOISE)}" in result.output.replace(" ", "")


def _trial_file(root, method, name, rows=2, **meta):
    values = {
        "kind": "hardware-trials",
        "protocol": "safety-layer",
        "method": method,
        "seed": 0,
        "backend": "twin",
        "preset": "ci",
        "dry_run": False,
        "force": False,
        "repair": True,
        "repair_push": False,
        "sensor_noise": 0,
        "policy": {"run_config_hash": resolve_run("dbm", method, 0, "ci").hash},
    }
    values.update(meta)
    row = dict.fromkeys(TRIAL_FIELDS, "0")
    write_csv(root / "hardware" / method / name, [row] * rows, TRIAL_FIELDS, **values)


def test_only_a_file_table_ii_would_count_makes_a_setting_done(tmp_path):
    """Force, dry runs, pushes, another preset or backend, a stale policy hash, the best
    policy's trials (Table II counts the final one's) and too few trials leave the setting
    due; a counted file of repair off removes exactly that one, a paper-protocol file the
    paper's setting, and a file without a protocol (written before the paper's protocol
    existed) counts as the safety layer's."""
    stale = {"run_config_hash": "0" * 16}
    current = resolve_run("dbm", "gprl", 0, "ci").hash
    for index, meta in enumerate(
        [
            {"force": True},
            {"dry_run": True},
            {"repair_push": True},
            {"preset": "paper"},
            {"backend": "ur"},
            {"policy": stale},
            {"policy": {"run_config_hash": current, "policy": "best (shipped, step 60)"}},
            {"repair": False, "rows": 1},
        ]
    ):
        rows = meta.pop("rows", 2)
        _trial_file(tmp_path, "gprl", f"trials_twin_seed0_{index}.csv", rows=rows, **meta)
    assert missing_settings(tmp_path, "ci", "gprl", 0, trials=2) == table2_settings("gprl")
    _trial_file(tmp_path, "gprl", "trials_twin_seed0_counted.csv", repair=False)
    due = tuple(s for s in table2_settings("gprl") if s != TrialSetting(False, 0))
    assert missing_settings(tmp_path, "ci", "gprl", 0, trials=2) == due
    _trial_file(tmp_path, "gprl", "trials_twin_seed0_paper.csv", protocol="paper", repair=False)
    due = tuple(s for s in due if s.protocol != "paper")
    assert missing_settings(tmp_path, "ci", "gprl", 0, trials=2) == due
    _trial_file(tmp_path, "gprl", "trials_twin_seed0_legacy.csv", protocol=None, sensor_noise=1)
    due = tuple(s for s in due if s != TrialSetting(True, 1))
    assert missing_settings(tmp_path, "ci", "gprl", 0, trials=2) == due
    # another seed's files do not count for seed 0, and vice versa
    assert missing_settings(tmp_path, "ci", "gprl", 1, trials=2) == table2_settings("gprl")


def test_the_best_policys_trials_are_settings_of_their_own(tmp_path):
    """Of the best policy (Table I's) Table II's three noise-free settings; a final-policy file
    does not make a best-policy setting done, nor the other way round; a reference's file
    (no policy) counts for both; the best policy can run from the actor the run ships."""
    from distgprl.experiments.policies import SHIPPED_POLICY
    from distgprl.experiments.table2_trials import policy_on_disk

    assert table2_settings("gprl", "best") == table2_settings("gprl")[:3]
    current = resolve_run("dbm", "gprl", 0, "ci").hash
    final = {"run_config_hash": current, "model": "/r/ci/dbm/gprl/seed0/model.zip"}
    best = {"run_config_hash": current, "model": "/r/policy_best.pt", "policy": "best (x)"}
    paper = {"protocol": "paper", "repair": False}
    _trial_file(tmp_path, "gprl", "trials_twin_seed0_final.csv", policy=final, **paper)
    assert PAPER_SETTING not in missing_settings(tmp_path, "ci", "gprl", 0, 2)
    assert PAPER_SETTING in missing_settings(tmp_path, "ci", "gprl", 0, 2, "best")
    _trial_file(tmp_path, "gprl", "trials_twin_seed0_best.csv", policy=best)
    assert missing_settings(tmp_path, "ci", "gprl", 0, 2, "best") == (
        PAPER_SETTING,
        TrialSetting(False, 0),
    )
    assert TrialSetting(True, 0) in missing_settings(tmp_path, "ci", "gprl", 0, 2)
    _trial_file(tmp_path, "demo", "trials_twin_seed0_demo.csv", policy={}, **paper)
    for policy in ("final", "best"):
        assert PAPER_SETTING not in missing_settings(tmp_path, "ci", "demo", 0, 2, policy)
    folder = model_path(tmp_path, "ci", "gprl", 0).parent
    folder.mkdir(parents=True)
    (folder / SHIPPED_POLICY).write_bytes(b"")
    assert policy_on_disk(tmp_path, "ci", "gprl", 0, "best")
    assert not policy_on_disk(tmp_path, "ci", "gprl", 0, "final")
    assert policy_on_disk(tmp_path, "ci", "demo", 0, "final")


def test_a_jobs_trial_policy_reaches_its_trials(monkeypatch):
    """The sweep's follow-up asks for and runs the trials of the policy its job names."""
    from distgprl.experiments import table2_trials

    seen = []
    monkeypatch.setattr(table2_trials, "trials_due", lambda *args: seen.append(args) or True)
    monkeypatch.setattr(table2_trials, "run_and_report", lambda *args: seen.append(args) or "")
    job = Job("dbm", "gprl", 0, "ci", "r", twin_trials=2, trial_policy="best")
    assert trials_due(job) and run_job_trials(job) == ""
    assert seen == [("gprl", 0, "ci", "r", 2, "best")] * 2


@pytest.fixture(scope="module")
def gprl_on_disk(tmp_path_factory, untrained_dbm_policy):
    """A results root with an (untrained) DBM ``gprl`` ci policy where its run keeps it."""
    root = tmp_path_factory.mktemp("results")
    source = untrained_dbm_policy("gprl")
    target = model_path(root, "ci", "gprl", 0)
    target.parent.mkdir(parents=True)
    target.write_bytes(source.read_bytes())
    write_json(
        target.parent / "config.json",
        {"config_hash": resolve_run("dbm", "gprl", 0, "ci").hash},
        kind="config",
    )
    return root


def test_the_sweep_runs_a_finished_runs_missing_trials_once(gprl_on_disk, monkeypatch):
    """A finished DBM run with its model on disk is picked up for its trials alone (no
    training, the job's time theirs), every setting runs once, and the next sweep finds
    nothing due."""
    root = gprl_on_disk
    job = Job("dbm", "gprl", 0, "ci", str(root), twin_trials=1)
    assert trials_due(job)
    assert not trials_due(Job("dbm", "gprl", 0, "ci", str(root)))  # not asked
    assert not trials_due(Job("dbm", "gprl", 1, "ci", str(root), 1))  # no model
    assert not trials_due(Job("dcp", "gprl", 0, "ci", str(root), 1))  # not DBM

    def already_trained(job):
        return sweep.JobResult(job, "skipped", 0.0)

    monkeypatch.setattr(sweep, "finished_result", already_trained)
    monkeypatch.setattr(sweep, "train_run", lambda *a, **k: pytest.fail("trained again"))
    results = sweep.run_sweep([job], workers=1)
    assert [r.status for r in results] == ["skipped"]
    assert results[0].seconds > 0  # the follow-ups' time, which the sweep's ETA reads
    settings = table2_settings("gprl")
    assert results[0].trials.startswith(f"twin trials: {len(settings)} setting(s) run\n")
    files = sorted((root / "hardware" / "gprl").glob("trials_twin_seed0_*.csv"))
    metas = [read_csv(path)[0] for path in files]
    assert {(m["protocol"], m["repair"], m["sensor_noise"]) for m in metas} == {
        (s.protocol, s.repair, s.sensor_noise) for s in settings
    }
    assert all(len(read_csv(path)[1]) == 1 for path in files)
    assert not trials_due(job)
    assert sweep.run_sweep([job], workers=1)[0].trials == ""  # nothing due: nothing run
    assert run_table2_trials("gprl", 0, "ci", root, trials=1) == []


def test_a_failing_trial_is_reported_with_the_job_and_leaves_the_run_done(
    gprl_on_disk, monkeypatch
):
    from distgprl.experiments import table2_trials

    def broken(*args, **kwargs):
        raise RuntimeError("camera unplugged")

    monkeypatch.setattr(table2_trials, "missing_settings", lambda *a, **k: (TrialSetting(True, 2),))
    monkeypatch.setattr("distgprl.hardware.trials.run_trials", broken)
    job = Job("dbm", "gprl", 0, "ci", str(gprl_on_disk), twin_trials=3)
    assert run_job_trials(job) == "twin trials failed: RuntimeError: camera unplugged"


def test_coverage_tells_complete_pending_and_lost_policies_apart(gprl_on_disk, tmp_path):
    """A policy with every setting is complete; one lacking settings is pending while its
    model is on disk and lost without it; the references need no model."""
    from distgprl.experiments.table2_trials import coverage

    root = tmp_path
    target = model_path(root, "ci", "gprl", 0)
    target.parent.mkdir(parents=True)
    target.write_bytes(model_path(gprl_on_disk, "ci", "gprl", 0).read_bytes())
    for setting in table2_settings("demo"):
        _trial_file(
            root,
            "demo",
            f"trials_twin_seed0_{setting.protocol}{setting.repair}{setting.sensor_noise}.csv",
            repair=setting.repair,
            sensor_noise=setting.sensor_noise,
            protocol=setting.protocol,
            policy={},
        )
    finished = [("demo", 0), ("gprl", 0), ("gprl", 1), ("promp-nominal", 0)]
    report = coverage(root, "ci", finished, trials=2)
    assert report.complete == ("demo/seed0",)
    assert report.pending == ("gprl/seed0", "promp-nominal/seed0")
    assert report.lost == ("gprl/seed1",)
    assert report.describe() == (
        "Table II twin trials: 1 DBM policies complete, 2 pending, "
        "1 without their model on disk (gprl/seed1)"
    )
