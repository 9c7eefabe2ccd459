"""The committed GP skills: every number the skill fit decides, shipped with the package
(protocol rule 7: one skill for every machine).

The fit (`distgprl.skill.gp.fit_skill`: the shared kernel's and the six zero-mean axis
kernels' marginal-likelihood optima, the via-points Gamma_0, the prior mean and the axis
scales) depends on the BLAS kernel in its last digits (about 1e-5 relative on the
hyperparameters). So it is not run where the skill is used: ``data/skills/<task>.json`` holds
the fitted skill of the task's shipped demonstration, and training, the operator, the action
scales, the mechanism table and the reports read it (`load_committed_skill`). Refitting is
explicit (`refit_committed_skill`, ``distgprl fit --task <task> --write``).

File format (JSON; every float written by Python's ``repr``, which reads back to the same
bits)::

    {"format": "distgprl-skill", "format_version": 1, "task": "dcp",
     "demonstration": {"file": "demos/dcp.csv", "sha256": "...", "samples": 401},
     "fit_config": {FitConfig's fields},
     "skill": {GPSkill.to_dict(): name, kernel, duration_s, via_times, via_points,
               prior_mean, axis_scale, axis_kernels},
     "provenance": {"code_commit", "fit_sources" (sha256 of the fitting modules),
                    "libraries" (numpy, scipy), "machine" (CPU and numerics fingerprint:
                    the BLAS kernel), "openblas_coretype" (the variable, if set),
                    "environment" (every OPENBLAS_*, NPY_* and OMP_NUM_THREADS variable set:
                    they choose kernels, blocking and threads), "utc_time"}}

A missing or malformed file, one fitted to another demonstration than the shipped one, or one
with another number of via-points than asked for is a `UserInputError` naming the file.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.data import DATA_DIR, check_task_name, demo_path
from distgprl.errors import UserInputError
from distgprl.io import atomic_write_text, file_sha256
from distgprl.skill.demos import load_demonstration
from distgprl.skill.gp import DEFAULT_N_VIA_POINTS, FitConfig, GPSkill, fit_skill

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "SKILL_DIR",
    "CommittedSkill",
    "committed_skill_path",
    "fit_provenance",
    "fit_task_skill",
    "load_committed_skill",
    "read_skill_file",
    "refit_committed_skill",
    "write_skill_file",
]

SKILL_DIR = DATA_DIR / "skills"
FORMAT = "distgprl-skill"
FORMAT_VERSION = 1
FIT_SOURCES = ("skill/gp.py", "skill/kernels.py", "skill/operator.py", "skill/demos.py")
"""The modules whose code decides the fitted numbers (hashed into the provenance)."""


@dataclass(frozen=True)
class CommittedSkill:
    """A skill file's contents: the skill, what it was fitted to and how."""

    task: str
    skill: GPSkill
    fit_config: FitConfig
    demonstration: dict[str, Any]
    provenance: dict[str, Any]
    path: Path


def committed_skill_path(task: str, directory: str | Path | None = None) -> Path:
    """``<directory>/<task>.json``, by default the package's ``data/skills/<task>.json``."""
    return Path(directory or SKILL_DIR) / f"{check_task_name(task)}.json"


def fit_provenance() -> dict[str, Any]:
    """What decided a fit's bits on this machine: code, libraries, BLAS kernel (module doc)."""
    from datetime import UTC, datetime

    import scipy

    from distgprl.machine import machine_info
    from distgprl.schema import git_commit

    package = Path(__file__).resolve().parents[1]
    return {
        "code_commit": git_commit(),
        "fit_sources": {name: file_sha256(package / name) for name in FIT_SOURCES},
        "libraries": {"numpy": np.__version__, "scipy": scipy.__version__},
        "machine": machine_info(),
        "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE"),
        "environment": {
            name: value
            for name, value in sorted(os.environ.items())
            if name.startswith(("OPENBLAS_", "NPY_")) or name == "OMP_NUM_THREADS"
        },
        "utc_time": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


def fit_task_skill(task: str, n_via_points: int = DEFAULT_N_VIA_POINTS) -> GPSkill:
    """A fresh fit of the task's shipped demonstration on this machine (explicit: nothing
    calls it implicitly; `refit_committed_skill` writes it, ``distgprl fit --compare`` shows
    how it differs from the committed one)."""
    config = FitConfig(n_via_points=n_via_points)
    demo = load_demonstration(demo_path(task), min_rows=n_via_points)
    skill = fit_skill(demo, config)
    return GPSkill.from_dict({**skill.to_dict(), "name": task})


def write_skill_file(
    task: str, skill: GPSkill, config: FitConfig, directory: str | Path | None = None
) -> Path:
    """Write ``skill`` (fitted with ``config`` to the task's shipped demonstration) as the
    task's skill file in ``directory`` (default the package's), with this machine's
    provenance; returns the path."""
    demo = demo_path(task)
    document = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "task": task,
        "demonstration": {
            "file": demo.relative_to(DATA_DIR).as_posix(),
            "sha256": file_sha256(demo),
            "samples": int(load_demonstration(demo).times.shape[0]),
        },
        "fit_config": asdict(config),
        "skill": {**skill.to_dict(), "name": task},
        "provenance": fit_provenance(),
    }
    path = committed_skill_path(task, directory)
    atomic_write_text(path, json.dumps(document, indent=1) + "\n")
    _read_cached.cache_clear()
    return path


def refit_committed_skill(
    task: str, n_via_points: int = DEFAULT_N_VIA_POINTS, directory: str | Path | None = None
) -> CommittedSkill:
    """Fit the task's shipped demonstration on this machine and write its skill file
    (``distgprl fit --task <task> --write``); returns what was written."""
    skill = fit_task_skill(task, n_via_points)
    path = write_skill_file(task, skill, FitConfig(n_via_points=n_via_points), directory)
    return read_skill_file(path)


def read_skill_file(path: str | Path) -> CommittedSkill:
    """Read and check a skill file (module docstring); `UserInputError` naming the file if
    it is missing or malformed."""
    path = Path(path)
    try:
        stat = path.stat()
    except OSError as error:
        raise UserInputError(
            f"{path}: the committed skill file is missing ({error.strerror}); "
            "write it with `distgprl fit --task <task> --write`"
        ) from None
    return _read_cached(str(path), (stat.st_mtime_ns, stat.st_size))


def load_committed_skill(
    task: str, n_via_points: int = DEFAULT_N_VIA_POINTS, directory: str | Path | None = None
) -> GPSkill:
    """The task's committed skill (never fitted here), checked against the shipped
    demonstration it was fitted to and the number of via-points asked for."""
    path = committed_skill_path(task, directory)
    committed = read_skill_file(path)
    refit = f"refit it with `distgprl fit --task {task} --write`"
    if committed.task != task:
        raise UserInputError(f"{path}: key 'task' is {committed.task!r}, expected {task!r}")
    shipped = file_sha256(demo_path(task))
    if committed.demonstration.get("sha256") != shipped:
        raise UserInputError(
            f"{path}: fitted to a demonstration with sha256 "
            f"{committed.demonstration.get('sha256')!r}, the shipped {demo_path(task).name} "
            f"has {shipped!r}; {refit}"
        )
    if committed.skill.n_via_points != n_via_points:
        raise UserInputError(
            f"{path}: key 'skill.via_times' has {committed.skill.n_via_points} via-points, "
            f"{n_via_points} asked for; {refit} --n-via-points {n_via_points}"
        )
    return committed.skill


@lru_cache(maxsize=16)
def _read_cached(path: str, stamp: tuple[int, int]) -> CommittedSkill:
    """`read_skill_file` once per file version (``stamp``: mtime and size)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise UserInputError(f"{path}: not a committed skill file ({error})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise UserInputError(f"{path}: not a committed skill file (key 'format' is not {FORMAT!r})")
    if data.get("format_version") != FORMAT_VERSION:
        raise UserInputError(
            f"{path}: key 'format_version' is {data.get('format_version')!r}, "
            f"this code reads {FORMAT_VERSION}"
        )
    for key, kind in (
        ("task", str),
        ("demonstration", dict),
        ("fit_config", dict),
        ("skill", dict),
        ("provenance", dict),
    ):
        if not isinstance(data.get(key), kind):
            raise UserInputError(f"{path}: key {key!r} is missing or not a {kind.__name__}")
    try:
        skill = GPSkill.from_dict(data["skill"])
        config = FitConfig(**data["fit_config"])
    except (KeyError, TypeError, ValueError) as error:
        raise UserInputError(f"{path}: key 'skill' is malformed ({error!r})") from None
    _check_skill(skill, Path(path))
    return CommittedSkill(
        data["task"], skill, config, data["demonstration"], data["provenance"], Path(path)
    )


def _check_skill(skill: GPSkill, path: Path) -> None:
    """Shapes, finiteness and signs of a committed skill's numbers (UserInputError)."""
    n = skill.n_via_points
    arrays = {
        "via_times": (skill.via_times, (n,)),
        "via_points": (skill.via_points, (n, 6)),
        "prior_mean": (skill.prior_mean, (6,)),
        "axis_scale": (skill.axis_scale, (6,)),
    }
    for key, (values, shape) in arrays.items():
        if values is None or np.shape(values) != shape or not np.all(np.isfinite(values)):
            raise UserInputError(f"{path}: key 'skill.{key}' must be {shape} finite numbers")
    if n < 2 or np.any(np.diff(skill.via_times) <= 0):
        raise UserInputError(f"{path}: key 'skill.via_times' must increase")
    if skill.axis_kernels is None or len(skill.axis_kernels) != 6:
        raise UserInputError(f"{path}: key 'skill.axis_kernels' must hold 6 kernels")
    for name, kernel in [("kernel", skill.kernel)] + [
        (f"axis_kernels[{a}]", k) for a, k in enumerate(skill.axis_kernels)
    ]:
        parameters = (kernel.length_scale, kernel.signal_variance, kernel.noise_variance)
        if not all(isinstance(v, float | int) and np.isfinite(v) for v in parameters) or not (
            kernel.length_scale > 0 and kernel.signal_variance > 0 and kernel.noise_variance >= 0
        ):
            raise UserInputError(
                f"{path}: key 'skill.{name}' must have a positive length scale and signal "
                "variance and a non-negative noise variance"
            )
    if not (np.isfinite(skill.duration) and skill.duration > 0):
        raise UserInputError(f"{path}: key 'skill.duration_s' must be a positive number")
