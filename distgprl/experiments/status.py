"""`distgprl status`: where every run of a sweep stands, read from its run folder alone.

A run's state is its `distgprl.runstate.RunState` verdict (``done``, ``stale``,
``damaged``, ``running``, ``failed``, ``partial``, ``missing``), the one the sweep and the
reports use too; a damaged run is listed with the file and the reason.

For started runs the last learning-curve row of ``progress.csv`` gives the step reached,
the curve success and collision rates and the training wall time so far. The ETA is the
steps left times the pace of the latest curve interval (the wall time between the last two
rows over their steps; the first interval is mostly gradient-free warm-up, so the pace since
step 0 would promise far too early a finish), or the pace since step 0 with one row.

A started run nobody trains now (``partial``, ``failed``) also says where a resume would
continue from (`distgprl.experiments.run_control.resume_point`): its checkpoint's step, or
"restarts: no checkpoint yet" (its learning curve so far is then no resumable progress,
and its ETA counts every step). `distgprl.experiments.pace.training_left` adds up the whole
sweep's remaining training.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass

from distgprl.experiments.jobs import Job
from distgprl.experiments.run_control import ResumePoint, resume_point
from distgprl.identity import RunSpec, resolve_run
from distgprl.methods import get_method
from distgprl.runstate import VERDICTS, run_state
from distgprl.schema import read_csv, read_json, run_dir

STATES = VERDICTS


def format_duration(seconds: float) -> str:
    """``"40 s"``, ``"12 min"``, ``"3 h 05 min"``."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    minutes = int(seconds // 60)
    if minutes < 60:
        return f"{minutes} min"
    return f"{minutes // 60} h {minutes % 60:02d} min"


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
    resume: ResumePoint | None = None  # a started run nobody trains now: where it resumes

    @property
    def start_step(self) -> int:
        """The step training continues from: a resume's (`ResumePoint.start_step`) for a
        run nobody trains now, else the step reached."""
        return self.resume.start_step if self.resume is not None else self.step

    @property
    def eta_s(self) -> float | None:
        """Seconds of training left at the pace so far (None if unknown or finished)."""
        if self.state in ("done", "stale", "damaged", "missing") or not self.seconds_per_step:
            return None
        return self.seconds_per_step * max(self.total_steps - self.start_step, 0)

    def describe(self) -> str:
        """One line: name, state, step, last curve rates, where a resume continues, ETA,
        error."""
        parts = [f"{self.job.name:<28} {self.state:<8}"]
        if self.total_steps:
            parts.append(f"{self.step:>6}/{self.total_steps:<6}")
        if self.success_rate is not None:
            parts.append(
                f"curve success {self.success_rate:.2f} collision {self.collision_rate:.2f}"
            )
        if self.resume is not None:
            parts.append(self.resume.describe())
        if self.eta_s is not None:
            parts.append(f"ETA {format_duration(self.eta_s)}")
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


def run_status(job: Job, run: RunSpec | None = None) -> RunStatus:
    """The state of one job's run folder (never trains, never writes): its `run_state`
    verdict against the config hash the code resolves for it (``run``, the job's
    `resolve_run`, if resolved already: a live report re-reads the same runs every
    second), with the learning curve's progress for started runs."""
    folder = run_dir(job.root, job.preset, job.task, job.method, job.seed)
    trainable = get_method(job.method).trainable
    if run is None:
        run = resolve_run(job.task, job.method, job.seed, job.preset)
    state = run_state(folder, trainable, run.hash)
    total = run.config.run.total_steps if trainable else 0
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
    if state.verdict != "running" and trainable:
        fields["resume"] = resume_point(folder)
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
