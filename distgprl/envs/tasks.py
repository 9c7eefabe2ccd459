"""Glue between the adaptation environments and the task simulations / skills."""

from __future__ import annotations

from functools import lru_cache

from distgprl.data import check_task_name, demo_path
from distgprl.skill.demos import load_demonstration
from distgprl.skill.gp import FitConfig, GPSkill, fit_skill


def make_task_sim(task: str):
    """(TaskSpec, task simulation) for ``task``; one PyBullet client per call."""
    from distgprl.sim.tasks import get_task

    spec = get_task(check_task_name(task))
    return spec, spec.make_sim()


@lru_cache(maxsize=8)
def _fit_cached(task: str, n_via_points: int, sha256: str) -> GPSkill:
    demo = load_demonstration(demo_path(task), min_rows=n_via_points)
    return fit_skill(demo, FitConfig(n_via_points=n_via_points))


def load_task_skill(task: str, n_via_points: int = 15) -> GPSkill:
    """The GP skill fitted to the task's shipped demonstration (cached per file hash)."""
    from distgprl.experiments.results import file_sha256

    path = demo_path(check_task_name(task))
    return _fit_cached(task, n_via_points, file_sha256(path))
