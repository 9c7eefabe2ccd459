"""Run identity: what a (task, method, seed, preset) run is, and its config hash.

A run's config hash (:attr:`RunSpec.hash`, :func:`distgprl.io.config_hash` of
:meth:`RunSpec.to_dict`) names its configuration in every result file; the reports count a
run only if the hash recorded in its folder is the one :func:`resolve_run` gives now. Any
change to what enters the hash makes committed runs stale, so the definition must only grow
by fields whose default adds nothing (``scene_revision`` 0, no ``method_revisions``,
`distgprl.methods.HASH_STABLE_DEFAULTS`).

No torch, pybullet or gymnasium import: the reports use it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from distgprl.config import load_config
from distgprl.config_types import ENVIRONMENT_VERSION, Config
from distgprl.data import DATA_DIR, SCENE_REVISIONS, check_task_name
from distgprl.errors import UserInputError
from distgprl.io import config_hash, sha256_hex
from distgprl.methods import MethodSpec, get_method
from distgprl.schema import EVALUATION_SEED, TRAINING_CURVE_SEED

__all__ = ["SWEEP_SEEDS", "RunSpec", "method_revisions", "resolve_run"]


def method_revisions(method: MethodSpec) -> dict[str, int]:
    """Revisions of the method's parts, for the config hash (beside the environment
    version, which is in every hash).

    Only the parts a method uses appear, so fixing one part leaves the hashes (and committed
    results) of methods without it valid: ``r_ga`` 1 — the gradient-alignment reward at the
    via-points before the update (Eq. grad_alignment_reward); ``l_hap`` 1 — L_hap over C_safe
    without the points the moving obstacles block.
    """
    revisions = {}
    if method.distance_rewards:
        revisions["r_ga"] = 1
    if method.hap_prior:
        revisions["l_hap"] = 1
    return revisions


@dataclass(frozen=True)
class RunSpec:
    """Everything that identifies a run."""

    task: str
    method: MethodSpec
    seed: int
    config: Config

    def to_dict(self) -> dict[str, Any]:
        data: dict[str, Any] = {
            "task": self.task,
            "method": self.method.to_dict(),
            "seed": self.seed,
            "config": self.config.to_dict(),
            "environment_version": ENVIRONMENT_VERSION,
        }
        if SCENE_REVISIONS[self.task]:  # see `distgprl.data.SCENE_REVISIONS`
            data["scene_revision"] = SCENE_REVISIONS[self.task]
        skill = committed_skill_digest(self.task)
        if skill is not None:  # a refitted skill (`distgprl fit --write`) makes runs stale
            data["skill_sha256"] = skill
        revisions = method_revisions(self.method)
        if revisions:
            data["method_revisions"] = revisions
        return data

    @property
    def hash(self) -> str:
        return config_hash(self.to_dict())


def committed_skill_digest(task: str) -> str | None:
    """SHA-256 of the task's committed skill file (``data/skills/<task>.json``, every number
    the skill fit decides, `distgprl.skill.committed`), or None for a task without one."""
    path = DATA_DIR / "skills" / f"{task}.json"
    return sha256_hex(path.read_bytes()) if path.exists() else None


SWEEP_SEEDS = (0, 1, 2, 3, 4)
"""The seeds a sweep trains by default: five per method and task (three seeds could not settle
any ablation)."""

SEED_LIMIT = 2**32
"""Seeds are integers in ``[0, SEED_LIMIT)`` (what NumPy, gymnasium and torch accept)."""


def check_seed(seed: int) -> int:
    """``seed`` as an int if it is a valid run seed, else a `UserInputError`."""
    if isinstance(seed, bool) or int(seed) != seed or not 0 <= int(seed) < SEED_LIMIT:
        raise UserInputError(f"seed {seed!r} must be an integer from 0 to 2**32 - 1")
    if int(seed) in (EVALUATION_SEED, TRAINING_CURVE_SEED):
        raise UserInputError(
            f"seed {seed} is reserved: it draws the evaluation / learning-curve TCs, which no "
            f"run may train on"
        )
    return int(seed)


def resolve_run(
    task: str, method: str, seed: int, preset: str = "paper", steps: int | None = None
) -> RunSpec:
    """Validate a run request and resolve its configuration, before anything touches the
    disk: the task, method and preset names, the seed (`check_seed`) and, if given, the
    total RL steps (a positive multiple of the episode length, ``env.n_windows`` RL steps).
    `train_run`, `evaluate_run` and the sweep's `plan_jobs` all start here.

    Raises:
        UserInputError: one line saying what is wrong with which input.
    """
    check_task_name(task)
    spec = get_method(method)
    seed = check_seed(seed)
    overrides = None
    if steps is not None:
        episode = load_config(preset, task=task).env.n_windows
        if isinstance(steps, bool) or int(steps) != steps or steps <= 0 or steps % episode:
            raise UserInputError(
                f"steps {steps!r} must be a positive multiple of the episode length "
                f"({episode} RL steps)"
            )
        overrides = {"run": {"total_steps": int(steps)}}
    config = load_config(preset, task=task, overrides=overrides)
    return RunSpec(task, spec, seed, config)
