"""Which trained policy a hardware or twin trial runs (`load_trial_policy`): the run's final
``model.zip`` where it is on disk (or the one ``--model`` names), else the best policy the run
ships (`distgprl.experiments.policies.SHIPPED_POLICY`, hash-checked), so that a fresh clone
runs Table I's policy without training; the provenance (file, SHA-256, config hash, which
policy) goes into the trial file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from distgprl.errors import UserInputError

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


def load_trial_policy(method: str, seed: int, preset: str, root, model_path, env):
    """(policy or None, provenance): the deterministic policy of the trained run and which
    model it is (path, SHA-256, the config hash of the run folder it sits in, if any): its
    final ``model.zip`` where it is on disk (or ``model_path``), else the best policy the run
    ships (`_shipped_policy`: a fresh clone runs Table I's policy without training)."""
    from distgprl.experiments.factories import load_model
    from distgprl.experiments.policies import SHIPPED_POLICY
    from distgprl.experiments.rollout import deterministic_policy
    from distgprl.io import file_sha256
    from distgprl.schema import read_json, run_dir

    if not env.method.trainable:  # the references (`demo`, `promp-nominal`) run no policy
        return None, {}
    path = (
        Path(model_path) if model_path else run_dir(root, preset, "dbm", method, seed) / "model.zip"
    )
    folder = run_dir(root, preset, "dbm", method, seed)
    if not path.exists() and not model_path and (folder / SHIPPED_POLICY).exists():
        return _shipped_policy(method, seed, preset, folder, env)
    if not path.exists():
        raise UserInputError(
            f"{path}: no trained model; run `distgprl train --method {method} --task dbm "
            f"--seed {seed} --preset {preset}` first (or pass --model)"
        )
    model = load_model(path, env, "dbm", method)
    provenance: dict[str, Any] = {"model": str(path), "model_sha256": file_sha256(path)}
    config_path = path.parent / "config.json"
    if config_path.exists():
        provenance["run_config_hash"] = read_json(config_path).get("config_hash")
    return deterministic_policy(model), provenance
