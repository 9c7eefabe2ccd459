"""Sweep status: each run's state is read correctly from its folder; the training time
a started run says where a resume continues from; the sweep reports running jobs while they
run; the status command reports the runs the sweeps into its root asked for."""

from __future__ import annotations

import json
import time

import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.experiments import pace, sweep
from distgprl.experiments.checkpoints import checkpoint_paths
from distgprl.experiments.run_control import run_lock
from distgprl.experiments.status import (
    count_states,
    format_duration,
    run_status,
    sweep_status,
)
from distgprl.identity import resolve_run
from distgprl.io import is_locked
from distgprl.schema import PROGRESS_FIELDS, run_dir, write_csv, write_json


def _job(tmp_path, method="gprl-d", seed=0):
    return sweep.plan_jobs("ci", [method], ["dcp"], [seed], root=tmp_path)[0]


def _progress(folder, step, wall_time_s, success=0.4, collision=0.1, earlier=()):
    """progress.csv with rows at the (step, wall_time_s) pairs ``earlier``, then this one."""
    rows = []
    for row_step, row_wall in [*earlier, (step, wall_time_s)]:
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(
            step=row_step,
            episodes=row_step // 3,
            success_rate=success,
            collision_rate=collision,
            mean_return=1.0,
            min_clearance_p5=0.01,
            wall_time_s=row_wall,
        )
        rows.append(row)
    write_csv(folder / "progress.csv", rows, PROGRESS_FIELDS)


def test_each_state_is_read_from_the_run_folder(tmp_path):
    job = _job(tmp_path)
    folder = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    run = resolve_run("dcp", "gprl-d", 0, "ci")
    total = run.config.run.total_steps
    assert run_status(job).state == "missing"

    write_json(folder / "config.json", {"config_hash": run.hash}, kind="config")
    status = run_status(job)
    assert (status.state, status.step, status.eta_s) == ("partial", 0, None)

    step = total // 4
    _progress(folder, step, wall_time_s=60.0, success=0.35, collision=0.05)
    status = run_status(job)
    assert (status.state, status.step, status.total_steps) == ("partial", step, total)
    assert (status.success_rate, status.collision_rate) == (0.35, 0.05)
    # No checkpoint yet: a resume trains every step again, and the line says so.
    assert status.eta_s == pytest.approx(60.0 / step * total)
    assert f"restarts: no checkpoint yet (it had reached step {step})" in status.describe()

    # With a checkpoint the ETA counts from its step, at the pace of the latest curve
    # interval (not the warm-up-heavy pace since step 0).
    _progress(folder, 2 * step, wall_time_s=160.0, earlier=[(0, 1.0), (step, 60.0)])
    checkpoints = checkpoint_paths(folder)["dir"]
    checkpoints.mkdir()
    (checkpoints / "model.zip").write_bytes(b"x")
    (checkpoints / "manifest.json").write_text(json.dumps({"num_timesteps": step, "files": {}}))
    status = run_status(job)
    assert status.step == 2 * step
    assert status.eta_s == pytest.approx(100.0 / step * (total - step))
    assert f"resumes from its checkpoint of step {step}" in status.describe()

    with run_lock(folder):
        assert is_locked(folder)
        assert run_status(job).state == "running"
    assert not is_locked(folder)

    write_json(folder / "error.json", {"error": "RuntimeError: boom"}, kind="error")
    status = run_status(job)
    assert status.state == "failed" and "boom" in status.describe()

    write_json(folder / "done.json", {"steps": total}, kind="done", config_hash=run.hash)
    assert run_status(job).state == "done" and run_status(job).eta_s is None
    write_json(folder / "done.json", {"steps": total}, kind="done", config_hash="0" * 16)
    assert run_status(job).state == "stale"


def test_durations_read_at_a_glance():
    assert [format_duration(s) for s in (40, 720, 3 * 3600 + 300)] == [
        "40 s",
        "12 min",
        "3 h 05 min",
    ]


def test_a_finished_run_reports_its_training_pace(tmp_path):
    job = _job(tmp_path)
    folder = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    run = resolve_run("dcp", "gprl-d", 0, "ci")
    done = {"steps": 300, "train_wall_time_s": 60.0, "cpu_s_per_step": 0.15}
    write_json(folder / "done.json", done, kind="done", config_hash=run.hash)
    assert run_status(job).seconds_per_step == pytest.approx(0.2)
    assert run_status(job).cpu_seconds_per_step == pytest.approx(0.15)


def test_count_states_lists_done_out_of_all_then_the_others(tmp_path):
    jobs = sweep.plan_jobs("ci", ["gprl-d"], ["dcp", "dbm"], [0, 1], root=tmp_path)
    folder = run_dir(tmp_path, "ci", "dbm", "gprl-d", 1)
    write_json(folder / "config.json", {}, kind="config")
    assert count_states(sweep_status(jobs)) == "0/4 done, 1 partial, 3 missing"


def test_sweep_reports_unfinished_jobs_while_they_run(tmp_path, monkeypatch):
    jobs = sweep.plan_jobs("ci", ["gprl-d"], ["dcp", "dbm"], [0], root=tmp_path)

    def slow_job(job):
        time.sleep(0.3)
        return sweep.JobResult(job, "done", 0.3)

    monkeypatch.setattr(sweep, "run_job", slow_job)
    ticks: list[list[str]] = []
    sweep.run_sweep(jobs, on_tick=lambda todo: ticks.append([j.name for j in todo]), tick_s=0.05)
    assert ticks, "no progress report while the jobs ran"
    assert ticks[0] == [j.name for j in jobs]  # nothing finished at the first report
    assert all(len(t) in (1, 2) for t in ticks)  # finished jobs drop out, the report stops
    count = len(ticks)
    time.sleep(0.2)
    assert len(ticks) == count


def test_a_report_under_way_ends_before_the_sweep_returns(tmp_path, monkeypatch):
    """A slow progress report that began while the last job ran finishes inside run_sweep:
    nothing reports after it returned (a caller may print its summary then)."""
    jobs = sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [0], root=tmp_path)
    monkeypatch.setattr(
        sweep, "run_job", lambda job: (time.sleep(0.3), sweep.JobResult(job, "done", 0.3))[1]
    )
    ticks: list[float] = []

    def slow_report(todo):
        time.sleep(0.25)
        ticks.append(time.monotonic())

    sweep.run_sweep(jobs, on_tick=slow_report, tick_s=0.2)
    returned = time.monotonic()
    time.sleep(0.4)
    assert ticks and all(tick <= returned for tick in ticks)


def test_status_command_prints_every_run_and_the_counts(tmp_path, monkeypatch):
    """Every run and the counts; an empty root is named as such; the training left has an
    estimate for every trainable run (here the default pace: no run measured one)."""
    monkeypatch.setattr(pace, "COMMITTED_RESULTS", tmp_path / "no-committed-results")
    result = CliRunner().invoke(
        app,
        [
            "status",
            "--preset",
            "ci",
            "--methods",
            "demo,gprl-d",
            "--seeds",
            "0,1",
            "--root",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    assert any(line.startswith("dcp/gprl-d/seed1") and "missing" in line for line in lines)
    assert lines[-4] == "0/6 done, 6 missing"
    assert (
        lines[-3]
        == f"no run of the ci preset in {tmp_path} (a sweep into another folder: its --root)"
    )
    # 4 trainable runs (demo trains nothing) of 240 steps, none measured: the default pace
    hours = 4 * 240 * pace.DEFAULT_SECONDS_PER_STEP / 3600
    assert lines[-2].startswith(f"training left: 4 runs, {hours:.1f} h of one worker")
    assert lines[-2].endswith(
        f"paces: 4 at the default pace ({pace.DEFAULT_SECONDS_PER_STEP} s/step)"
    )
    assert lines[-1] == "training done: none"
    bad = CliRunner().invoke(app, ["status", "--seeds", "x", "--root", str(tmp_path)])
    assert bad.exit_code == 2


def test_sweep_command_prints_running_jobs_progress(tmp_path, monkeypatch):
    folder = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    run = resolve_run("dcp", "gprl-d", 0, "ci")
    write_json(folder / "config.json", {"config_hash": run.hash}, kind="config")
    _progress(folder, 30, wall_time_s=3.0, success=0.25, collision=0.5)

    def job_holding_the_lock(job):
        with run_lock(run_dir(job.root, job.preset, job.task, job.method, job.seed)):
            time.sleep(0.5)
        return sweep.JobResult(job, "done", 0.5)

    monkeypatch.setattr(sweep, "run_job", job_holding_the_lock)
    result = CliRunner().invoke(
        app,
        [
            "sweep",
            "--preset",
            "ci",
            "--methods",
            "gprl-d",
            "--tasks",
            "dcp",
            "--seeds",
            "0",
            "--root",
            str(tmp_path),
            "--heartbeat",
            "0.002",
            "--workers",
            "1",
        ],
    )
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert "dcp/gprl-d/seed0: restarts: no checkpoint yet (it had reached step 30)" in lines
    running = [line for line in lines if line.startswith("  dcp/gprl-d/seed0")]
    assert running and "30/240" in running[0]
    assert "curve success 0.25 collision 0.50" in running[0]
    assert any(line.startswith("sweep: 0/1 runs, 30/240 steps, elapsed ") for line in lines)


def test_a_finish_marker_not_of_this_schema_is_damaged_not_stale(tmp_path):
    """A done.json that is not a result of this schema is reported `damaged` with the file
    and the reason (not `stale`, which a sweep would retrain), and has no ETA."""
    job = _job(tmp_path)
    folder = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    folder.mkdir(parents=True)
    (folder / "done.json").write_text('{"meta": {"schema_version": 999}, "steps": 240}')
    status = run_status(job)
    assert status.state == "damaged" and status.eta_s is None
    assert status.error.startswith(f"{folder / 'done.json'}: schema_version 999 is not supported")
    assert count_states([status]) == "0/1 done, 1 damaged"
