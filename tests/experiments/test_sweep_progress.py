"""`distgprl.experiments.sweep_progress`: the sweep says what it found done (and how to train
it again) and where each started run resumes; its line counts runs and steps and gives an
ETA from the measured pace of each task and method plus the jobs' measured time beyond
training; on a terminal it redraws in place, elsewhere it prints plain lines."""

from __future__ import annotations

import io
import shutil

import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.experiments import sweep
from distgprl.experiments.pace import DEFAULT_SECONDS_PER_STEP
from distgprl.experiments.run_control import ResumePoint
from distgprl.experiments.status import RunStatus
from distgprl.experiments.sweep_progress import SweepProgress, format_steps
from distgprl.identity import resolve_run
from distgprl.machine import machine_info
from distgprl.schema import run_dir, write_json

HERE = machine_info()["numerics"]  # the machine the finished runs of these tests record


class Clock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


def _finish(root, task, method, seed=0, wall_s=24.0, preset="ci"):
    """A finished run folder (``done.json`` of the current config) trained in ``wall_s``."""
    run = resolve_run(task, method, seed, preset)
    steps = run.config.run.total_steps
    done = {"steps": steps, "train_wall_time_s": wall_s}
    folder = run_dir(root, preset, task, method, seed)
    write_json(folder / "done.json", done, kind="done", config_hash=run.hash)
    return folder


def _progress(jobs, stream=None, live=False, workers=1):
    return SweepProgress(
        jobs, workers, stream or io.StringIO(), live, Clock(), numerics=HERE, committed=()
    )


def test_step_counts_read_at_a_glance():
    assert [format_steps(n) for n in (950, 90_000, 2_625_000)] == ["950", "90.0k", "2.62M"]


def test_the_opening_says_what_is_done_how_to_retrain_and_where_runs_resume(tmp_path):
    jobs = sweep.plan_jobs("ci", ["gprl-d", "gprl"], ["dcp"], [0, 1], root=tmp_path)
    folder = _finish(tmp_path, "dcp", "gprl-d")
    stale = _finish(tmp_path, "dcp", "gprl", seed=1)
    write_json(stale / "done.json", {"steps": 240}, kind="done", config_hash="0" * 16)
    started = run_dir(tmp_path, "ci", "dcp", "gprl-d", 1)
    write_json(started / "config.json", {}, kind="config")
    lines = _progress(jobs).opening(tmp_path)
    assert lines == [
        f"already done: 1 of 4 runs in {tmp_path / 'ci'} (skipped); to train them again, "
        "sweep into another results folder (e.g. --root runs) or delete a run's folder "
        f"(e.g. {folder})",
        "1 runs finished with another configuration: trained anew",
        "dcp/gprl-d/seed1: restarts: no checkpoint yet",
    ]


def test_the_sweep_line_counts_runs_and_steps_and_its_eta_follows_the_measured_pace(tmp_path):
    """ETA: each unfinished run's steps at the pace of the sweep's runs of its task and
    method (here 0.5 s/step finished; the running one at its own 1 s/step), on the workers
    in order; after a job finished, its time beyond training is added to every run left."""
    jobs = sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [0, 1, 2], root=tmp_path)
    progress = _progress(jobs)
    done, running, waiting = jobs
    progress.statuses[done] = RunStatus(done, "done", 240, 240, seconds_per_step=0.5, numerics=HERE)
    progress.statuses[running] = RunStatus(running, "running", 120, 240, seconds_per_step=1.0)
    progress.unfinished = [running, waiting]
    progress.clock.now += 125
    assert progress.eta_s() == pytest.approx(120 * 1.0 + 240 * 0.5)
    assert progress.summary() == ("sweep: 1/3 runs, 360/720 steps, elapsed 2 min, ETA 4 min")
    assert progress.running_line(progress.statuses[running]).endswith("2 min left")
    _finish(tmp_path, "dcp", "gprl-d", seed=1, wall_s=240.0)  # 1 s/step
    progress.finished(sweep.JobResult(running, "done", 300.0), 2, 3)  # 60 s beyond training
    # the pair's median finished pace is now 0.75 s/step
    assert progress.eta_s() == pytest.approx(240 * 0.75 + 60.0)


def test_the_eta_counts_the_references_left_at_their_tasks_measured_time(tmp_path):
    """An untrained reference trains nothing but still takes time (evaluation, twin trials):
    each job left adds the median time beyond training of its task's finished jobs, of every
    task's while its own has none (so the ETA is not 0 s while references are left)."""
    jobs = sweep.plan_jobs("ci", ["demo", "gprl-d"], ["dcp", "dbm"], [0], root=tmp_path)
    by_name = {job.name: job for job in jobs}
    progress = _progress(jobs)
    _finish(tmp_path, "dbm", "gprl-d", wall_s=120.0)  # 0.5 s/step
    progress.finished(sweep.JobResult(by_name["dbm/gprl-d/seed0"], "done", 150.0), 1, 4)
    write_json(
        run_dir(tmp_path, "ci", "dbm", "demo", 0) / "summary.json",
        {"summary": {}},
        kind="summary",
        config_hash=resolve_run("dbm", "demo", 0, "ci").hash,
    )
    progress.finished(sweep.JobResult(by_name["dbm/demo/seed0"], "done", 40.0), 2, 4)
    assert progress.overhead_s("dbm") == pytest.approx((30.0 + 40.0) / 2)
    assert progress.overhead_s("dcp") == pytest.approx(35.0)  # no dcp job finished: all tasks
    progress.unfinished = [by_name["dcp/demo/seed0"], by_name["dcp/gprl-d/seed0"]]
    # one worker: the dcp demo's 35 s, then the dcp run's 240 steps at the default pace (no
    # dcp run measured, none committed here) and 35 s
    assert progress.eta_s() == pytest.approx(35.0 + 240 * DEFAULT_SECONDS_PER_STEP + 35.0)


def test_runs_done_with_follow_ups_due_count_in_the_line_and_the_eta(tmp_path, monkeypatch):
    """A sweep of runs done already whose follow-ups are due (here twin trials): the line
    counts the follow-ups done of all, and the ETA is the median finished follow-up's time per
    one left (0 s before one has finished), not 0 s because no training is left."""
    from distgprl.experiments import sweep_progress

    jobs = sweep.plan_jobs("ci", ["gprl-d"], ["dbm"], [0, 1, 2], root=tmp_path, twin_trials=1)
    for job in jobs:
        _finish(tmp_path, "dbm", "gprl-d", seed=job.seed)
    monkeypatch.setattr(sweep_progress, "follow_up_due", lambda job: job.seed != 2)
    progress = _progress(jobs)
    assert progress.follow_ups == set(jobs[:2]) and progress.eta_s() == 0.0
    assert progress.summary().startswith("sweep: 3/3 runs, 720/720 steps, follow-ups 0/2, ")
    progress.finished(sweep.JobResult(jobs[0], "skipped", 90.0, trials="twin trials: 3"), 1, 3)
    progress.unfinished = jobs[1:]
    assert progress.eta_s() == pytest.approx(90.0)  # one left; the run without follow-ups: none
    assert progress.summary().endswith("follow-ups 1/2, elapsed 0 s, ETA 1 min")
    progress.finished(sweep.JobResult(jobs[1], "skipped", 70.0, trials="twin trials: 3"), 2, 3)
    progress.unfinished = jobs[2:]
    assert progress.eta_s() == 0.0 and "follow-ups 2/2" in progress.summary()


def test_plain_output_prints_each_finished_job_with_the_sweeps_line(tmp_path):
    jobs = sweep.plan_jobs("ci", ["gprl-d"], ["dcp", "dbm"], [0], root=tmp_path)
    stream = io.StringIO()
    _finish(tmp_path, "dcp", "gprl-d")
    progress = _progress(jobs, stream)
    progress.finished(sweep.JobResult(jobs[0], "skipped", 0.0), 1, 2)  # in the opening already
    assert stream.getvalue() == ""
    _finish(tmp_path, "dbm", "gprl-d")
    result = sweep.JobResult(
        jobs[1], "done", 30.0, resumed="resumed from its checkpoint of step 120"
    )
    progress.finished(result, 2, 2)
    lines = stream.getvalue().splitlines()
    assert lines[0] == (
        "[2/2] dbm/gprl-d/seed0: done in 30 s (resumed from its checkpoint of step 120)"
    )
    assert lines[1].startswith("  sweep: 2/2 runs, 480/480 steps, elapsed ")
    assert "\r" not in stream.getvalue()
    progress.heartbeat()
    assert stream.getvalue().splitlines()[2].startswith("sweep: 2/2 runs")
    # a job that found its run done when it ran (not when the sweep started) says so
    progress.finished(sweep.JobResult(jobs[1], "skipped", 0.0), 2, 2)
    assert stream.getvalue().splitlines()[3] == "[2/2] dbm/gprl-d/seed0: skipped in 0 s"


def test_a_terminal_gets_one_display_redrawn_with_a_line_per_running_job(tmp_path):
    jobs = sweep.plan_jobs("ci", ["gprl-d"], ["dcp", "dbm"], [0], root=tmp_path)
    stream = io.StringIO()
    progress = _progress(jobs, stream, live=True, workers=2)
    progress.statuses[jobs[0]] = RunStatus(jobs[0], "running", 120, 240, seconds_per_step=1.0)
    progress._draw()
    text = stream.getvalue()
    assert "\r" in text  # redrawn in place
    assert "sweep: 0/2 runs, 120/480 steps" in text
    assert "dcp/gprl-d/seed0" in text and "2 min left" in text
    progress.close()
    assert progress._bars == []


def test_a_partial_run_counts_the_steps_of_its_checkpoint_only(tmp_path):
    """A run whose curve reached step 120 without a checkpoint has done no resumable step."""
    job = sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [0], root=tmp_path)[0]
    progress = _progress([job])
    progress.statuses[job] = RunStatus(
        job, "partial", 120, 240, seconds_per_step=1.0, resume=ResumePoint(120, None)
    )
    assert progress.summary().startswith("sweep: 0/1 runs, 0/240 steps")
    assert progress.eta_s() == pytest.approx(240.0)


def test_a_sweep_of_runs_done_already_says_so_and_how_to_train_them_again(tmp_path, monkeypatch):
    """The README's main job on a root whose runs are done (the committed results): one line
    with the count and how to retrain, no line per skipped run, exit 0; deleting a run's
    folder as it says trains that run."""
    for task in ("dcp", "dbm"):
        _finish(tmp_path, task, "gprl-d")
    trained = []

    def fake_job(job):
        trained.append(job.name)
        _finish(tmp_path, job.task, job.method)
        return sweep.JobResult(job, "done", 1.0)

    monkeypatch.setattr(sweep, "run_job", fake_job)
    arguments = ["sweep", "--preset", "ci", "--methods", "gprl-d", "--seeds", "0"]
    arguments += ["--root", str(tmp_path), "--workers", "1", "--no-repair-evaluations"]
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[1].startswith(f"already done: 2 of 2 runs in {tmp_path / 'ci'} (skipped); ")
    assert "delete a run's folder" in lines[1] and "--root" in lines[1]
    assert not any("skipped in" in line for line in lines) and trained == []

    shutil.rmtree(run_dir(tmp_path, "ci", "dbm", "gprl-d", 0))
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 0, result.output
    assert trained == ["dbm/gprl-d/seed0"]
    assert "already done: 1 of 2 runs" in result.output
