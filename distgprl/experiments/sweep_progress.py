"""The report of a sweep while it runs (`SweepProgress`), read from the run folders as
`distgprl status` reads them (`distgprl.experiments.status.run_status`).

One line stands for the whole sweep: runs done of all, training steps done of all, the time
elapsed and the ETA. The ETA is the training left, each unfinished run's steps left at the
pace of its task and method (`distgprl.experiments.pace.Paces`: measured from the sweep's
runs finished or in progress, else estimated), handed out to the workers in the sweep's
order (`distgprl.experiments.pace.makespan`), plus, per job left (an untrained reference's
too), the median time the sweep's finished jobs of its task took beyond their training
(building the environment, evaluating, twin trials: most of a `ci` job; of any task until one
of its own has finished). A run done when the sweep started that still has follow-ups due
(`distgprl.experiments.follow_ups`: twin trials, safety-layer evaluations) is a job too: the
line counts those done of all (``follow-ups 3/35``) and the ETA adds, per one left, the median
time of the sweep's finished follow-up jobs (0 until one has finished).

- On a terminal (``live``) that line is a progress bar redrawn in place every refresh, with
  one line per running job beneath it (its step, curve rates, minutes left) and a line per
  finished job printed above.
- Elsewhere (a log file, a pipe) nothing is redrawn: each finished job's line ends with the
  sweep's line, and `heartbeat` prints the sweep's line and the running jobs' (the sweep's
  ``--heartbeat``).

Before anything runs, `opening` says what the sweep found: how many runs are done already
(and how to train them again), finished with another configuration, or started (each with
where it resumes: its checkpoint's step, or "restarts: no checkpoint yet").
"""

from __future__ import annotations

import io
import os
import statistics
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TextIO

from distgprl.experiments.follow_ups import follow_up_due
from distgprl.experiments.jobs import Job
from distgprl.experiments.pace import Paces, makespan, steps_left
from distgprl.experiments.status import RunStatus, format_duration, run_status
from distgprl.identity import resolve_run
from distgprl.schema import run_dir

FALLBACK_SIZE = (100, 24)
"""Columns and lines of the live display where the terminal reports none."""

STARTED = ("partial", "failed")
"""States of a started run nobody trains: the sweep resumes (or restarts) it."""


def format_steps(steps: int) -> str:
    """``"950"``, ``"90.0k"``, ``"2.62M"``."""
    if steps < 1000:
        return str(steps)
    if steps < 1_000_000:
        return f"{steps / 1000:.1f}k"
    return f"{steps / 1_000_000:.2f}M"


def retrain_hint(root: str | Path, example: Job) -> str:
    """How to train runs that are done again, naming one of them."""
    folder = run_dir(root, example.preset, example.task, example.method, example.seed)
    other = "runs" if Path(root) != Path("runs") else "runs-2"
    return (
        f"to train them again, sweep into another results folder (e.g. --root {other}) "
        f"or delete a run's folder (e.g. {folder})"
    )


class SweepProgress:
    """The sweep's report (module docstring); thread-safe (the sweep reports finished jobs
    from its main thread and ticks from another).

    Args:
        jobs: the sweep's jobs, in its order.
        workers: jobs run at once.
        stream: where to write (default: stdout).
        live: redraw a progress display in place (default: whether ``stream`` is a
            terminal).
        clock: seconds, monotonic (replaced in tests).
        numerics: this machine's numerics fingerprint (default: `distgprl.machine`'s).
        committed: the committed reference runs for paces nothing measured (default:
            `distgprl.experiments.pace.committed_statuses`, read when first needed).
    """

    def __init__(
        self,
        jobs: Sequence[Job],
        workers: int,
        stream: TextIO | None = None,
        live: bool | None = None,
        clock: Callable[[], float] = time.monotonic,
        numerics: str | None = None,
        committed: Sequence[RunStatus] | None = None,
    ):
        from distgprl.machine import machine_info

        self.jobs = list(jobs)
        self.workers = max(int(workers), 1)
        self.stream = stream if stream is not None else sys.stdout
        self.live = bool(self.stream.isatty()) if live is None else live
        self.clock = clock
        self.started_at = clock()
        self.numerics = machine_info()["numerics"] if numerics is None else numerics
        self.committed = committed
        self.runs = {job: resolve_run(job.task, job.method, job.seed, job.preset) for job in jobs}
        self.statuses: dict[Job, RunStatus] = {job: self._read(job) for job in self.jobs}
        self.unfinished: list[Job] = list(self.jobs)
        # done when the sweep started: `opening` counts them, their "skipped" is not repeated
        self.found_done = {job for job in self.jobs if self.statuses[job].state == "done"}
        # of those, the runs the sweep picks up for their follow-ups alone, and the time each took
        self.follow_ups = {job for job in self.found_done if follow_up_due(job)}
        self.follow_ups_left = set(self.follow_ups)
        self.follow_up_seconds: list[float] = []
        self._lock = threading.Lock()
        self._bars: list[Any] = []
        self._last_paces: Paces | None = None
        self.overheads: dict[str, list[float]] = {}  # task -> seconds beyond training per job

    # --- what the numbers are -------------------------------------------------------------

    def _read(self, job: Job) -> RunStatus:
        return run_status(job, self.runs[job])

    def _paces(self) -> Paces:
        """The paces of the runs as they stand now (the committed reference runs are read
        once, by the first `Paces` that needs them, and kept)."""
        if self._last_paces is not None and self._last_paces.committed is not None:
            self.committed = self._last_paces.committed
        self._last_paces = Paces(list(self.statuses.values()), self.numerics, [], self.committed)
        return self._last_paces

    def summary(self) -> str:
        """The sweep's line: ``"sweep: 3/74 runs, 90.0k/2.62M steps, elapsed 21 min, ETA 12 h
        30 min"``."""
        statuses = list(self.statuses.values())
        done = sum(s.state == "done" for s in statuses)
        total_steps = sum(s.total_steps for s in statuses)
        steps = sum(s.total_steps if s.state == "done" else s.start_step for s in statuses)
        elapsed = format_duration(self.clock() - self.started_at)
        text = f"sweep: {done}/{len(statuses)} runs, "
        text += f"{format_steps(steps)}/{format_steps(total_steps)} steps, "
        if self.follow_ups:
            followed = len(self.follow_ups) - len(self.follow_ups_left)
            text += f"follow-ups {followed}/{len(self.follow_ups)}, "
        return text + f"elapsed {elapsed}, ETA {format_duration(self.eta_s())}"

    def overhead_s(self, task: str) -> float:
        """The median time the sweep's finished jobs of ``task`` took beyond their training
        (of every task's while none of its own has finished; 0 before any has)."""
        every_task = [second for seconds in self.overheads.values() for second in seconds]
        seconds = self.overheads.get(task) or every_task
        return statistics.median(seconds) if seconds else 0.0

    def eta_s(self) -> float:
        """Seconds the sweep has left on its workers (module docstring)."""
        paces = self._paces()
        follow_up = statistics.median(self.follow_up_seconds) if self.follow_up_seconds else 0.0
        durations = [
            follow_up
            if status.state == "done"
            else (paces.lookup(status)[0] * steps_left(status) if status.total_steps else 0.0)
            + self.overhead_s(status.job.task)
            for status in (self.statuses[job] for job in self.unfinished)
            if status.state != "done" or status.job in self.follow_ups_left
        ]
        running = min(self.workers, len(durations))
        return makespan(durations[:running], durations[running:], self.workers)

    def running(self) -> list[RunStatus]:
        """The statuses of the jobs that run now (the sweep hands jobs out in order, so the
        first ``workers`` unfinished ones), that have started training."""
        return [
            self.statuses[job]
            for job in self.unfinished[: self.workers]
            if self.statuses[job].state == "running"
        ]

    def running_line(self, status: RunStatus) -> str:
        """A running job's line: name, step, curve rates, minutes left at its pace."""
        parts = [f"  {status.job.name:<28} {status.step:>6}/{status.total_steps:<6}"]
        if status.success_rate is not None:
            parts.append(
                f"curve success {status.success_rate:.2f} collision {status.collision_rate:.2f}"
            )
        if status.total_steps:
            left = self._paces().lookup(status)[0] * steps_left(status)
            parts.append(f"{format_duration(left)} left")
        return "  ".join(parts)

    # --- what the sweep calls -----------------------------------------------------------

    def opening(self, root: str | Path) -> list[str]:
        """What the sweep found before it runs anything (module docstring)."""
        counts = Counter(status.state for status in self.statuses.values())
        lines = []
        done = [job for job in self.jobs if self.statuses[job].state == "done"]
        if done:
            presets = {job.preset for job in done}  # a study's: several readings
            where = Path(root) / done[0].preset if len(presets) == 1 else Path(root)
            lines.append(
                f"already done: {len(done)} of {len(self.jobs)} runs in {where} (skipped); "
                + retrain_hint(root, done[0])
            )
        if counts["stale"]:
            lines.append(
                f"{counts['stale']} runs finished with another configuration: trained anew"
            )
        for job in self.jobs:
            status = self.statuses[job]
            if status.state in STARTED and status.resume is not None:
                lines.append(f"{job.name}: {status.resume.describe()}")
        return lines

    def tick(self, unfinished: Sequence[Job]) -> None:
        """Re-read the running jobs' run folders (``unfinished``: the jobs not finished, in
        the sweep's order) and redraw the live display."""
        with self._lock:
            self.unfinished = list(unfinished)
            for job in self.unfinished[: self.workers]:
                self.statuses[job] = self._read(job)
            if self.live:
                self._draw()

    def heartbeat(self) -> None:
        """Plain lines: the sweep's line and each running job's."""
        with self._lock:
            lines = [self.summary(), *(self.running_line(s) for s in self.running())]
            self._print("\n".join(lines))

    def finished(self, result: Any, count: int, total: int) -> None:
        """A finished job (`distgprl.experiments.sweep.JobResult`): its line; a run found
        done when the sweep started was counted in `opening` already (its line only if its
        follow-ups ran); a job that found its run done when it ran (a Ray retry of a task
        whose lost node had finished it) says so."""
        with self._lock:
            job = result.job
            if job in self.unfinished:
                self.unfinished.remove(job)
            self.statuses[job] = status = self._read(job)
            if result.status == "done" and (status.seconds_per_step or not status.total_steps):
                training = (status.seconds_per_step or 0.0) * status.total_steps
                overheads = self.overheads.setdefault(job.task, [])
                overheads.append(max(result.seconds - training, 0.0))
            if result.status == "skipped" and job in self.follow_ups_left:
                self.follow_ups_left.discard(job)
                if result.trials or result.repairs:
                    self.follow_up_seconds.append(result.seconds)
            if result.status == "skipped" and job in self.found_done:
                self.found_done.discard(job)  # reported once, by `opening`
                if not (result.trials or result.repairs):
                    return
            line = describe_result(result, count, total)
            self._print(line if self.live else f"{line}\n  {self.summary()}")
            if self.live:
                self._draw()

    def close(self) -> None:
        """Remove the live display (the last finished lines stay)."""
        with self._lock:
            for bar in self._bars:
                bar.close()
            self._bars = []

    # --- drawing ------------------------------------------------------------------------

    def _print(self, text: str) -> None:
        if self._bars:
            from tqdm import tqdm

            tqdm.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def _size(self) -> tuple[int, int]:
        """The terminal's columns and lines (`FALLBACK_SIZE` where it reports none, e.g. a
        pseudo terminal never sized, on which tqdm would draw nothing)."""
        try:
            size = os.get_terminal_size(self.stream.fileno())
        except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
            return FALLBACK_SIZE
        return size.columns or FALLBACK_SIZE[0], size.lines or FALLBACK_SIZE[1]

    def _draw(self) -> None:
        from tqdm import tqdm

        columns, lines = self._size()
        if not self._bars:
            self._bars = [
                tqdm(
                    total=0,
                    file=self.stream,
                    position=position,
                    bar_format="{bar:20} {percentage:3.0f}% {desc}" if position == 0 else "{desc}",
                    ncols=columns,
                    nrows=max(lines, self.workers + 2),
                    leave=position == 0,
                )
                for position in range(self.workers + 1)
            ]
        statuses = list(self.statuses.values())
        main = self._bars[0]
        main.total = max(sum(s.total_steps for s in statuses), 1)
        main.n = sum(s.total_steps if s.state == "done" else s.start_step for s in statuses)
        running = [self.running_line(s) for s in self.running()]
        texts = [self.summary(), *running, *[""] * (self.workers - len(running))]
        for position, (bar, line) in enumerate(zip(self._bars, texts, strict=True)):
            # a line wider than the terminal wraps and the redraw goes astray: cut it
            room = columns - 1 - (26 if position == 0 else 0)
            bar.ncols = columns
            bar.set_description_str(line[: max(room, 0)], refresh=True)


def describe_result(result: Any, count: int, total: int) -> str:
    """A finished job's line: ``"[3/74] dcp/gprl/seed0: done in 1243 s"`` and what it
    reported (its error, where it resumed, its trials and safety-layer evaluations)."""
    extra = f" ({result.error})" if result.error else ""
    extra += f" ({result.resumed})" if result.resumed else ""
    extra += f"\n  {result.trials}" if result.trials else ""
    extra += f"\n  {result.repairs}" if result.repairs else ""
    return f"[{count}/{total}] {result.job.name}: {result.status} in {result.seconds:.0f} s{extra}"
