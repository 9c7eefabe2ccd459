"""The safety-layer evaluations a sweep runs after each run (`experiments.repair_follow_ups`),
on the ci preset's untrained `demo` reference (no training needed)."""

from __future__ import annotations

import pytest

from distgprl.experiments import repair_follow_ups as follow
from distgprl.experiments import sweep
from distgprl.experiments.evaluation import evaluate_run
from distgprl.experiments.follow_ups import follow_up_due, repairs_due
from distgprl.experiments.jobs import Job
from distgprl.schema import read_csv, read_json, repair_evaluation_file_names, run_dir, write_json


def test_the_modes_are_check_only_and_retime_without_push():
    check, repair = (follow.mode_config(mode) for mode in follow.SWEEP_REPAIR_MODES)
    assert (check.retime, check.repair) == (False, False)
    assert (repair.retime, repair.repair) == (True, False)
    with pytest.raises(ValueError, match="push"):
        follow.mode_config("push")


@pytest.fixture
def demo_evaluated(tmp_path):
    """A results root where the ci DBM `demo` reference has its plain evaluation."""
    evaluate_run("dbm", "demo", 0, "ci", root=tmp_path, show_progress=False)
    return tmp_path


def test_a_sweep_evaluates_a_finished_run_in_both_modes_once(demo_evaluated, monkeypatch):
    """A finished run without its safety-layer evaluations is picked up for them alone (not
    evaluated or trained again), both modes are written for the run's configuration, and the
    next sweep finds nothing due."""
    root = demo_evaluated
    job = Job("dbm", "demo", 0, "ci", str(root), repair_evaluations=True)
    assert repairs_due(job) and follow_up_due(job)
    assert not repairs_due(Job("dbm", "demo", 0, "ci", str(root)))  # not asked
    assert not repairs_due(Job("dcp", "demo", 0, "ci", str(root), 0, True))  # no run
    monkeypatch.setattr(sweep, "finished_result", lambda job: sweep.JobResult(job, "skipped", 0))
    monkeypatch.setattr(sweep, "evaluate_run", lambda *a, **k: pytest.fail("evaluated again"))
    results = sweep.run_sweep([job], workers=1)
    assert [r.status for r in results] == ["skipped"]
    lines = results[0].repairs.split("\n  ")
    assert [line.split(":")[0] for line in lines] == [
        "safety layer (check)",
        "safety layer (repair)",
    ]
    folder = run_dir(root, "ci", "dbm", "demo", 0)
    current = read_json(folder / "config.json")["config_hash"]
    for mode in follow.SWEEP_REPAIR_MODES:
        csv_name, summary_name = repair_evaluation_file_names(None, "final", mode)
        meta, rows = read_csv(folder / csv_name)
        assert meta["repair_mode"] == mode and meta["config_hash"] == current and len(rows) == 6
    assert follow.missing_modes(root, "ci", "dbm", "demo", 0) == ()
    assert not repairs_due(job)
    assert sweep.run_sweep([job], workers=1)[0].repairs == ""


def test_an_evaluation_of_another_configuration_is_due_again(demo_evaluated):
    folder = run_dir(demo_evaluated, "ci", "dbm", "demo", 0)
    for mode in follow.SWEEP_REPAIR_MODES:
        summary = folder / repair_evaluation_file_names(None, "final", mode)[1]
        write_json(summary, {"summary": {}}, config_hash="0" * 16 if mode == "check" else None)
    assert follow.missing_modes(demo_evaluated, "ci", "dbm", "demo", 0) == ("check", "repair")


def test_a_trained_run_without_its_model_is_not_due(tmp_path):
    """Weights are not committed: a finished trained run from elsewhere cannot be evaluated."""
    folder = run_dir(tmp_path, "ci", "dbm", "gprl", 0)
    folder.mkdir(parents=True)
    write_json(folder / "summary.json", {"summary": {}})
    assert not follow.evaluations_due(tmp_path, "ci", "dbm", "gprl", 0)
    (folder / "model.zip").write_bytes(b"")
    assert follow.evaluations_due(tmp_path, "ci", "dbm", "gprl", 0)


def test_a_failing_evaluation_is_reported_and_does_not_raise(demo_evaluated, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("simulator lost")

    monkeypatch.setattr("distgprl.experiments.safety_layer_evaluation.evaluate_with_repair", broken)
    report = follow.run_and_report(demo_evaluated, "ci", "dbm", "demo", 0)
    assert report == "safety-layer evaluation failed: RuntimeError: simulator lost"


def test_coverage_sorts_finished_runs_into_complete_pending_and_lost(demo_evaluated, tmp_path):
    """A reference with its plain evaluation is pending until evaluated, then complete; a
    trained run whose model is gone is lost."""
    finished = [("dbm", "demo", 0), ("dbm", "gprl", 0)]
    gone = run_dir(demo_evaluated, "ci", "dbm", "gprl", 0)
    gone.mkdir(parents=True)
    write_json(gone / "summary.json", {"summary": {}})
    state = follow.coverage(demo_evaluated, "ci", finished)
    assert (state.complete, state.pending, state.lost) == (
        (),
        ("dbm/demo/seed0",),
        ("dbm/gprl/seed0",),
    )
    follow.run_and_report(demo_evaluated, "ci", "dbm", "demo", 0)
    state = follow.coverage(demo_evaluated, "ci", finished)
    assert state.complete == ("dbm/demo/seed0",) and state.pending == ()
    assert state.describe() == (
        "Table I + repair evaluations: 1 runs complete, 0 pending, 1 without their model on disk"
    )


def test_coverage_counts_methods_without_a_window_plan_apart(tmp_path):
    """ProMP-RRL (residual control) and its nominal have no window plan, so a sweep never
    evaluates them with the safety layer: coverage names them apart, never pending or lost."""
    finished = [("dbm", "promp-rrl", 0), ("dcp", "promp-nominal", 0), ("dbm", "gprl", 0)]
    for task, method, seed in finished:
        folder = run_dir(tmp_path, "ci", task, method, seed)
        folder.mkdir(parents=True)
        write_json(folder / "summary.json", {"summary": {}})
    state = follow.coverage(tmp_path, "ci", finished)
    assert state.not_applicable == ("dbm/promp-rrl/seed0", "dcp/promp-nominal/seed0")
    assert (state.complete, state.pending, state.lost) == ((), (), ("dbm/gprl/seed0",))
    assert state.describe().endswith(
        "0 pending, 1 without their model on disk, 2 without a window plan (not evaluated)"
    )
