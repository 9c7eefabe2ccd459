"""`distgprl.experiments.pace`: every unfinished run's pace comes from the first source that
has one (its own curve, the sweep's runs of its task and method or task, a reference
preset, the committed reference runs, the default), so the training left always adds every
run; the makespan hands jobs out to the workers in order."""

from __future__ import annotations

from collections import Counter

import pytest

from distgprl.experiments import pace, sweep
from distgprl.experiments.pace import (
    DEFAULT_SECONDS_PER_STEP,
    Paces,
    makespan,
    training_done,
    training_left,
)
from distgprl.experiments.run_control import ResumePoint
from distgprl.experiments.status import RunStatus


def _jobs(tmp_path, method="gprl-d", task="dcp", seeds=range(4)):
    return [sweep.plan_jobs("ci", [method], [task], [s], root=tmp_path)[0] for s in seeds]


def test_training_left_uses_own_pace_else_the_sweeps_runs_of_the_task(tmp_path):
    dcp, dbm = _jobs(tmp_path), _jobs(tmp_path, task="dbm")
    statuses = [
        RunStatus(dcp[0], "done", 1000, 1000, seconds_per_step=0.1),
        RunStatus(dcp[1], "done", 1000, 1000, seconds_per_step=0.3),
        RunStatus(dcp[2], "done", 1000, 1000, seconds_per_step=5.0),
        # started: its own pace, 600 steps left
        RunStatus(dcp[3], "partial", 400, 1000, seconds_per_step=0.5),
        # no run of the task measured anything: the default pace for all 1000 steps
        RunStatus(dbm[0], "missing", 0, 1000),
    ]
    left = training_left(statuses, committed=())
    assert (left.runs, left.sources) == (2, Counter(own=1, default=1))
    assert left.seconds == pytest.approx(600 * 0.5 + 1000 * DEFAULT_SECONDS_PER_STEP)
    statuses[-1] = RunStatus(dcp[3], "missing", 0, 1000)
    statuses[-2] = RunStatus(dbm[1], "running", 100, 1000, seconds_per_step=2.0)
    left = training_left(statuses, committed=())
    assert (left.runs, left.sources) == (2, Counter(own=1, sweep=1))
    assert left.seconds == pytest.approx(1000 * 0.3 + 900 * 2.0)  # the median finished dcp pace
    assert left.describe(2) == (
        f"training left: 2 runs, {2100 / 3600:.1f} h of one worker "
        f"({2100 / 7200:.1f} h with 2 workers); paces: 1 at their own pace, "
        "1 at the pace of the sweep's runs of the task"
    )
    assert training_left(statuses[:3]).describe() == "training left: none"


def test_a_run_in_progress_sets_the_pace_of_its_task_and_methods_other_runs(tmp_path):
    """Before any run of a task and method finished, the runs of it in progress set the pace
    of its runs not started; a finished run of the pair takes over from them."""
    jobs = _jobs(tmp_path)
    running = RunStatus(jobs[0], "running", 500, 1000, seconds_per_step=0.2)
    waiting = RunStatus(jobs[1], "missing", 0, 1000)
    paces = Paces([running, waiting], numerics="")
    assert paces.lookup(waiting) == (pytest.approx(0.2), "sweep")
    finished = RunStatus(jobs[2], "done", 1000, 1000, seconds_per_step=0.6)
    assert Paces([running, waiting, finished], "").lookup(waiting)[0] == pytest.approx(0.6)


def test_a_partial_run_without_a_checkpoint_counts_every_step(tmp_path):
    """A run whose curve reached step 400 but has no checkpoint trains all 1000 steps again;
    one with a checkpoint of step 300 trains 700."""
    job = _jobs(tmp_path)[0]
    restarts = RunStatus(
        job, "partial", 400, 1000, seconds_per_step=0.5, resume=ResumePoint(400, None)
    )
    resumes = RunStatus(
        job, "partial", 400, 1000, seconds_per_step=0.5, resume=ResumePoint(400, 300)
    )
    assert training_left([restarts], committed=()).seconds == pytest.approx(1000 * 0.5)
    assert training_left([resumes], committed=()).seconds == pytest.approx(700 * 0.5)


def test_training_left_adds_cpu_hours_from_the_finished_runs_cpu_pace(tmp_path):
    """With finished runs that recorded their CPU seconds per step, the remaining training is
    also given as CPU-hours (each unfinished run's steps left at its task's median CPU pace)
    and as hours on that many idle cores; without such runs no CPU figure is made up."""
    jobs = _jobs(tmp_path)
    done = [
        RunStatus(jobs[0], "done", 1000, 1000, seconds_per_step=0.4, cpu_seconds_per_step=0.1),
        RunStatus(jobs[1], "done", 1000, 1000, seconds_per_step=0.6, cpu_seconds_per_step=0.3),
        RunStatus(jobs[2], "done", 1000, 1000, seconds_per_step=0.5, cpu_seconds_per_step=0.2),
    ]
    partial = RunStatus(jobs[3], "partial", 400, 1000, seconds_per_step=1.0)
    left = training_left([*done, partial], committed=())
    assert left.cpu_seconds == pytest.approx(600 * 0.2)
    hours = 600 * 0.2 / 3600
    assert f"; {hours:.1f} CPU-hours ({hours / 2:.1f} h on 2 idle cores); " in left.describe(2)
    old = [RunStatus(j, "done", 1000, 1000, seconds_per_step=0.5) for j in jobs[:3]]
    missing = RunStatus(jobs[3], "missing", 0, 1000)
    assert training_left([*old, missing], committed=()).cpu_seconds is None


def test_training_done_sums_each_finished_runs_recorded_wall_and_cpu_time(tmp_path):
    """The finished training is each done run's recorded pace times its steps, summed: wall
    time over every done run, CPU time over those that recorded it (said when not all did);
    runs not done and references without steps add nothing."""
    jobs = _jobs(tmp_path)
    statuses = [
        RunStatus(jobs[0], "done", 1000, 1000, seconds_per_step=3.6, cpu_seconds_per_step=1.8),
        RunStatus(jobs[1], "done", 2000, 2000, seconds_per_step=1.8, cpu_seconds_per_step=0.9),
        RunStatus(jobs[2], "running", 500, 1000, seconds_per_step=9.0),
        RunStatus(jobs[3], "done", 0, 0),
    ]
    done = training_done(statuses)
    assert (done.runs, done.cpu_runs) == (2, 2)
    assert (done.seconds, done.cpu_seconds) == (pytest.approx(7200.0), pytest.approx(3600.0))
    assert done.describe() == "training done: 2 runs, 2.0 h of one worker; 1.0 CPU-hours"
    statuses[1] = RunStatus(jobs[1], "done", 2000, 2000, seconds_per_step=1.8)
    assert training_done(statuses).describe() == (
        "training done: 2 runs, 2.0 h of one worker; 0.5 CPU-hours (the 1 that recorded it)"
    )
    assert training_done(statuses[2:]).describe() == "training done: none"


def test_training_left_prefers_the_pace_of_runs_made_on_a_machine_like_this(tmp_path):
    """Where a task has finished runs of this machine's numerics, only they set its pace (a
    run committed from another machine may be twice as slow); else every finished run does,
    and a task without local runs keeps all of its own."""
    jobs, dbm = _jobs(tmp_path), _jobs(tmp_path, task="dbm", seeds=[0, 1])
    statuses = [
        RunStatus(jobs[0], "done", 1000, 1000, seconds_per_step=2.0, numerics="other"),
        RunStatus(jobs[1], "done", 1000, 1000, seconds_per_step=2.0, numerics=""),
        RunStatus(jobs[2], "done", 1000, 1000, seconds_per_step=0.5, numerics="here"),
        RunStatus(jobs[3], "missing", 0, 1000),
        RunStatus(dbm[0], "done", 1000, 1000, seconds_per_step=3.0, numerics="other"),
        RunStatus(dbm[1], "missing", 0, 1000),
    ]
    assert training_left(statuses, "here", committed=()).seconds == pytest.approx(500 + 3000)
    assert training_left(statuses, "elsewhere", committed=()).seconds == pytest.approx(2000 + 3000)


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
    left = training_left(statuses, numerics="", reference=reference, committed=())
    assert left.sources == Counter(reference=1, default=1)  # dbm: no run of the task anywhere
    assert left.seconds == pytest.approx(1000 * 0.3 + 1000 * DEFAULT_SECONDS_PER_STEP)
    assert left.cpu_seconds == pytest.approx(1000 * 0.15)
    assert training_left(statuses, "", committed=()).sources == Counter(default=2)
    own = RunStatus(study[0], "done", 1000, 1000, seconds_per_step=1.0)
    dcp_again = sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [1], root=tmp_path / "study")[0]
    left = training_left([own, RunStatus(dcp_again, "missing", 0, 1000)], "", reference, ())
    assert left.seconds == pytest.approx(1000 * 1.0)


def test_runs_nothing_measured_take_the_committed_reference_runs_pace(tmp_path):
    """The committed runs' pace of the same task and method, else of the task; a task they
    lack takes the default. Without ``committed`` they are read from the checkout's
    committed results (its `paper` preset), here a folder of one finished run."""
    committed = [
        RunStatus(_jobs(tmp_path / "c", "gprl")[0], "done", 1000, 1000, seconds_per_step=0.07),
        RunStatus(_jobs(tmp_path / "c", "gprl-d")[0], "done", 1000, 1000, seconds_per_step=0.05),
    ]
    gprl_d, gprl_h = _jobs(tmp_path, "gprl-d")[0], _jobs(tmp_path, "gprl-h")[0]
    dbm = _jobs(tmp_path, task="dbm")[0]
    statuses = [RunStatus(job, "missing", 0, 1000) for job in (gprl_d, gprl_h, dbm)]
    paces = Paces(statuses, "", committed=committed)
    assert paces.lookup(statuses[0]) == (pytest.approx(0.05), "committed")
    assert paces.lookup(statuses[1]) == (pytest.approx(0.06), "committed")  # the task's median
    assert paces.lookup(statuses[2]) == (DEFAULT_SECONDS_PER_STEP, "default")


def test_committed_statuses_read_the_checkouts_committed_paper_runs(tmp_path, monkeypatch):
    monkeypatch.setattr(pace, "COMMITTED_RESULTS", tmp_path)
    assert pace.committed_statuses() == []
    (tmp_path / "paper").mkdir()
    statuses = pace.committed_statuses()
    assert statuses and {s.job.preset for s in statuses} == {"paper"}
    assert {s.state for s in statuses} == {"missing"}


def test_makespan_hands_queued_jobs_to_the_first_free_worker():
    assert makespan([], [], 2) == 0.0
    assert makespan([10.0], [], 2) == 10.0
    # 2 workers: running 10 and 4; queued 5 goes to the one free at 4 (-> 9), 3 to the one
    # free at 9 (-> 12)
    assert makespan([10.0, 4.0], [5.0, 3.0], 2) == 12.0
    assert makespan([], [5.0, 5.0, 5.0], 1) == 15.0
    assert makespan([], [5.0, 5.0, 5.0], 3) == 5.0
