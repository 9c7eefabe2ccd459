"""The simulated tasks and their registry (``TASKS``, :func:`get_task`).

Each task module declares its one `TaskSpec` as ``TASK`` (name, scene revision, TC sampler,
expert, simulation class, demonstrations); `TASKS` collects them in
`distgprl.data.TASK_NAMES` order, the pybullet-free catalogue of names and scene revisions
that the config hashes and the CLI read (a test checks the two agree).
"""

from __future__ import annotations

from distgprl.data import TASK_NAMES, check_task_name
from distgprl.sim.tasks import dbm, dcp
from distgprl.sim.tasks.base import TaskSpec

_DECLARED: dict[str, TaskSpec] = {spec.name: spec for spec in (dcp.TASK, dbm.TASK)}

TASKS: dict[str, TaskSpec] = {name: _DECLARED[name] for name in TASK_NAMES}
"""Task registry: name -> :class:`TaskSpec` (each task module's ``TASK``)."""


def get_task(name: str) -> TaskSpec:
    """The task called ``name``; raises :class:`UserInputError` listing the valid names."""
    return TASKS[check_task_name(name)]


__all__ = [
    "TASKS",
    "get_task",
]
