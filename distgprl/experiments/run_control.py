"""Control of a training run from outside its training loop: the exclusive lock that keeps
a second process from training the same run folder (`run_lock`), the interrupt that says
where training stopped (`TrainingInterrupted`), the command that resumes it
(`resume_command`) and where a resume would continue from (`resume_point`)."""

from __future__ import annotations

import fcntl
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from distgprl.errors import RunBusyError
from distgprl.experiments.checkpoints import checkpoint_step, trained_steps
from distgprl.schema import read_json


@contextmanager
def run_lock(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on a run folder (``.lock``) while one process trains it.

    A second process (say, a restarted sweep while a worker of the old one still runs)
    gets a clear error instead of writing the same checkpoints and CSVs concurrently.
    Closing the file (or the holder's exit, however it dies) releases the lock.
    """
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RunBusyError(
                f"{folder}: another process is training this run (lock {folder / '.lock'})"
            ) from None
        yield


class TrainingInterrupted(KeyboardInterrupt):
    """Training stopped by KeyboardInterrupt (SIGINT; SIGTERM with
    `~distgprl.experiments.sweep.stop_on_interrupt_signals`), with where it stopped.

    Attributes:
        folder: the run folder.
        step: RL steps trained when it stopped.
        total: the run's total RL steps.
        checkpoint_step: the step of the last checkpoint written (a resume continues from
            it), or None if the run had none yet (a resume starts over).
    """

    def __init__(self, folder: Path, step: int, total: int, checkpoint_step: int | None):
        super().__init__(f"{folder}: interrupted at step {step}/{total}")
        self.folder, self.step, self.total = folder, step, total
        self.checkpoint_step = checkpoint_step

    def describe(self, resume_command: str) -> str:
        """Two lines for stderr: where training stopped, what is kept, how to resume."""
        if self.checkpoint_step is None:
            kept = "no checkpoint was written yet, so a resume starts over"
        else:
            kept = f"its checkpoint of step {self.checkpoint_step} is kept"
        return (
            f"train interrupted at step {self.step} of {self.total} ({self.folder}); {kept}.\n"
            f"resume with: {resume_command}"
        )


def describe_interrupt(error: KeyboardInterrupt, command: str) -> str:
    """What `distgprl train` prints when interrupted: `TrainingInterrupted.describe`, or,
    interrupted outside the training steps (setting up, or evaluating after them), one
    line with the resume command."""
    if isinstance(error, TrainingInterrupted):
        return error.describe(command)
    return f"train interrupted outside the training steps; resume with: {command}"


def resume_command(
    task: str,
    method: str,
    seed: int,
    preset: str,
    steps: int | None,
    root: str | Path,
    evaluate_after: bool = True,
) -> str:
    """The exact ``distgprl train ... --resume`` command that continues a run."""
    import shlex

    words = ["distgprl", "train", "--method", method, "--task", task, "--seed", str(seed)]
    words += ["--preset", preset]
    if steps is not None:
        words += ["--steps", str(steps)]
    words += ["--root", str(root), "--resume"]
    if not evaluate_after:
        words.append("--no-evaluate")
    return shlex.join(words)


@dataclass(frozen=True)
class ResumePoint:
    """Where a started, unfinished run stands for a resume.

    Attributes:
        reached: the last step its ``progress.csv`` recorded (0: none).
        checkpoint: the step of the checkpoint a resume continues from (`checkpoint_step`),
            or None if it has none yet: a resume then trains from step 0 (the learning
            curve recorded so far is not resumable progress).
    """

    reached: int
    checkpoint: int | None

    @property
    def start_step(self) -> int:
        """The step a resume trains from."""
        return self.checkpoint or 0

    def describe(self) -> str:
        """``"resumes from its checkpoint of step 1500"`` or ``"restarts: no checkpoint yet
        (it had reached step 1500)"``."""
        if self.checkpoint is not None:
            return f"resumes from its checkpoint of step {self.checkpoint}"
        reached = f" (it had reached step {self.reached})" if self.reached else ""
        return f"restarts: no checkpoint yet{reached}"


def resume_point(folder: Path) -> ResumePoint:
    """Where a resume of the run in ``folder`` would continue from (reads, never writes)."""
    return ResumePoint(trained_steps(folder / "progress.csv"), checkpoint_step(folder))


def describe_resume(folder: Path, reached: int) -> str:
    """Where a run that had reached step ``reached`` before a job was resumed from, as its
    ``done.json`` records it (empty for a run the job trained from its start)."""
    if reached <= 0:
        return ""
    resumes = read_json(folder / "done.json").get("resumes") or [{}]
    step = int(resumes[-1].get("step", 0))
    if step > 0:
        return f"resumed from its checkpoint of step {step}"
    return f"restarted from step 0 (it had reached step {reached})"
