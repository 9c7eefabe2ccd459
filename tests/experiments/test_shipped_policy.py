"""The trained policies ship (issue 50 item 6): each committed run carries the actor Table I
evaluates, hash-checked; a machine without the run's checkpoints (a fresh clone) loads it and
acts exactly as the checkpointed best policy; a changed file is an error, never loaded.

Across machines: the committed-runs test checks files and hashes only (no floats); the
equivalence test trains its own run on this machine and compares the shipped actor's actions
with the checkpointed one's bit for bit (same machine, same weights)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

import distgprl
from distgprl.errors import UserInputError
from distgprl.experiments.checkpoints import checkpoint_dir
from distgprl.experiments.policies import (
    SHIPPED_POLICY,
    SHIPPED_POLICY_RECORD,
    run_best_selection,
    ship_best_policy,
    verified_shipped_policy,
)
from distgprl.methods import METHODS
from distgprl.schema import read_csv

RESULTS = Path(__file__).resolve().parents[2] / "results" / "paper"


def committed_runs() -> list[Path]:
    return sorted(
        p.parent
        for p in RESULTS.glob("*/*/seed*/done.json")
        if METHODS[p.parent.parent.name].trainable
    )


def test_every_committed_trained_run_ships_its_best_actor_with_a_matching_hash():
    """Every finished trained run of the paper preset has policy_best.pt whose SHA-256 is
    the recorded one and whose step is the run's best trained learning-curve point (after
    learning_starts: never step 0, protocol v8 rule 2), with its comparison against the
    untrained step-0 point recorded as the curve gives it."""
    for folder in committed_runs():
        path, record = verified_shipped_policy(folder)
        selection = run_best_selection(folder)
        assert record["step"] == selection.step > selection.learning_starts > 0, folder
        assert record.get("beats_untrained") == selection.beats_untrained, folder
        assert path.stat().st_size == record["bytes"] < 1_000_000, folder  # the actor only


@pytest.fixture(scope="module")
def shipped_run(tmp_path_factory):
    """A 120-step ci Dist-GPRL run on DCP with its best actor shipped; returns (root, the
    checkpointed best policy's actions on a few observations, those observations)."""
    root = tmp_path_factory.mktemp("shipped")
    folder = distgprl.train(
        "dcp", "dist-gprl", seed=0, preset="ci", steps=120, root=root, evaluate=False,
        progress=False,
    )  # fmt: skip
    ship_best_policy(folder)
    policy = distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root=root, policy="best")
    assert policy.selected["policy_step"] == 120  # the one trained point (learning_starts 60)
    env = distgprl.make_env("dcp", "dist-gprl", preset="ci")
    observations = []
    try:
        for seed in range(3):
            observations.append(env.reset(seed=seed)[0])
    finally:
        env.close()
    actions = [policy.predict(obs) for obs in observations]
    return root, folder, observations, actions


def test_the_shipped_actor_acts_as_the_checkpointed_best_policy(shipped_run):
    """With model.zip and the checkpoints gone, load_policy(best) loads the shipped actor
    and its deterministic actions equal the checkpointed best policy's bit for bit."""
    root, folder, observations, actions = shipped_run
    (folder / "model.zip").unlink()
    shutil.rmtree(checkpoint_dir(folder))
    policy = distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root=root, policy="best")
    assert policy.selected["policy_source"] == SHIPPED_POLICY
    for obs, action in zip(observations, actions, strict=True):
        np.testing.assert_array_equal(policy.predict(obs), action)
    with pytest.raises(UserInputError, match="ships only its best policy"):
        distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root=root, policy="final")


def test_a_changed_shipped_actor_is_refused_with_both_hashes(shipped_run, tmp_path):
    root, folder, _, _ = shipped_run
    copy = tmp_path / "ci" / "dcp" / "dist-gprl" / "seed0"
    shutil.copytree(folder, copy)
    data = bytearray((copy / SHIPPED_POLICY).read_bytes())
    data[-1] ^= 0xFF
    (copy / SHIPPED_POLICY).write_bytes(bytes(data))
    with pytest.raises(UserInputError, match="does not match the .* recorded in policy_best"):
        distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root=tmp_path, policy="best")
    (copy / SHIPPED_POLICY).unlink()
    (copy / SHIPPED_POLICY_RECORD).unlink()
    (copy / "model.zip").unlink(missing_ok=True)
    with pytest.raises(UserInputError, match="neither the trained model"):
        distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root=tmp_path, policy="best")


def test_twin_trials_run_the_policy_they_name_and_never_switch(tmp_path):
    """`distgprl hardware --backend twin` on a run folder with only its small files (a clone):
    the final policy Table II counts is not there, so the default is an error that names
    ``--policy best`` (no silent switch to another policy); ``policy="best"`` runs Table I's
    shipped best actor, and the trial file names it; a file `trial_file_exclusion` lists."""
    from functools import partial

    from distgprl.experiments.trial_policy import load_trial_policy
    from distgprl.hardware.trials import run_trials
    from distgprl.hardware.twin import TwinConfig
    from distgprl.schema import trial_file_exclusion

    folder = distgprl.train(
        "dbm", "gprl", seed=0, preset="ci", steps=120, root=tmp_path, evaluate=False,
        progress=False,
    )  # fmt: skip
    ship_best_policy(folder)
    (folder / "model.zip").unlink()
    shutil.rmtree(checkpoint_dir(folder))
    trials = dict(
        trials=1, method="gprl", seed=0, root=tmp_path, preset="ci",
        twin_config=TwinConfig(width=640, height=480), echo=lambda _: None,
    )  # fmt: skip
    with pytest.raises(UserInputError, match="no final policy on disk.*--policy best"):
        run_trials(**trials, load_policy=load_trial_policy)
    report = run_trials(**trials, load_policy=partial(load_trial_policy, policy="best"))
    meta, rows = read_csv(report.path)
    provenance = meta["policy"]
    assert provenance["model"].endswith(SHIPPED_POLICY)
    assert provenance["policy"].startswith("best (shipped")
    assert len(rows) == 1
    assert "ran the best policy" in trial_file_exclusion(meta, provenance["run_config_hash"])
