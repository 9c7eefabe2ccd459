"""How long a sweep's runs take: each run's training pace (seconds per RL step), measured
where it can be, estimated where it cannot, and the time the sweep has left.

A run's pace, first that applies (`Paces.lookup`, which also says where it came from):

1. ``own``: a started run's own pace (`distgprl.experiments.status.RunStatus.seconds_per_step`,
   its latest learning-curve interval);
2. ``sweep``: the median pace of the sweep's runs of the same task and method, finished
   (``done.json``: training wall time over steps) or in progress; else of the same task's
   finished runs (any method). Where finished runs of a key were trained on a machine of
   this one's numerics (`distgprl.machine`), only theirs count: runs committed from another
   machine may be twice as slow or fast;
3. ``reference``: the median pace of the same task and method in a reference sweep (a
   study's reference preset: the same method under another reading trains at the same size);
4. ``committed``: the median pace of the same task and method, else of the task, among the
   committed reference runs of this checkout (`COMMITTED_RESULTS`, the ``paper`` preset);
5. ``default``: `DEFAULT_SECONDS_PER_STEP`.

So every unfinished run has an estimate; `TrainingLeft.describe` says how many came from each
source. Finished runs' paces include whatever shared the machine with them (another worker),
so the figures are estimates at the same load.
"""

from __future__ import annotations

import heapq
import statistics
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from distgprl.experiments.status import RunStatus

COMMITTED_RESULTS = Path(__file__).resolve().parents[2] / "results"
"""The reference results committed with this checkout (absent from an installed wheel)."""

COMMITTED_PRESET = "paper"
"""The preset of `COMMITTED_RESULTS` whose runs' paces estimate runs nothing else measured."""

DEFAULT_SECONDS_PER_STEP = 0.035
"""Wall seconds per RL step of a run nothing measured: a paper-size run on one of two busy
cores (the 70 committed Table I runs took 0.014–0.143 s per step, median
0.033: their ``done.json``)."""

SOURCES = ("own", "sweep", "reference", "committed", "default")
"""Where a pace came from (module docstring), in the order they are tried."""

_SOURCE_TEXT = {
    "own": "their own pace",
    "sweep": "the pace of the sweep's runs of the task",
    "reference": "the reference preset's pace",
    "committed": "the committed reference runs' pace",
    "default": f"the default pace ({DEFAULT_SECONDS_PER_STEP} s/step)",
}

IN_PROGRESS = ("running", "partial", "failed")
"""States of a started, unfinished run whose learning curve gives it a pace of its own."""


def _median_paces(
    statuses: Iterable[RunStatus], numerics: str, key: Callable[[RunStatus], object]
) -> tuple[dict, dict]:
    """Median wall and CPU seconds per step of the finished runs in ``statuses``, by
    ``key(status)``; where a key has finished runs of this machine's ``numerics``, only
    theirs count."""
    done = [s for s in statuses if s.state == "done"]
    local = {key(s) for s in done if s.numerics == numerics}
    paces: dict[object, list[float]] = {}
    cpu_paces: dict[object, list[float]] = {}
    for status in done:
        if key(status) in local and status.numerics != numerics:
            continue
        if status.seconds_per_step:
            paces.setdefault(key(status), []).append(status.seconds_per_step)
        if status.cpu_seconds_per_step:
            cpu_paces.setdefault(key(status), []).append(status.cpu_seconds_per_step)
    return (
        {k: statistics.median(v) for k, v in paces.items()},
        {k: statistics.median(v) for k, v in cpu_paces.items()},
    )


def _task_and_method(status: RunStatus) -> tuple[str, str]:
    return status.job.task, status.job.method


def _task(status: RunStatus) -> str:
    return status.job.task


def committed_statuses() -> list[RunStatus]:
    """`run_status` of every run of `COMMITTED_PRESET` in `COMMITTED_RESULTS` (empty if
    this checkout has none)."""
    from distgprl.experiments.status import sweep_status
    from distgprl.experiments.sweep import plan_jobs

    if not (COMMITTED_RESULTS / COMMITTED_PRESET).is_dir():
        return []
    return sweep_status(plan_jobs(COMMITTED_PRESET, root=COMMITTED_RESULTS))


@dataclass
class Paces:
    """Pace lookup for a sweep's runs (module docstring).

    Args:
        statuses: the sweep's runs.
        numerics: this machine's numerics fingerprint (finished runs of it are preferred).
        reference: a reference sweep's runs (a study's reference preset), or none.
        committed: the committed reference runs; None: `committed_statuses`, read the first
            time a run needs them.
    """

    statuses: Sequence[RunStatus]
    numerics: str
    reference: Sequence[RunStatus] = ()
    committed: Sequence[RunStatus] | None = None
    _tables: list[tuple[str, Callable, dict, dict]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        by_method, cpu_by_method = _median_paces(self.statuses, self.numerics, _task_and_method)
        for key, paces in self._in_progress().items():
            if key not in by_method:  # finished runs first: their pace covers a whole run
                by_method[key] = statistics.median(paces)
        by_task, cpu_by_task = _median_paces(self.statuses, self.numerics, _task)
        borrowed, cpu_borrowed = _median_paces(self.reference, self.numerics, _task_and_method)
        self._tables = [
            ("sweep", _task_and_method, by_method, cpu_by_method),
            ("sweep", _task, by_task, cpu_by_task),
            ("reference", _task_and_method, borrowed, cpu_borrowed),
        ]

    def _in_progress(self) -> dict[tuple[str, str], list[float]]:
        paces: dict[tuple[str, str], list[float]] = {}
        for status in self.statuses:
            if status.state in IN_PROGRESS and status.seconds_per_step:
                paces.setdefault(_task_and_method(status), []).append(status.seconds_per_step)
        return paces

    def _committed_tables(self) -> list[tuple[str, Callable, dict, dict]]:
        """The committed reference runs' tables, read the first time a run needs them."""
        if self.committed is None:
            self.committed = committed_statuses()
        by_method, cpu_by_method = _median_paces(self.committed, self.numerics, _task_and_method)
        by_task, cpu_by_task = _median_paces(self.committed, self.numerics, _task)
        return [
            ("committed", _task_and_method, by_method, cpu_by_method),
            ("committed", _task, by_task, cpu_by_task),
        ]

    def _find(self, status: RunStatus, column: int) -> tuple[float, str] | None:
        """(pace, source) from the first table holding one for ``status``; ``column`` 0:
        wall seconds per step, 1: CPU seconds per step."""
        for index in range(5):
            if index == len(self._tables):
                self._tables += self._committed_tables()
            source, key, *paces = self._tables[index]
            pace = paces[column].get(key(status))
            if pace:
                return pace, source
        return None

    def lookup(self, status: RunStatus) -> tuple[float, str]:
        """(wall seconds per step, source) for ``status``'s run: one of `SOURCES`."""
        if status.state in IN_PROGRESS and status.seconds_per_step:
            return status.seconds_per_step, "own"
        found = self._find(status, 0)
        return found if found is not None else (DEFAULT_SECONDS_PER_STEP, "default")

    def cpu_lookup(self, status: RunStatus) -> float | None:
        """Process CPU seconds per step for ``status``'s run, from the first source with
        finished runs that recorded it (None: none did)."""
        found = self._find(status, 1)
        return found[0] if found is not None else None


@dataclass(frozen=True)
class TrainingLeft:
    """The sweep's remaining training, in seconds of one worker (wall time at the measured
    runs' load) and in process CPU seconds (``cpu_seconds``: what the same work costs on an
    idle core, None if no finished run recorded it); ``sources`` counts the runs by where
    their pace came from (`SOURCES`)."""

    seconds: float
    runs: int
    sources: Counter = field(default_factory=Counter)
    cpu_seconds: float | None = None

    def describe(self, workers: int = 1) -> str:
        """e.g. ``"training left: 9 runs, 6.1 h of one worker (3.1 h with 2 workers);
        paces: 2 at their own pace, 7 at the pace of the sweep's runs of the task"``."""
        if not self.runs:
            return "training left: none"
        hours = self.seconds / 3600.0
        text = f"training left: {self.runs} runs, {hours:.1f} h of one worker"
        if workers > 1:
            text += f" ({hours / workers:.1f} h with {workers} workers)"
        if self.cpu_seconds is not None:
            cpu_hours = self.cpu_seconds / 3600.0
            text += f"; {cpu_hours:.1f} CPU-hours ({cpu_hours / workers:.1f} h on {workers} idle"
            text += " cores)" if workers > 1 else " core)"
        counts = [f"{self.sources[s]} at {_SOURCE_TEXT[s]}" for s in SOURCES if self.sources[s]]
        return text + "; paces: " + ", ".join(counts)


@dataclass(frozen=True)
class TrainingDone:
    """The sweep's finished training: ``runs`` done trainable runs, their training wall time
    (``seconds``, summed over runs: what one worker spent) and process CPU time
    (``cpu_seconds``, over the ``cpu_runs`` of them whose ``done.json`` records it), both as
    each run's ``done.json`` gives them (curve evaluations included, evaluations after
    training not)."""

    runs: int
    seconds: float
    cpu_seconds: float
    cpu_runs: int

    def describe(self) -> str:
        """e.g. ``"training done: 48 runs, 21.3 h of one worker; 20.8 CPU-hours"`` (``the k
        runs that recorded it`` after the CPU-hours where not every run did)."""
        if not self.runs:
            return "training done: none"
        text = f"training done: {self.runs} runs, {self.seconds / 3600.0:.1f} h of one worker"
        if self.cpu_runs:
            text += f"; {self.cpu_seconds / 3600.0:.1f} CPU-hours"
            text += "" if self.cpu_runs == self.runs else f" (the {self.cpu_runs} that recorded it)"
        return text


def training_done(statuses: Iterable[RunStatus]) -> TrainingDone:
    """`TrainingDone` of the done trainable runs among ``statuses`` (each run's pace times its
    total steps: the ``done.json`` figures `distgprl.experiments.status.run_status` read)."""
    done = [s for s in statuses if s.state == "done" and s.total_steps and s.seconds_per_step]
    cpu = [s.cpu_seconds_per_step * s.total_steps for s in done if s.cpu_seconds_per_step]
    seconds = sum(s.seconds_per_step * s.total_steps for s in done if s.seconds_per_step)
    return TrainingDone(len(done), seconds, sum(cpu), len(cpu))


def steps_left(status: RunStatus) -> int:
    """RL steps a run has still to train: all of them unless it is running (its curve's
    step) or a resume continues from its checkpoint (`RunStatus.start_step`)."""
    return max(status.total_steps - status.start_step, 0)


def training_left(
    statuses: Iterable[RunStatus],
    numerics: str | None = None,
    reference: Iterable[RunStatus] = (),
    committed: Sequence[RunStatus] | None = None,
) -> TrainingLeft:
    """Training time left in the sweep: every trainable run not done, its steps left
    (`steps_left`) at its pace (`Paces`; ``numerics`` default: this machine's
    `distgprl.machine.numerics_fingerprint`)."""
    from distgprl.machine import machine_info

    statuses = list(statuses)
    numerics = machine_info()["numerics"] if numerics is None else numerics
    paces = Paces(statuses, numerics, list(reference), committed)
    seconds, runs, sources = 0.0, 0, Counter[str]()
    cpu_seconds: float | None = None
    for status in statuses:
        if status.state == "done" or not status.total_steps:
            continue
        runs += 1
        pace, source = paces.lookup(status)
        sources[source] += 1
        seconds += pace * steps_left(status)
        cpu_pace = paces.cpu_lookup(status)
        if cpu_pace is not None:
            cpu_seconds = (cpu_seconds or 0.0) + cpu_pace * steps_left(status)
    return TrainingLeft(seconds, runs, sources, cpu_seconds)


def makespan(running: Iterable[float], queued: Iterable[float], workers: int) -> float:
    """Seconds until ``workers`` parallel workers finish: the running jobs' seconds left
    (one worker each), then the queued jobs' durations in order, each on the first worker
    free (the sweep hands out jobs in that order)."""
    free = sorted(running)
    free = [*free, *[0.0] * max(workers - len(free), 0)]
    heapq.heapify(free)
    for duration in queued:
        heapq.heappush(free, heapq.heappop(free) + duration)
    return max(free, default=0.0)
