"""`distgprl sweep`: every (task, method, seed) as an independent, resumable job.

- A job whose run folder has ``done.json`` with the same config hash is skipped.
- A job whose run folder has a checkpoint resumes from it; one with only a config starts
  over (its partial files are replaced atomically).
- Worker processes exit when the sweep process dies, and a run folder is locked while it
  trains, so a restarted sweep never trains the same run twice at once.
- Interrupting the sweep (Ctrl-C, SIGINT or SIGTERM to the sweep process) starts no
  further job and stops the running ones as a kill would (their last checkpoints stay, to
  resume from); this holds for a sweep started in the background too
  (`stop_on_interrupt_signals`).
- A failing job writes ``error.json`` (type, message, traceback) into its run folder and
  the sweep goes on; the next sweep retries it. With ``workers > 1`` each job runs in a
  process of its own, so a worker that dies (a crash in native code, the OOM killer, a
  signal) fails its own job only: the sweep writes that job's ``error.json`` (exit code or
  signal) and goes on with the others. On Ray, a task whose process or node was lost is
  retried on another node, resuming its run from its checkpoint, and recorded the same way
  once its retries are spent; a lost head stops the sweep (`distgprl.experiments.
  ray_executor`).
- A damaged run (`distgprl.runstate`: a result file not readable as a result
  of this schema, or the evaluation of a finished run gone) is reported ``damaged`` with
  the file and the reason and left alone, never retrained over (that would discard a
  finished run whose checkpoints are gone, e.g. a committed one on a fresh clone) unless
  the sweep is told to (``retrain_damaged``: its folder is removed and it trains anew).
- A job whose run another process is training (its folder is locked) is reported ``busy``
  and left to that process; nothing is written. So two sweeps of overlapping jobs can run
  side by side (e.g. one per CPU core, in different orders), each training what the other
  is not.
- The untrained references (`demo`, `promp-nominal`) are evaluated once per task (seed 0);
  they have no training.
- With ``twin_trials`` (`distgprl sweep --twin-trials N`), a DBM job also runs the digital-
  twin trials Table II counts for its policy (`distgprl.experiments.table2_trials`), in the
  same process, right after training: a policy's weights are not committed, so its trials
  must run where it was trained. A finished DBM run whose ``model.zip`` is still on disk and
  whose trials are missing is picked up again for them alone; trials that fail are reported
  with the job (``trials`` of its result) and leave the run done.
- With ``repair_evaluations`` (`distgprl sweep --repair-evaluations`, on by default), every
  finished run is also evaluated with the hardware safety layer in the loop (check only,
  and retime-then-refuse; `distgprl.experiments.repair_follow_ups`), for the same reason
  and in the same way: right after training, or later for a finished run whose model is
  still on disk; the report is ``repairs`` of the job's result.

Executors: ``local`` (worker processes on this machine) and ``ray`` (the same job
function submitted to a Ray cluster; optional extra ``distgprl[ray]``).
"""

from __future__ import annotations

import _thread
import os
import pickle
import shutil
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Generator, Sequence
from dataclasses import asdict, dataclass, replace
from multiprocessing import get_context
from multiprocessing.connection import wait as wait_for_any
from pathlib import Path
from typing import cast

from distgprl.data import TASK_NAMES, check_task_name
from distgprl.errors import RunBusyError, UserInputError
from distgprl.experiments.checkpoints import checkpoint_dir, trained_steps
from distgprl.experiments.evaluation import evaluate_run
from distgprl.experiments.follow_ups import (
    follow_up_due,
    run_follow_ups,
)
from distgprl.experiments.jobs import Job
from distgprl.experiments.policies import ship_if_missing
from distgprl.experiments.run_control import describe_resume
from distgprl.experiments.training import train_run
from distgprl.identity import SWEEP_SEEDS, check_seed, resolve_run
from distgprl.io import is_locked
from distgprl.methods import TABLE_ORDER, get_method
from distgprl.runstate import job_state
from distgprl.schema import run_dir, write_json
from distgprl.studies import get_study, is_study
from distgprl.trial_protocol import TABLE2_POLICY, check_trial_policy


@dataclass(frozen=True)
class JobResult:
    job: Job
    # "done", "skipped", "busy" (another process trains it), "failed", "damaged" (left alone)
    status: str
    seconds: float
    error: str = ""
    trials: str = ""  # what the Table II twin trials did (empty: none were due)
    repairs: str = ""  # what the safety-layer evaluations did (empty: none were due)
    resumed: str = ""  # where a run this job continued was resumed from (empty: a fresh run)


def plan_jobs(
    preset: str,
    methods: Sequence[str] | None = None,
    tasks: Sequence[str] | None = None,
    seeds: Sequence[int] | None = None,
    root: str | Path = "results",
    twin_trials: int = 0,
    repair_evaluations: bool = False,
    trial_policy: str = TABLE2_POLICY,
) -> list[Job]:
    """All jobs of a sweep: seed by seed, methods in the given order (default: table order),
    tasks innermost. An untrained reference (`demo`, `promp-nominal`) runs once (seed 0),
    with the first seed's jobs. ``twin_trials``: trials per Table II setting each DBM job
    runs after training (0: none), of the trained policy ``trial_policy`` names
    (`distgprl.trial_protocol.TRIAL_POLICIES`); ``repair_evaluations``: each job also
    evaluates its run with the safety layer in the loop.

    Every name, seed and the preset are validated first (`resolve_run` for every job), so
    a bad request is a `UserInputError` before anything touches the disk.

    ``preset`` may name a study (`distgprl.studies`): the jobs are then its readings' presets'
    for the study's methods (or ``methods``), seed by seed across the readings, with no
    follow-ups (the twin trials and safety-layer evaluations are Table I's, not a study's).

    ``seeds`` None: `SWEEP_SEEDS` for a preset; for a study `Study.planned_runs` (its seeds,
    then its rules' further runs). Given seeds are exactly those, for every reading."""
    if is_study(preset):  # its readings' runs seed by seed, then its rules' (`planned_runs`)
        runs = get_study(preset).planned_runs(methods, tasks or TASK_NAMES, seeds)
        jobs = [
            replace(job, named_with_preset=True)
            for member, method, task, seed in runs
            for job in plan_jobs(member, [method], [task], [seed], root)
        ]
        if not jobs:
            raise UserInputError("no seeds given")
        return list({(j.preset, j.task, j.method, j.seed): j for j in jobs}.values())
    seeds = SWEEP_SEEDS if seeds is None else seeds
    methods = list(methods or TABLE_ORDER)
    tasks = list(tasks or TASK_NAMES)
    for method in methods:
        get_method(method)
    for task in tasks:
        check_task_name(task)
    if not seeds:
        raise UserInputError("no seeds given")
    if twin_trials < 0:
        raise UserInputError(f"twin_trials must be >= 0, got {twin_trials}")
    check_trial_policy(trial_policy)
    # a repeated seed: one job
    seeds = list(dict.fromkeys(check_seed(seed) for seed in seeds))
    jobs = []
    # Seeds outermost, then methods, then tasks: an interrupted sweep has one seed of every
    # method on every task before it starts on the next seed.
    for seed in seeds:
        for method in methods:
            if not get_method(method).trainable and seed != seeds[0]:
                continue
            for task in tasks:
                jobs.append(
                    Job(
                        task,
                        method,
                        0 if not get_method(method).trainable else int(seed),
                        preset,
                        str(root),
                        int(twin_trials),
                        bool(repair_evaluations),
                        trial_policy=trial_policy,
                    )
                )
    for job in jobs:
        resolve_run(job.task, job.method, job.seed, job.preset)
    return jobs


def default_workers() -> int:
    """One job per CPU core this process may run on (each job trains on one torch thread)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not on Linux
        return max(os.cpu_count() or 1, 1)


def is_complete(job: Job) -> bool:
    """True if the job's run folder holds a finished, undamaged run of the same
    configuration (`job_state` is ``done``)."""
    return job_state(job.root, job.preset, job.task, job.method, job.seed).verdict == "done"


def finished_result(job: Job) -> JobResult | None:
    """The job's result if there is nothing to run: "skipped" (`job_state` ``done``) or
    "damaged" (reported with the file and reason, never retrained over); None if it has
    to run."""
    state = job_state(job.root, job.preset, job.task, job.method, job.seed)
    if state.verdict == "done":
        return JobResult(job, "skipped", 0.0)
    if state.verdict == "damaged":
        return JobResult(job, "damaged", 0.0, state.describe())
    return None


def clear_damaged(job: Job) -> bool:
    """Remove a damaged run's folder (and its checkpoints) so that it trains anew; False
    (nothing removed) if the run is not damaged or a process is training it."""
    folder = run_dir(job.root, job.preset, job.task, job.method, job.seed)
    state = job_state(job.root, job.preset, job.task, job.method, job.seed)
    if state.verdict != "damaged" or is_locked(folder):
        return False
    shutil.rmtree(checkpoint_dir(folder), ignore_errors=True)
    shutil.rmtree(folder)
    return True


def run_job(job: Job) -> JobResult:
    """Run one job to completion (resuming if possible); never raises for a run failure."""
    import torch

    torch.set_num_threads(1)
    start = time.perf_counter()
    finished = finished_result(job)
    if finished is not None:
        if finished.status == "skipped" and get_method(job.method).trainable:
            ship_if_missing(run_dir(job.root, job.preset, job.task, job.method, job.seed))
        if finished.status == "skipped" and follow_up_due(job):
            reports = run_follow_ups(job)
            return replace(finished, seconds=time.perf_counter() - start, **reports)
        return finished
    folder = run_dir(job.root, job.preset, job.task, job.method, job.seed)
    busy = JobResult(job, "busy", 0.0, "another process is training this run")
    if is_locked(folder):
        return busy
    resumed = ""
    try:
        if get_method(job.method).trainable:
            resume = (folder / "config.json").exists()
            reached = trained_steps(folder / "progress.csv") if resume else 0
            train_run(
                job.task,
                job.method,
                job.seed,
                job.preset,
                resume=resume,
                root=job.root,
                show_progress=False,
            )
            ship_if_missing(folder)  # Table I's actor, committed with the run's small files
            resumed = describe_resume(folder, reached)
        else:
            evaluate_run(
                job.task, job.method, job.seed, job.preset, root=job.root, show_progress=False
            )
    except RunBusyError:  # locked between the check above and train_run's lock
        return busy
    except Exception as exc:  # recorded, the sweep goes on
        message = f"{type(exc).__name__}: {exc}"
        return record_failure(job, message, traceback.format_exc(), time.perf_counter() - start)
    error_file = folder / "error.json"
    if error_file.exists():
        error_file.unlink()
    follow_ups = run_follow_ups(job)
    return JobResult(job, "done", time.perf_counter() - start, resumed=resumed, **follow_ups)


def record_failure(job: Job, message: str, details: str, seconds: float) -> JobResult:
    """Write the job's ``error.json`` (its error and the traceback or other details) and
    return its "failed" result; the run folder's other files are left as they are."""
    folder = run_dir(job.root, job.preset, job.task, job.method, job.seed)
    write_json(
        folder / "error.json",
        {"job": asdict(job), "error": message, "traceback": details},
        kind="error",
    )
    return JobResult(job, "failed", seconds, message)


def describe_exit(exitcode: int | None) -> str:
    """``"exit code 3"``, ``"killed by signal SIGKILL"`` (a negative exit code)."""
    if exitcode is not None and exitcode < 0:
        try:
            return f"killed by signal {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exit code {exitcode}"


def _raise_keyboard_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def stop_on_interrupt_signals() -> None:
    """Make SIGINT and SIGTERM raise KeyboardInterrupt in this process (main thread only).

    A process started in the background by a non-interactive shell (``nohup distgprl sweep
    ... &``) inherits SIGINT *ignored*, and Python then never raises KeyboardInterrupt (nor
    does ``_thread.interrupt_main``); SIGTERM ends a process without unwinding. With this,
    both stop a sweep, and each of its workers, the orderly way wherever it was started.
    """
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)


_job_running = threading.Event()  # in a pool worker: set while a job runs
_sweep_stopped = None  # in a pool worker: the sweep's stop event (set by `_watch_sweep`)


def _run_job_in_worker(job: Job) -> JobResult:
    """`run_job` in a pool worker; a job handed over after the sweep stopped never starts."""
    if _sweep_stopped is not None and _sweep_stopped.is_set():
        raise KeyboardInterrupt
    _job_running.set()
    try:
        return run_job(job)
    finally:
        _job_running.clear()


def _watch_sweep(parent_pid: int, stop, poll_s: float = 0.5) -> None:
    """Worker initializer: a thread that ends this worker's work with the sweep's.

    - The sweep process is gone (SIGKILL cannot stop its pool): exit at once, since an
      orphaned worker would go on training a run that a restarted sweep will resume.
    - The sweep was interrupted (``stop``, a multiprocessing Event, is set): raise
      KeyboardInterrupt in the running job, as Ctrl-C does, so it stops where a kill would;
      its last checkpoint stays.
    """
    global _sweep_stopped
    _sweep_stopped = stop
    stop_on_interrupt_signals()  # `interrupt_main` does nothing while SIGINT is ignored

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent_pid:
                os._exit(1)
            if stop.is_set() and _job_running.is_set():
                _thread.interrupt_main()
                while _job_running.is_set():  # one interrupt per job: let it unwind
                    time.sleep(poll_s)

    threading.Thread(target=watch, name="watch-sweep", daemon=True).start()


INTERRUPTED_EXIT = 130
"""Exit code of a job's process stopped by KeyboardInterrupt (SIGINT, or the sweep's stop):
the sweep treats it as an interrupt of the whole sweep, as Ctrl-C, not as a failed job."""


def _job_process(job: Job, parent_pid: int, stop, connection) -> None:
    """Body of a job's own process: run it and send its `JobResult` to the sweep."""
    _watch_sweep(parent_pid, stop)
    try:
        result = _run_job_in_worker(job)
    except KeyboardInterrupt:  # the sweep was interrupted: stop quietly, as a kill would
        sys.exit(INTERRUPTED_EXIT)
    connection.send(result)
    connection.close()


def _run_local(jobs: list[Job], workers: int) -> Generator[JobResult, None, None]:
    """Run ``jobs`` here: in this process one after the other (``workers <= 1``), else each
    in a spawned process of its own, at most ``workers`` at a time. A process that ends
    without sending a result (it crashed or was killed) fails its job only."""
    if workers <= 1:
        for job in jobs:
            yield run_job(job)
        return
    context = get_context("spawn")
    stop = context.Event()
    queue = list(jobs)
    running: dict[int, tuple] = {}  # sentinel -> (process, receiving end, job, start time)
    try:
        while queue or running:
            while queue and len(running) < workers:
                job = queue.pop(0)
                receiver, sender = context.Pipe(duplex=False)
                process = context.Process(
                    target=_job_process,
                    args=(job, os.getpid(), stop, sender),
                    name=f"sweep {job.name}",
                )
                process.start()
                sender.close()  # the child's copy stays open: EOF once it ends
                running[process.sentinel] = (process, receiver, job, time.perf_counter())
            for sentinel in wait_for_any(list(running)):
                # wait() returns the sentinels it was given
                process, receiver, job, started = running.pop(cast(int, sentinel))
                result = None
                try:
                    if receiver.poll():
                        result = receiver.recv()
                except (EOFError, OSError, pickle.UnpicklingError):  # died while sending it
                    result = None
                process.join()
                receiver.close()
                if result is None and process.exitcode == INTERRUPTED_EXIT:
                    raise KeyboardInterrupt  # Ctrl-C reached the job before this process
                if result is None:
                    how = describe_exit(process.exitcode)
                    result = record_failure(
                        job,
                        f"WorkerDied: the job's process ended without a result ({how}); "
                        "its last checkpoint stays for the next sweep to resume",
                        f"process {process.pid} {how}",
                        time.perf_counter() - started,
                    )
                yield result
    except BaseException:
        # Interrupted (Ctrl-C, or the consumer stopped): start nothing new and stop the
        # running jobs where a kill would (their watch threads raise KeyboardInterrupt).
        stop.set()
        for process, receiver, _, _ in running.values():
            process.join()
            receiver.close()
        raise


def _run_ray(
    jobs: list[Job], workers: int, address: str | None
) -> Generator[JobResult, None, None]:
    """Run ``jobs`` as Ray tasks (`distgprl.experiments.ray_executor`: which faults it
    survives, and how)."""
    from distgprl.experiments.ray_executor import run_on_ray

    # `run_job` looked up here, at call time: the tests replace it
    yield from run_on_ray(jobs, workers, address, run_job, record_failure)


HEARTBEAT_JOIN_S = 60.0
"""How long `run_sweep` waits, before it returns, for a progress report under way (one that
hangs, say on a stuck file system, does not hold the sweep)."""


def run_sweep(
    jobs: list[Job],
    workers: int = 1,
    executor: str = "local",
    address: str | None = None,
    on_result: Callable[[JobResult, int, int], None] | None = None,
    on_tick: Callable[[list[Job]], None] | None = None,
    tick_s: float = 300.0,
    retrain_damaged: bool = False,
) -> list[JobResult]:
    """Run every job; ``on_result(result, finished, total)`` reports each finished job and
    ``on_tick(unfinished_jobs)`` is called every ``tick_s`` seconds while jobs run (from a
    background thread), e.g. to report the running jobs' progress from their run folders.

    A damaged run is reported ("damaged") and left alone; with ``retrain_damaged`` its
    folder is removed (`clear_damaged`) and it trains anew."""
    if executor not in ("local", "ray"):
        raise UserInputError(f"unknown executor {executor!r}; valid: local, ray")
    todo, results = [], []
    for job in jobs:
        finished = finished_result(job)
        if finished is not None and finished.status == "damaged" and retrain_damaged:
            if clear_damaged(job):
                finished = None
        if finished is not None and finished.status == "skipped" and follow_up_due(job):
            finished = None  # trained, its model still here: `run_job` runs its follow-ups
        if finished is None:
            todo.append(job)
        else:
            results.append(finished)
    total = len(jobs)
    for result in results:
        if on_result:
            on_result(result, len(results), total)
    completed: set[Job] = set()
    stop = threading.Event()
    heartbeat = None
    if on_tick is not None and todo:

        def tick() -> None:
            while not stop.wait(tick_s):
                on_tick([job for job in todo if job not in completed])

        heartbeat = threading.Thread(target=tick, name="sweep-heartbeat", daemon=True)
        heartbeat.start()
    stream = _run_local(todo, workers) if executor == "local" else _run_ray(todo, workers, address)
    try:
        for result in stream:
            completed.add(result.job)
            results.append(result)
            if on_result:
                on_result(result, len(results), total)
    finally:
        stop.set()
        try:
            stream.close()  # interrupted: the executor stops its running and queued jobs now
        finally:
            if heartbeat is not None:  # a report under way ends before the sweep returns
                heartbeat.join(timeout=HEARTBEAT_JOIN_S)
    return results
