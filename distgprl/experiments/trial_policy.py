"""Which trained policy a hardware or twin trial runs (`load_trial_policy`), by name: the
run's final ``model.zip`` (or the file ``--model`` names), or the best policy the run ships
(`distgprl.experiments.policies.SHIPPED_POLICY`, hash-checked), which a fresh clone has without
training; the provenance (file, SHA-256, config hash, which policy) goes into the trial file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from distgprl.errors import UserInputError
from distgprl.trial_protocol import (
    BEST_POLICY,
    FINAL_POLICY,
    GIVEN_POLICY,
    TABLE2_POLICY,
    check_trial_policy,
)

__all__ = ["load_trial_policy"]


def _shipped_policy(method: str, seed: int, preset: str, folder: Path, env):
    """(policy, provenance) of the actor the run ships (Table I's best policy,
    `distgprl.experiments.policies.SHIPPED_POLICY`, hash-checked), for a machine without the
    run's ``model.zip`` (a fresh clone)."""
    from distgprl.experiments.factories import make_env
    from distgprl.experiments.policies import SHIPPED_POLICY, load_trained_policy
    from distgprl.experiments.rollout import deterministic_policy
    from distgprl.identity import resolve_run

    run = resolve_run("dbm", method, seed, preset)
    sim_env = make_env(run)
    try:
        trained = load_trained_policy(run, folder, sim_env, "best")
    finally:
        sim_env.close()
    model = trained.model
    if model.observation_space != env.observation_space or model.action_space != env.action_space:
        raise UserInputError(f"{folder / SHIPPED_POLICY}: policy spaces do not match the cell's")
    provenance: dict[str, Any] = {
        "model": str(folder / SHIPPED_POLICY),
        "model_sha256": trained.selected["policy_sha256"],
        "run_config_hash": trained.run.hash,
        "policy": f"best (shipped, curve step {trained.selected['policy_step']})",
    }
    return deterministic_policy(model), provenance


def load_trial_policy(
    method: str,
    seed: int,
    preset: str,
    root,
    model_path,
    env,
    policy: str = TABLE2_POLICY,
):
    """(policy or None, provenance): the deterministic policy of the trained run and which
    model it is (path, SHA-256, the config hash of the run folder it sits in, which policy).

    ``policy`` names it (`distgprl.trial_protocol.TRIAL_POLICIES`): ``final``, the run's
    ``model.zip`` (or ``model_path``), on disk only where the run was trained; ``best``, the
    best policy the run ships (`_shipped_policy`: Table I's, in every clone). A missing one
    is a `UserInputError` that says what is on disk, never a silent switch to the other.
    A reference (``demo``, ``promp-nominal``) runs no policy: (None, {})."""
    from distgprl.experiments.factories import load_model
    from distgprl.experiments.rollout import deterministic_policy
    from distgprl.io import file_sha256
    from distgprl.schema import read_json, run_dir

    check_trial_policy(policy)
    if not env.method.trainable:  # the references (`demo`, `promp-nominal`) run no policy
        return None, {}
    folder = run_dir(root, preset, "dbm", method, seed)
    if policy == BEST_POLICY:
        if model_path:
            raise UserInputError(
                f"{model_path}: a policy file runs as given; the best policy is the one the "
                "run ships: give --model or --policy best, not both"
            )
        return _shipped_policy(method, seed, preset, folder, env)
    path = Path(model_path) if model_path else folder / "model.zip"
    if not path.exists():
        raise UserInputError(
            f"{path}: {_no_final_policy(method, seed, preset, folder, model_path)}"
        )
    model = load_model(path, env, "dbm", method)
    provenance: dict[str, Any] = {"model": str(path), "model_sha256": file_sha256(path)}
    config_path = path.parent / "config.json"
    if config_path.exists():
        provenance["run_config_hash"] = read_json(config_path).get("config_hash")
    provenance["policy"] = FINAL_POLICY if not model_path else GIVEN_POLICY
    return deterministic_policy(model), provenance


def _no_final_policy(method: str, seed: int, preset: str, folder: Path, model_path) -> str:
    """What to do when the final policy is not on disk: the run's best policy where it ships
    one (a clone), else train the run (or give ``--model``)."""
    from distgprl.experiments.policies import SHIPPED_POLICY

    train = f"`distgprl train --method {method} --task dbm --seed {seed} --preset {preset}`"
    if model_path or not (folder / SHIPPED_POLICY).exists():
        return f"no trained model; run {train} first (or pass --model)"
    return (
        f"no final policy on disk (the run ships its best policy, {SHIPPED_POLICY}, only): "
        "pass --policy best to run that one, Table I's (Table II counts the final policy's "
        f"trials; the best policy's are tabulated beside it), or run {train} to train the "
        "final one"
    )
