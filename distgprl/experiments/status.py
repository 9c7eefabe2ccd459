"""`distgprl status`: where every run of a sweep stands, read from its run folder alone.

A run's state is its `distgprl.runstate.RunState` verdict (``done``, ``stale``,
``damaged``, ``running``, ``failed``, ``partial``, ``missing``), the one the sweep and the
reports use too; a damaged run is listed with the file and the reason.

For started runs the last learning-curve row of ``progress.csv`` gives the step reached,
the curve success and collision rates and the training wall time so far. The ETA is the
steps left times the pace of the latest curve interval (the wall time between the last two
rows over their steps; the first interval is mostly gradient-free warm-up, so the pace since
step 0 would promise far too early a finish), or the pace since step 0 with one row.
`training_left` adds up the whole sweep's remaining training: each unfinished run's steps
left at its own pace, or, for runs not started, at the median pace of the task's finished
runs (``done.json``: training wall time over steps), or for a study's first runs at the pace
of the same task and method in its reference preset.
"""

from __future__ import annotations

import statistics
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass

from distgprl.experiments.jobs import Job
from distgprl.experiments.results import read_csv, read_json
from distgprl.identity import resolve_run
from distgprl.methods import get_method
from distgprl.runstate import VERDICTS, job_state
from distgprl.schema import run_dir

STATES = VERDICTS


@dataclass(frozen=True)
class RunStatus:
    """Where one run stands. Rates are the last learning-curve evaluation's (fractions)."""

    job: Job
    state: str
    step: int = 0
    total_steps: int = 0
    success_rate: float | None = None
    collision_rate: float | None = None
    wall_time_s: float | None = None
    seconds_per_step: float | None = None
    cpu_seconds_per_step: float | None = None
    error: str = ""
    numerics: str = ""  # a finished run's machine (`distgprl.machine`; "" if not recorded)

    @property
    def eta_s(self) -> float | None:
        """Seconds of training left at the pace so far (None if unknown or finished)."""
        if self.state in ("done", "stale", "damaged", "missing") or not self.seconds_per_step:
            return None
        return self.seconds_per_step * max(self.total_steps - self.step, 0)

    def describe(self) -> str:
        """One line: name, state, step, last curve rates, ETA, error."""
        parts = [f"{self.job.name:<28} {self.state:<8}"]
        if self.total_steps:
            parts.append(f"{self.step:>6}/{self.total_steps:<6}")
        if self.success_rate is not None:
            parts.append(
                f"curve success {self.success_rate:.2f} collision {self.collision_rate:.2f}"
            )
        if self.eta_s is not None:
            parts.append(f"ETA {self.eta_s / 60:.0f} min")
        if self.error:
            parts.append(self.error)
        return "  ".join(parts)


def _curve_rows(folder) -> list[dict[str, str]]:
    path = folder / "progress.csv"
    if not path.exists():
        return []
    try:
        _, rows = read_csv(path)
    except Exception:  # noqa: BLE001 - a status report must not fail on one odd file
        return []
    return rows


def _seconds_per_step(rows: list[dict[str, str]]) -> float | None:
    """Training wall time per step over the latest curve interval (None if unknown)."""
    if not rows:
        return None
    last = rows[-1]
    previous = rows[-2] if len(rows) > 1 else {"step": "0", "wall_time_s": "0"}
    steps = int(last["step"]) - int(previous["step"])
    seconds = float(last["wall_time_s"]) - float(previous["wall_time_s"])
    return seconds / steps if steps > 0 and seconds > 0 else None


def run_status(job: Job) -> RunStatus:
    """The state of one job's run folder (never trains, never writes): its `job_state`
    verdict, with the learning curve's progress for started runs."""
    folder = run_dir(job.root, job.preset, job.task, job.method, job.seed)
    trainable = get_method(job.method).trainable
    state = job_state(job.root, job.preset, job.task, job.method, job.seed)
    total = resolve_run(job.task, job.method, job.seed, job.preset).config.run.total_steps
    total = total if trainable else 0
    if state.verdict == "damaged":
        return RunStatus(job, "damaged", 0, total, error=state.describe())
    if state.verdict == "done":
        pace = cpu_pace = None
        numerics = ""
        if trainable:
            try:
                done = read_json(folder / "done.json")
                pace = float(done["train_wall_time_s"]) / int(done["steps"])
                cpu_pace = done.get("cpu_s_per_step")  # runs made before it was recorded: None
                numerics = (done["meta"].get("machine") or {}).get("numerics", "")
            except Exception:  # noqa: BLE001 - a status report must not fail on one odd file
                pace = cpu_pace = None
        return RunStatus(
            job,
            "done",
            total,
            total,
            seconds_per_step=pace,
            cpu_seconds_per_step=cpu_pace,
            numerics=numerics,
        )
    if state.verdict in ("stale", "missing"):
        return RunStatus(job, state.verdict, 0, total)
    rows = _curve_rows(folder)
    fields: dict = {}
    if rows:
        row = rows[-1]
        fields = {
            "step": int(row["step"]),
            "success_rate": float(row["success_rate"]),
            "collision_rate": float(row["collision_rate"]),
            "wall_time_s": float(row["wall_time_s"]),
            "seconds_per_step": _seconds_per_step(rows),
        }
    return RunStatus(job, state.verdict, total_steps=total, error=state.reason, **fields)


def sweep_status(jobs: Iterable[Job]) -> list[RunStatus]:
    """`run_status` of every job, in the given order."""
    return [run_status(job) for job in jobs]


def count_states(statuses: Iterable[RunStatus]) -> str:
    """e.g. ``"12/42 done, 2 running, 1 partial, 27 missing"`` (states present only)."""
    statuses = list(statuses)
    counts = Counter(s.state for s in statuses)
    done = f"{counts.pop('done', 0)}/{len(statuses)} done"
    rest = [f"{counts[state]} {state}" for state in STATES if counts.get(state)]
    return ", ".join([done, *rest])


@dataclass(frozen=True)
class TrainingLeft:
    """The sweep's remaining training, in seconds of one worker (wall time at the finished
    runs' load) and in process CPU seconds (``cpu_seconds``: what the same work costs on an
    idle core, None if no finished run recorded it)."""

    seconds: float
    runs: int
    unestimated: int
    cpu_seconds: float | None = None

    def describe(self, workers: int = 1) -> str:
        """e.g. ``"training left: 9 runs, 6.1 h of one worker (3.1 h with 2 workers)"``."""
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
        if self.unestimated:
            text += f"; {self.unestimated} without an estimate (no finished run of the task)"
        return text


def _median_paces(statuses: list[RunStatus], numerics: str, key) -> tuple[dict, dict]:
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


def training_left(
    statuses: Iterable[RunStatus],
    numerics: str | None = None,
    reference: Iterable[RunStatus] = (),
) -> TrainingLeft:
    """Training time left in the sweep (trainable runs not done), at each started run's
    own pace (`RunStatus.seconds_per_step`), else at the median pace of the finished runs
    of its task. The finished runs' pace includes whatever shared the machine with them
    (another worker), so this is an estimate at the same load. Where finished runs of a task
    were trained on a machine of this one's numerics (``numerics``, default this machine's
    `distgprl.machine.numerics_fingerprint`), only theirs count: runs committed from another
    machine may be twice as slow or fast. A task without a finished run of its own (a
    study's first seed) takes the median pace of the same task and method in ``reference``
    (e.g. the study's reference preset: the same method under another reading trains at
    the same size)."""
    from distgprl.machine import machine_info

    statuses = list(statuses)
    numerics = machine_info()["numerics"] if numerics is None else numerics
    median, cpu_median = _median_paces(statuses, numerics, lambda s: s.job.task)
    borrowed, cpu_borrowed = _median_paces(
        list(reference), numerics, lambda s: (s.job.task, s.job.method)
    )
    seconds, runs, unestimated = 0.0, 0, 0
    cpu_seconds: float | None = None
    for status in statuses:
        if status.state == "done" or not status.total_steps:
            continue
        runs += 1
        steps_left = max(status.total_steps - status.step, 0)  # stale runs: step 0
        task, method = status.job.task, status.job.method
        own_task = task in median or task in cpu_median
        cpu_pace = cpu_median.get(task) if own_task else cpu_borrowed.get((task, method))
        if cpu_pace is not None:  # the finished runs' median CPU pace
            cpu_seconds = (cpu_seconds or 0.0) + cpu_pace * steps_left
        pace = status.seconds_per_step or median.get(task) or borrowed.get((task, method))
        if pace is None:
            unestimated += 1
            continue
        seconds += pace * steps_left
    return TrainingLeft(seconds, runs, unestimated, cpu_seconds)
