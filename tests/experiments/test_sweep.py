"""Sweeps: skip finished runs, survive SIGKILL and Ctrl-C, record failures; reports are pure."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from distgprl.errors import UserInputError
from distgprl.experiments import sweep
from distgprl.experiments.jobs import Job
from distgprl.experiments.run_control import run_lock
from distgprl.report.curves import write_curves
from distgprl.report.tables import write_tables
from distgprl.schema import read_csv, read_json, run_dir


def test_plan_validates_names_and_runs_demo_once_per_task():
    jobs = sweep.plan_jobs("ci", ["demo", "dist-gprl"], ["dcp"], [0, 1, 2])
    assert [j.name for j in jobs] == [
        "dcp/demo/seed0",
        "dcp/dist-gprl/seed0",
        "dcp/dist-gprl/seed1",
        "dcp/dist-gprl/seed2",
    ]
    with pytest.raises(UserInputError, match="valid methods"):
        sweep.plan_jobs("ci", ["bogus"], ["dcp"])
    with pytest.raises(UserInputError, match="valid tasks"):
        sweep.plan_jobs("ci", ["demo"], ["bogus"])


@pytest.mark.parametrize(
    ("seeds", "preset", "message"),
    [([-1], "ci", "seed -1"), ([0, 2**32], "ci", "seed 4294967296"), ([0], "nope", "preset")],
)
def test_a_bad_seed_or_preset_is_refused_when_the_sweep_is_planned(
    tmp_path, seeds, preset, message
):
    """`plan_jobs` validates every job as `resolve_run` does, so `sweep --seeds -1` is
    refused input (nothing written), not a failed run."""
    with pytest.raises(UserInputError, match=message):
        sweep.plan_jobs(preset, ["demo", "gprl-d"], ["dcp"], seeds, root=tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_every_planned_job_carries_the_twin_trials_asked_for():
    """The CLI's ``--twin-trials`` reaches every job (only DBM jobs act on it: `trials_due`);
    the default plans none, and a negative count is refused."""
    assert {j.twin_trials for j in sweep.plan_jobs("ci", ["demo", "gprl"], None, [0])} == {0}
    jobs = sweep.plan_jobs("ci", ["demo", "gprl"], None, [0, 1], twin_trials=3)
    assert {j.twin_trials for j in jobs} == {3} and len(jobs) == 6
    with pytest.raises(UserInputError, match="twin_trials"):
        sweep.plan_jobs("ci", ["gprl"], None, [0], twin_trials=-1)


def test_a_repeated_seed_plans_one_job():
    jobs = sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [0, 0, 1])
    assert [j.name for j in jobs] == ["dcp/gprl-d/seed0", "dcp/gprl-d/seed1"]


def test_default_workers_is_one_per_usable_core(monkeypatch):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 2, 5}, raising=False)
    assert sweep.default_workers() == 3


def test_failing_run_is_recorded_and_does_not_stop_the_others(tmp_path, monkeypatch):
    jobs = sweep.plan_jobs("ci", ["demo", "gprl-d"], ["dcp"], [0], root=tmp_path)

    def boom(*args, **kwargs):
        raise RuntimeError("simulated failure")

    monkeypatch.setattr(sweep, "train_run", boom)
    results = sweep.run_sweep(jobs)
    status = {r.job.method: r.status for r in results}
    assert status == {"demo": "done", "gprl-d": "failed"}
    error = read_json(run_dir(tmp_path, "ci", "dcp", "gprl-d", 0) / "error.json")
    assert "simulated failure" in error["error"]
    again = sweep.run_sweep(sweep.plan_jobs("ci", ["demo"], ["dcp"], [0], root=tmp_path))
    assert again[0].status == "skipped"


CRASH_HELPER = """
import os, signal
from distgprl.experiments import sweep

def job_process(job, parent_pid, stop, connection):
    if job.task == "dcp" and job.root.endswith("crash"):  # dies as a segfault or OOM kill would
        os.kill(os.getpid(), signal.SIGKILL)
    if job.task == "dcp" and job.root.endswith("interrupt"):  # Ctrl-C reaches it mid-job
        import threading
        threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT)).start()
    sweep._job_process(job, parent_pid, stop, connection)
"""


def test_a_worker_that_dies_fails_its_own_job_only(tmp_path, monkeypatch):
    """Two workers, three jobs; the process of the first is killed (SIGKILL) mid-job. That
    job is recorded as failed, with the signal in its error.json; the job running beside it
    and the one queued after it still finish, and the sweep itself does not raise."""
    (tmp_path / "crash_helper.py").write_text(CRASH_HELPER)
    monkeypatch.syspath_prepend(str(tmp_path))  # spawned workers get this sys.path
    import crash_helper

    monkeypatch.setattr(sweep, "_job_process", crash_helper.job_process)
    crash, other = str(tmp_path / "crash"), str(tmp_path / "other")
    jobs = [
        Job("dcp", "demo", 0, "ci", crash),
        Job("dbm", "demo", 0, "ci", crash),
        Job("dcp", "demo", 0, "ci", other),
    ]
    results = sweep.run_sweep(jobs, workers=2)
    status = {(r.job.root, r.job.task): r for r in results}
    died = status[(crash, "dcp")]
    assert died.status == "failed" and "killed by signal SIGKILL" in died.error
    error = read_json(run_dir(crash, "ci", "dcp", "demo", 0) / "error.json")
    assert error["error"].startswith("WorkerDied: ") and error["job"]["task"] == "dcp"
    for key in ((crash, "dbm"), (other, "dcp")):
        assert status[key].status == "done"
        folder = run_dir(key[0], "ci", key[1], "demo", 0)
        assert read_json(folder / "summary.json")["summary"]["episodes"] == 6
        assert not (folder / "error.json").exists()


def test_a_job_interrupted_before_the_sweep_interrupts_the_sweep(tmp_path, monkeypatch):
    """A job's process stopped by SIGINT (a terminal's Ctrl-C reaches the whole process
    group, and may reach a job first) stops the sweep as Ctrl-C does: KeyboardInterrupt,
    and no error.json, since nothing failed."""
    (tmp_path / "crash_helper.py").write_text(CRASH_HELPER)
    monkeypatch.syspath_prepend(str(tmp_path))
    import crash_helper

    monkeypatch.setattr(sweep, "_job_process", crash_helper.job_process)
    root = str(tmp_path / "interrupt")
    jobs = [Job("dcp", "demo", 0, "ci", root), Job("dbm", "demo", 0, "ci", root)]
    with pytest.raises(KeyboardInterrupt):
        sweep.run_sweep(jobs, workers=2)
    assert not list(Path(root).rglob("error.json"))


def test_a_finished_run_with_an_unreadable_marker_is_reported_not_retrained(tmp_path):
    """A done.json that is not a result (say, damaged by hand) makes the job `damaged` with
    the reason, from the sweep's first check and from `run_job` alike; the run folder is
    left byte for byte as it was (no retraining over a finished run that has no
    checkpoint)."""
    job = sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [0], root=tmp_path)[0]
    folder = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    folder.mkdir(parents=True)
    (folder / "done.json").write_text('{"steps": 240')
    (folder / "progress.csv").write_text("the finished run's curve\n")
    before = {path.name: path.read_bytes() for path in folder.iterdir()}
    for result in (sweep.run_sweep([job])[0], sweep.run_job(job)):
        assert result.status == "damaged" and "not valid JSON" in result.error
        assert {path.name: path.read_bytes() for path in folder.iterdir()} == before


def test_sweep_command_exits_3_when_runs_were_left_to_another_process(tmp_path, monkeypatch):
    """Busy runs are not complete: the sweep says so and exits 3 (not 0), so `make
    reproduce` does not go on to the tables as if the sweep had finished."""
    from typer.testing import CliRunner

    from distgprl.cli import app

    monkeypatch.setattr(
        sweep, "run_job", lambda job: sweep.JobResult(job, "busy", 0.0, "another process")
    )
    arguments = ["sweep", "--preset", "ci", "--methods", "gprl-d", "--tasks", "dcp"]
    arguments += ["--seeds", "0", "--root", str(tmp_path), "--workers", "1", "--heartbeat", "0"]
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 3, result.output
    assert "0/1 runs complete, 1 left to the other process training them" in result.output


def test_sweep_command_refuses_options_its_jobs_would_not_read(tmp_path, monkeypatch):
    """An option no job of the sweep would read is a user error (exit 2, one line naming what
    to do) before anything runs or is recorded: ``--address`` without ``--executor ray``,
    ``--twin-trials N`` / ``--repair-evaluations`` for a study (no follow-ups),
    ``--twin-trials N`` without a DBM run, ``--repair-evaluations`` for residual-control
    methods only, ``--trial-policy`` with no trials, for a study or without a DBM run (and an
    unknown one). Their defaults, 0 and ``--no-repair-evaluations`` still pass."""
    from typer.testing import CliRunner

    from distgprl.cli import app

    swept = []

    def fake_run_sweep(jobs, workers, executor, address, **kwargs):
        swept.append((jobs, executor, address))
        return []

    monkeypatch.setattr(sweep, "run_sweep", fake_run_sweep)
    base = ["sweep", "--preset", "ci", "--seeds", "0", "--heartbeat", "0"]
    refused = {
        ("--address", "127.0.0.1:6379"): "use it with --executor ray",
        ("--executor", "local", "--address", "auto"): "use it with --executor ray",
        ("--preset", "operators", "--twin-trials", "2"): "a study's runs have no follow-ups",
        ("--preset", "operators", "--repair-evaluations"): "a study's runs have no follow-ups",
        ("--tasks", "dcp", "--twin-trials", "3"): "add dbm to --tasks",
        ("--methods", "demo,gprl", "--tasks", "dcp", "--twin-trials", "1"): "add dbm to --tasks",
        ("--methods", "promp-rrl,promp-nominal", "--repair-evaluations"): "not implemented",
        ("--twin-trials", "0", "--trial-policy", "best"): "give --twin-trials N",
        ("--preset", "operators", "--trial-policy", "best"): "a study's runs have no follow-ups",
        ("--tasks", "dcp", "--trial-policy", "best"): "add dbm to --tasks",
        ("--trial-policy", "latest"): "final, best",
    }
    runner = CliRunner()
    for options, advice in refused.items():
        root = tmp_path / f"refused{len(swept)}"
        result = runner.invoke(app, [*base, "--root", str(root), *options])
        assert result.exit_code == 2, (options, result.output)
        assert len(result.output.strip().splitlines()) == 1 and advice in result.output
        assert not root.exists()
    assert swept == []
    accepted = [
        ("--executor", "ray", "--address", "127.0.0.1:6379"),
        ("--tasks", "dcp"),  # the default --twin-trials: DBM runs only, none here
        ("--tasks", "dcp", "--twin-trials", "0"),
        ("--methods", "gprl", "--tasks", "dbm", "--twin-trials", "3"),
        ("--methods", "promp-rrl"),  # the default --repair-evaluations: via-point methods only
        ("--methods", "promp-rrl", "--no-repair-evaluations"),
        ("--methods", "gprl,promp-rrl", "--tasks", "dcp", "--repair-evaluations"),
        ("--methods", "gprl", "--tasks", "dbm", "--trial-policy", "best"),
    ]
    for options in accepted:
        result = runner.invoke(app, [*base, "--root", str(tmp_path / "ok"), *options])
        assert result.exit_code == 0, (options, result.output)
    assert [(executor, address) for _, executor, address in swept[:2]] == [
        ("ray", "127.0.0.1:6379"),
        ("local", None),
    ]
    assert {job.twin_trials for job in swept[3][0]} == {3}
    assert {job.trial_policy for job in swept[3][0]} == {"final"}  # Table II's, by default
    assert {job.trial_policy for job in swept[-1][0]} == {"best"}


def _children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid`` (from /proc)."""
    children = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            children.append(int(stat.parent.name))
    return children


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_run_lock_refuses_a_second_trainer_of_the_same_run(tmp_path):
    folder = tmp_path / "run"
    with run_lock(folder):
        with pytest.raises(UserInputError, match="another process is training"):
            with run_lock(folder):
                pass
    with run_lock(folder):  # released when the holder is done
        pass


@pytest.mark.parametrize("locked_when", ["before the job starts", "after the job's check"])
def test_a_run_another_process_trains_is_reported_busy_and_left_alone(
    tmp_path, monkeypatch, locked_when
):
    job = sweep.plan_jobs("ci", ["gprl-d"], ["dcp"], [0], root=tmp_path)[0]
    folder = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    folder.mkdir(parents=True)
    (folder / "progress.csv").write_text("the other process's file\n")
    holder = subprocess.Popen(  # another process holding the run's lock, as a trainer does
        [
            sys.executable,
            "-c",
            "import sys, time\n"
            "from distgprl.experiments.run_control import run_lock\n"
            "with run_lock(__import__('pathlib').Path(sys.argv[1])):\n"
            "    print('locked', flush=True); time.sleep(60)",
            str(folder),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        if locked_when == "after the job's check":  # the lock is taken in between
            monkeypatch.setattr(sweep, "is_locked", lambda folder: False)
        before = {path.name: path.read_bytes() for path in folder.iterdir()}
        result = sweep.run_job(job)
        assert (result.status, result.error) == ("busy", "another process is training this run")
        assert {path.name: path.read_bytes() for path in folder.iterdir()} == before
    finally:
        holder.kill()
        holder.wait()


def _interrupt(process: subprocess.Popen, how: str) -> None:
    if how == "SIGKILL":
        process.send_signal(signal.SIGKILL)
    elif how == "Ctrl-C":  # the terminal signals the whole foreground process group
        os.killpg(process.pid, signal.SIGINT)
    elif how == "SIGTERM":  # e.g. `kill PID`: the sweep process alone
        process.send_signal(signal.SIGTERM)
    else:  # "SIGINT": the sweep process alone; its workers must be stopped by it
        process.send_signal(signal.SIGINT)


def _start_dispositions(how: str):
    """The signal dispositions the sweep starts with, whatever pytest was started with.

    "SIGINT" is sent to a sweep started in the background by a script (``nohup distgprl
    sweep ... &``): such a process inherits SIGINT *ignored*, its workers too. The others
    start as from a terminal, with the default dispositions.
    """
    ignored = signal.SIG_IGN if how == "SIGINT" else signal.SIG_DFL

    def set_dispositions() -> None:
        signal.signal(signal.SIGINT, ignored)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)

    return set_dispositions


@pytest.mark.parametrize("how", ["SIGKILL", "Ctrl-C", "SIGINT", "SIGTERM"])
def test_killed_sweep_completes_on_restart_without_lost_or_duplicated_runs(tmp_path, how):
    command = [
        sys.executable,
        "-m",
        "distgprl.cli",
        "sweep",
        "--preset",
        "ci",
        "--tasks",
        "dcp",
        "--methods",
        "demo,gprl-d",
        "--seeds",
        "0,1,2",
        "--root",
        str(tmp_path),
        "--workers",
        "2",
    ]
    env = {**os.environ, "DISTGPRL_CHECKPOINT_ROOT": ""}
    process = subprocess.Popen(
        command,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=_start_dispositions(how),
    )
    first = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    deadline = time.time() + 300
    # Interrupt mid-run: after the first trained run's first checkpoint, before it
    # finishes; seed 2 is still queued (two workers: demo then seed 1, and seed 0).
    while time.time() < deadline and not (first / "checkpoints" / "state.pkl").exists():
        time.sleep(0.2)
    assert (first / "checkpoints" / "state.pkl").exists(), "no checkpoint within 300 s"
    workers = _children(process.pid)
    assert workers, "the sweep runs its jobs in worker processes"
    _interrupt(process, how)
    # An orderly stop unwinds both jobs (logger, progress bar) and joins them: seconds on an
    # idle machine, but a minute and more for a niced CI starved by other jobs on its cores
    # (a 60 s limit failed once so, session 24). The limit only bounds a real hang.
    _, stderr = process.communicate(timeout=240)
    if how != "SIGKILL":  # an orderly stop: exit code 130 and a line saying how to resume
        assert process.returncode == 130
        assert "sweep interrupted" in stderr and "re-run the same command" in stderr
    # Its workers exit too, instead of training on (or starting queued runs) as orphans.
    deadline = time.time() + 120
    while time.time() < deadline and any(_alive(pid) for pid in workers):
        time.sleep(0.2)
    assert not any(_alive(pid) for pid in workers)
    for seed in (0, 1):  # the running runs were stopped, not finished
        assert not (run_dir(tmp_path, "ci", "dcp", "gprl-d", seed) / "done.json").exists()
    assert not (run_dir(tmp_path, "ci", "dcp", "gprl-d", 2) / "config.json").exists()
    result = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "4/4 runs complete" in result.stdout
    for seed in (0, 1, 2):
        folder = run_dir(tmp_path, "ci", "dcp", "gprl-d", seed)
        done = read_json(folder / "done.json")
        assert done["steps"] == 240
        if seed == 0:  # resumed from its checkpoint, not restarted from scratch
            # a checkpoint at 120 (or the end of the episode it falls in, v5) or at 240
            [resumed] = [r["step"] for r in done["resumes"]]
            assert 120 <= resumed < 123 or resumed == 240
            assert all(r["exact"] for r in done["resumes"])
        _, progress = read_csv(folder / "progress.csv")
        steps = [int(r["step"]) for r in progress]
        assert steps == sorted(set(steps)) == [0, 120, 240]
        _, rows = read_csv(folder / "evaluation.csv")
        assert len(rows) == 6
    leftovers = [p for p in tmp_path.rglob("*.tmp*")]
    assert leftovers == []
    if how != "SIGKILL":  # once: the resumed runs are checked above for every way of stopping
        return
    # Tables and curves are pure functions of the result files.
    out_a, out_b = tmp_path / "fig_a", tmp_path / "fig_b"
    files_a = write_tables(tmp_path, "ci", out_a) + write_curves(tmp_path, "ci", out_a)
    files_b = write_tables(tmp_path, "ci", out_b) + write_curves(tmp_path, "ci", out_b)
    assert [p.name for p in files_a] == [p.name for p in files_b]
    for a, b in zip(files_a, files_b, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name
    table = (out_a / "table1_ci.md").read_text()
    assert "GPRL-D" in table and "Demo (no adaptation)" in table
    assert "[3]" in table


def test_ray_executor_runs_the_same_jobs_on_a_local_ray_instance(tmp_path, monkeypatch):
    """On a local Ray instance: an evaluation job and a training job finish as locally
    (the results root is passed on absolute: here a relative one), a task whose worker
    dies (every time: after its retries, `ray_executor.MAX_RETRIES`) is recorded as failed
    with its error.json and stops nothing else, and a second sweep skips the finished runs."""
    import ray  # installed by `make setup` (extra `distgprl[ray]`)

    def run_job(job):  # pickled by value: the Ray worker's own `sweep.run_job` is the real one
        import os

        from distgprl.experiments import sweep as worker_sweep

        if job.task == "dbm":
            os._exit(9)  # the worker process dies, as on a crash or an OOM kill
        return worker_sweep.run_job(job)

    real_run_job = sweep.run_job
    monkeypatch.setattr(sweep, "run_job", run_job)
    monkeypatch.chdir(tmp_path)
    jobs = sweep.plan_jobs("ci", ["demo", "gprl-d"], ["dcp", "dbm"], [0], root="results")
    results = sweep.run_sweep(jobs, workers=2, executor="ray")
    assert not ray.is_initialized()
    assert sorted((r.job.name, r.status) for r in results) == [
        ("dbm/demo/seed0", "failed"),
        ("dbm/gprl-d/seed0", "failed"),
        ("dcp/demo/seed0", "done"),
        ("dcp/gprl-d/seed0", "done"),
    ]
    assert {r.job.root for r in results} == {"results"}  # the jobs as planned
    for method in ("demo", "gprl-d"):
        folder = run_dir("results", "ci", "dcp", method, 0)
        assert read_json(folder / "summary.json")["summary"]["episodes"] == 6
        error = read_json(run_dir("results", "ci", "dbm", method, 0) / "error.json")
        assert "Worker" in error["error"] or "Crash" in error["error"], error["error"]
    assert read_json(run_dir("results", "ci", "dcp", "gprl-d", 0) / "done.json")["steps"] == 240
    monkeypatch.setattr(sweep, "run_job", real_run_job)
    again = sweep.run_sweep(sweep.plan_jobs("ci", ["demo", "gprl-d"], ["dcp"], [0], "results"))
    assert {r.status for r in again} == {"skipped"}
