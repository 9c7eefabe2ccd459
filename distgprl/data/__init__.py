"""Shipped data: demonstrations (CSV) per task.

``demos/<task>.csv`` is the nominal demonstration of a task; ``demos/<task>_varied/``
holds the 20 varied demonstrations (one per task configuration, planned by a TC-aware
expert, each successful and collision-free for its TC) over which Table I's ProMP-RRL fits
its object-centric ProMP (as the paper's §V-B defines it; also the exploration method
`promp-rrl-expert`); the study method `promp-rrl-1demo` gets only the nominal one.
Both are regenerated exactly by ``python -m distgprl.sim.experts``.
"""

from __future__ import annotations

from pathlib import Path

from distgprl.errors import UserInputError

DATA_DIR = Path(__file__).resolve().parent
DEMO_DIR = DATA_DIR / "demos"
TASK_NAMES: tuple[str, ...] = ("dcp", "dbm")

SCENE_REVISIONS: dict[str, int] = {"dcp": 0, "dbm": 2}
"""Per task, the revision of its simulated scene. A non-zero revision enters every run's
config hash, so runs made in an earlier scene are stale (a sweep re-runs them); revision 0
adds nothing, keeping the hashes of runs made before revisions were recorded.

- dbm 1: all 31 conveyor rollers are in PyBullet. In revision 0 the roller body held only
  the first 16 (PyBullet silently drops shapes beyond 16 per shape array): the physical
  conveyor ended at y = 0.015 m while the distance field saw rollers up to 0.615 m, so
  robot contact with the missing rollers was neither a collision nor in the clearance.
- dbm 2: the bars' TC offsets vary across the belt too (x, up to the
  rails), as the paper varies them in the xy-plane.
"""


def task_order(task: str) -> int:
    """Sort key: tasks in `TASK_NAMES` order (the paper's: DCP, DBM), unknown ones after."""
    return TASK_NAMES.index(task) if task in TASK_NAMES else len(TASK_NAMES)


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
