"""Glue between the adaptation environments and the task simulations / skills."""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import numpy as np

from distgprl.data import check_task_name
from distgprl.safety.hap_build import HapConfig, SafeSubspace, tqdm_progress
from distgprl.safety.hap_cache import build_or_load
from distgprl.skill.committed import load_committed_skill
from distgprl.skill.gp import GPSkill


def make_task_sim(task: str):
    """(TaskSpec, task simulation) for ``task``; one PyBullet client per call."""
    from distgprl.sim.tasks import get_task

    spec = get_task(check_task_name(task))
    return spec, spec.make_sim()


def cache_root() -> Path:
    """``$DISTGPRL_CACHE_DIR`` or ``~/.cache/distgprl``: derived artefacts, safe to delete."""
    root = os.environ.get("DISTGPRL_CACHE_DIR")
    return Path(root) if root else Path.home() / ".cache" / "distgprl"


def load_task_skill(task: str, n_via_points: int = 15) -> GPSkill:
    """The task's committed GP skill (``data/skills/<task>.json``; never fitted here:
    `distgprl.skill.committed`)."""
    return load_committed_skill(check_task_name(task), n_via_points)


def hap_cache_dir() -> Path:
    """Where HAP subspaces are cached: ``<cache_root()>/hap``."""
    return cache_root() / "hap"


def task_hap_config(task: str, n_via_points: int = 15) -> HapConfig:
    """The HAP grid for a task, derived from its demonstration (DESIGN §4).

    Workspace: the box spanned by the demonstration's positions and by the object offsets
    of the TC range (±0.2 m in x and y), padded by 0.1 m, with a 0.1 m grid. Orientations:
    the demonstration's start orientation and the same turned by ±45° about the world z
    axis. Root: the demonstration's start position.
    """
    from scipy.spatial.transform import Rotation

    skill = load_task_skill(task, n_via_points)
    positions = skill.via_points[:, :3]
    lower = positions.min(axis=0) - np.array([0.3, 0.3, 0.1])
    upper = positions.max(axis=0) + np.array([0.3, 0.3, 0.1])
    lower[2] = max(lower[2], 0.02)
    base = Rotation.from_rotvec(skill.via_points[0, 3:])
    orientations = tuple(
        _xyz((Rotation.from_euler("z", yaw) * base).as_rotvec())
        for yaw in (-np.pi / 4, 0.0, np.pi / 4)
    )
    return HapConfig(
        workspace_lower=_xyz(lower),
        workspace_upper=_xyz(upper),
        orientations=orientations,
        root_position=_xyz(positions[0]),
    )


def _xyz(values: np.ndarray) -> tuple[float, float, float]:
    """A 3-vector as a tuple of floats (HapConfig's fields)."""
    x, y, z = values
    return (float(x), float(y), float(z))


def hap_robot_id(robot: str, tool: str, task: str, scene_revision: int) -> str:
    """The collision model's identity in the HAP cache key (``ur5e+shovel/dcp/...``): the
    robot, its tool and the scene's PyBullet bodies are what the collision checks see, so a
    new scene revision builds a new subspace (revision 0 adds nothing: caches made before
    revisions stay valid)."""
    suffix = f"/scene-r{scene_revision}" if scene_revision else ""
    return f"{robot}+{tool}/{task}/hap-wiring-v1{suffix}"


def load_task_subspace(task: str, progress=None) -> tuple[SafeSubspace, bool]:
    """The task's HAP safe subspace against its static obstacles (built once, then cached).

    ``progress``: a `ProgressFunction` for the build; default progress bars on stderr
    (`tqdm_progress`, drawn only on a terminal).
    """
    from distgprl.sim.tasks import get_task

    spec = get_task(check_task_name(task))
    sim = spec.make_sim()  # a dedicated instance: the collision checks move its robot
    try:
        static = [s for s in sim.obstacle_shapes() if not s.dynamic]
        return build_or_load(
            task_hap_config(task),
            sim.robot.ik_all,
            sim.configuration_in_collision,
            obstacles=static,
            robot_id=hap_robot_id(sim.robot.name, sim.tool.name, task, spec.scene_revision),
            cache_dir=hap_cache_dir(),
            joint_lower=sim.robot.lower_limits,
            joint_upper=sim.robot.upper_limits,
            progress=progress if progress is not None else tqdm_progress(),
        )
    finally:
        sim.close()


@lru_cache(maxsize=8)
def _hap_prior_cached(task: str, k: int, temperature: float, hinge: bool):
    from distgprl.safety.hap_loss import HapPrior

    subspace, _ = load_task_subspace(task)
    step = task_hap_config(task).grid_step
    return HapPrior(
        subspace.unique_positions,
        k=k,
        temperature=temperature,
        hinge_step=step if hinge else 0.0,
        grid_step=step,
    )


def load_task_hap_prior(task: str, k: int = 8, temperature: float = 0.05, hinge: bool = False):
    """The L_hap prior over the task's static C_safe: Eq. hap_compact as written (the raw
    soft-min in m, no offset), or with ``hinge`` the variant hinged at a safe cell's
    soft-min and in units of the task's HAP grid step
    (`distgprl.safety.hap_loss.HapPrior`'s ``hinge_step``; ``SACConfig.hap_hinge``)."""
    return _hap_prior_cached(task, int(k), float(temperature), bool(hinge))
