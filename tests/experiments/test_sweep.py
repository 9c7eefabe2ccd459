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
from distgprl.experiments.results import read_csv, read_json
from distgprl.experiments.runner import run_dir, run_lock
from distgprl.report.curves import write_curves
from distgprl.report.tables import write_tables


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
            "from distgprl.experiments.runner import run_lock\n"
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
    _, stderr = process.communicate(timeout=60)
    if how != "SIGKILL":  # an orderly stop: exit code 130 and a line saying how to resume
        assert process.returncode == 130
        assert "sweep interrupted" in stderr and "re-run the same command" in stderr
    # Its workers exit too, instead of training on (or starting queued runs) as orphans.
    deadline = time.time() + 30
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
            assert [r["step"] for r in done["resumes"]] in ([120], [240])
            assert all(r["exact"] for r in done["resumes"])
        _, progress = read_csv(folder / "progress.csv")
        steps = [int(r["step"]) for r in progress]
        assert steps == sorted(set(steps)) == [0, 120, 240]
        _, rows = read_csv(folder / "evaluation.csv")
        assert len(rows) == 6
    leftovers = [p for p in tmp_path.rglob("*.tmp*")]
    assert leftovers == []
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


def test_ray_executor_runs_the_same_jobs_on_a_local_ray_instance(tmp_path):
    import ray  # installed by `make setup` (extra `distgprl[ray]`)

    jobs = sweep.plan_jobs("ci", ["demo"], ["dcp", "dbm"], [0], root=tmp_path)
    results = sweep.run_sweep(jobs, workers=2, executor="ray")
    assert not ray.is_initialized()
    assert sorted((r.job.name, r.status) for r in results) == [
        ("dbm/demo/seed0", "done"),
        ("dcp/demo/seed0", "done"),
    ]
    for job in jobs:
        folder = run_dir(tmp_path, "ci", job.task, job.method, job.seed)
        assert read_json(folder / "summary.json")["summary"]["episodes"] == 6
    again = sweep.run_sweep(jobs, executor="ray")
    assert {r.status for r in again} == {"skipped"}
