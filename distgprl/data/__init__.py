"""Shipped data: demonstrations (CSV) per task.

``demos/<task>.csv`` is the nominal demonstration of a task; ``demos/<task>_varied/``
holds the 20 varied demonstrations (one per task configuration) that ProMP-RRL fits.
Both are regenerated exactly by ``python -m distgprl.sim.experts``.
"""

from __future__ import annotations

from pathlib import Path

from distgprl.errors import UserInputError

DATA_DIR = Path(__file__).resolve().parent
DEMO_DIR = DATA_DIR / "demos"
TASK_NAMES: tuple[str, ...] = ("dcp", "dbm")


def check_task_name(task: str) -> str:
    """Return ``task`` if it is a known task name, else raise a `UserInputError`."""
    if task not in TASK_NAMES:
        raise UserInputError(f"unknown task {task!r}; valid tasks: {', '.join(TASK_NAMES)}")
    return task


def demo_path(task: str) -> Path:
    """Path of the shipped nominal demonstration of ``task``."""
    path = DEMO_DIR / f"{check_task_name(task)}.csv"
    if not path.exists():
        raise UserInputError(
            f"{path}: the shipped demonstration of task {task!r} is missing; "
            "regenerate it with `python -m distgprl.sim.experts`"
        )
    return path
