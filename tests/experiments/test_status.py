"""Sweep status: each run's state is read correctly from its folder; the training time
left adds each run's steps left at its own or its task's finished pace; the sweep reports
running jobs while they run."""

from __future__ import annotations

import time

import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.experiments import sweep
from distgprl.experiments.results import write_csv, write_json
from distgprl.experiments.runner import PROGRESS_FIELDS, is_locked, resolve_run, run_dir, run_lock
from distgprl.experiments.status import (
    RunStatus,
    count_states,
    run_status,
    sweep_status,
    training_left,
)


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
    assert status.eta_s == pytest.approx(60.0 / step * (total - step))

    # The ETA follows the pace of the latest interval, not the warm-up-heavy pace since step 0.
    _progress(folder, 2 * step, wall_time_s=160.0, earlier=[(0, 1.0), (step, 60.0)])
    status = run_status(job)
    assert status.step == 2 * step
    assert status.eta_s == pytest.approx(100.0 / step * (total - 2 * step))

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


def test_a_finished_run_reports_its_training_pace(tmp_path):
    job = _job(tmp_path)
    folder = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    run = resolve_run("dcp", "gprl-d", 0, "ci")
    done = {"steps": 300, "train_wall_time_s": 60.0, "cpu_s_per_step": 0.15}
    write_json(folder / "done.json", done, kind="done", config_hash=run.hash)
    assert run_status(job).seconds_per_step == pytest.approx(0.2)
    assert run_status(job).cpu_seconds_per_step == pytest.approx(0.15)


def test_training_left_uses_own_pace_else_the_tasks_finished_median(tmp_path):
    jobs = {
        (task, seed): sweep.plan_jobs("ci", ["gprl-d"], [task], [seed], root=tmp_path)[0]
        for task in ("dcp", "dbm")
        for seed in range(4)
    }
    statuses = [
        RunStatus(jobs["dcp", 0], "done", 1000, 1000, seconds_per_step=0.1),
        RunStatus(jobs["dcp", 1], "done", 1000, 1000, seconds_per_step=0.3),
        RunStatus(jobs["dcp", 2], "done", 1000, 1000, seconds_per_step=5.0),
        # started: its own pace, 600 steps left
        RunStatus(jobs["dcp", 3], "partial", 400, 1000, seconds_per_step=0.5),
        # not started: the median finished dcp pace (0.3 s) for all 1000 steps
        RunStatus(jobs["dbm", 0], "missing", 0, 1000),
    ]
    left = training_left(statuses)
    assert (left.runs, left.unestimated) == (2, 1)  # dbm has no finished run
    assert left.seconds == pytest.approx(600 * 0.5)
    statuses[-1] = RunStatus(jobs["dcp", 3], "missing", 0, 1000)
    statuses[-2] = RunStatus(jobs["dbm", 1], "running", 100, 1000, seconds_per_step=2.0)
    left = training_left(statuses)
    assert (left.runs, left.unestimated) == (2, 0)
    assert left.seconds == pytest.approx(1000 * 0.3 + 900 * 2.0)
    assert left.describe(2) == (
        f"training left: 2 runs, {2100 / 3600:.1f} h of one worker "
        f"({2100 / 7200:.1f} h with 2 workers)"
    )
    assert training_left(statuses[:3]).describe() == "training left: none"


def test_training_left_adds_cpu_hours_from_the_finished_runs_cpu_pace(tmp_path):
    """With finished runs that recorded their CPU seconds per step, the remaining training is
    also given as CPU-hours (each unfinished run's steps left at its task's median CPU pace)
    and as hours on that many idle cores; without such runs no CPU figure is made up."""
    jobs = [sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [s], root=tmp_path)[0] for s in range(4)]
    done = [
        RunStatus(jobs[0], "done", 1000, 1000, seconds_per_step=0.4, cpu_seconds_per_step=0.1),
        RunStatus(jobs[1], "done", 1000, 1000, seconds_per_step=0.6, cpu_seconds_per_step=0.3),
        RunStatus(jobs[2], "done", 1000, 1000, seconds_per_step=0.5, cpu_seconds_per_step=0.2),
    ]
    left = training_left([*done, RunStatus(jobs[3], "partial", 400, 1000, seconds_per_step=1.0)])
    assert left.cpu_seconds == pytest.approx(600 * 0.2)
    hours = 600 * 0.2 / 3600
    assert left.describe(2).endswith(f"; {hours:.1f} CPU-hours ({hours / 2:.1f} h on 2 idle cores)")
    old = [RunStatus(j, "done", 1000, 1000, seconds_per_step=0.5) for j in jobs[:3]]
    assert training_left([*old, RunStatus(jobs[3], "missing", 0, 1000)]).cpu_seconds is None


def test_training_left_prefers_the_pace_of_runs_made_on_a_machine_like_this(tmp_path):
    """Where a task has finished runs of this machine's numerics, only they set its pace (a
    run committed from another machine may be twice as slow); else every finished run does,
    and a task without local runs keeps all of its own."""
    jobs = [sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [s], root=tmp_path)[0] for s in range(4)]
    dbm = sweep.plan_jobs("ci", ["gprl-d"], ["dbm"], [0, 1], root=tmp_path)
    statuses = [
        RunStatus(jobs[0], "done", 1000, 1000, seconds_per_step=2.0, numerics="other"),
        RunStatus(jobs[1], "done", 1000, 1000, seconds_per_step=2.0, numerics=""),
        RunStatus(jobs[2], "done", 1000, 1000, seconds_per_step=0.5, numerics="here"),
        RunStatus(jobs[3], "missing", 0, 1000),
        RunStatus(dbm[0], "done", 1000, 1000, seconds_per_step=3.0, numerics="other"),
        RunStatus(dbm[1], "missing", 0, 1000),
    ]
    assert training_left(statuses, numerics="here").seconds == pytest.approx(500 + 3000)
    assert training_left(statuses, numerics="elsewhere").seconds == pytest.approx(2000 + 3000)


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


def test_status_command_prints_every_run_and_the_counts(tmp_path):
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
    assert lines[-2] == "0/6 done, 6 missing"
    # 4 trainable runs (demo trains nothing), no finished run to estimate their pace from
    assert lines[-1].startswith("training left: 4 runs, 0.0 h of one worker")
    assert lines[-1].endswith("4 without an estimate (no finished run of the task)")
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
        ],
    )
    assert result.exit_code == 0, result.output
    assert "dcp/gprl-d/seed0" in result.output and "running" in result.output
    assert "curve success 0.25 collision 0.50" in result.output


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


def test_training_left_borrows_the_pace_of_the_same_task_and_method_from_a_reference(tmp_path):
    """A task without a finished run of its own (a study's first seed) takes the median pace
    of the same task *and method* in ``reference`` (the study's reference preset), wall and
    CPU; another method's reference runs do not set it, and a task with its own finished runs
    keeps its own pace."""
    study = sweep.plan_jobs("ci", ["gprl-d"], ["dcp", "dbm"], [0], root=tmp_path / "study")
    other = sweep.plan_jobs("ci", ["gprl-d", "gprl"], ["dcp"], [0, 1], root=tmp_path / "ref")
    reference = [
        RunStatus(job, "done", 1000, 1000, seconds_per_step=pace, cpu_seconds_per_step=pace / 2)
        for job, pace in zip(other, (0.2, 9.0, 0.4, 9.0), strict=True)  # gprl-d 0.2 / 0.4
    ]
    assert [job.method for job in other] == ["gprl-d", "gprl", "gprl-d", "gprl"]
    statuses = [RunStatus(job, "missing", 0, 1000) for job in study]
    left = training_left(statuses, numerics="", reference=reference)
    assert (left.runs, left.unestimated) == (2, 1)  # dbm: no run of the task anywhere
    assert left.seconds == pytest.approx(1000 * 0.3)
    assert left.cpu_seconds == pytest.approx(1000 * 0.15)
    assert training_left(statuses, numerics="").unestimated == 2  # no reference: as before
    own = RunStatus(study[0], "done", 1000, 1000, seconds_per_step=1.0)
    dcp_again = sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [1], root=tmp_path / "study")[0]
    left = training_left([own, RunStatus(dcp_again, "missing", 0, 1000)], "", reference)
    assert left.seconds == pytest.approx(1000 * 1.0)
