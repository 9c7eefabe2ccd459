"""The public Python API (distgprl/api.py, re-exported lazily by distgprl/__init__.py): a
notebook can train a run, load its policy and act in the run's environment; importing
``distgprl`` loads neither torch nor pybullet."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import distgprl
from distgprl import config as config_module
from distgprl.errors import UserInputError


def test_import_distgprl_is_cheap_and_exports_the_api_lazily():
    code = (
        "import sys, distgprl; names = ('torch', 'pybullet', 'stable_baselines3'); "
        "loaded = lambda: [m for m in names if m in sys.modules]; assert not loaded(), loaded(); "
        "assert callable(distgprl.load_policy) and callable(distgprl.make_env); "
        "assert not loaded(), loaded(); print(sorted(distgprl.__all__))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    for name in ("make_env", "load_policy", "train", "evaluate", "fit_skill", "Policy"):
        assert name in result.stdout
    with pytest.raises(AttributeError):
        distgprl.no_such_function  # noqa: B018


@pytest.fixture(scope="module")
def trained_root(tmp_path_factory):
    """A 120-step `ci` Dist-GPRL run on DCP, trained through `distgprl.train`."""
    root = tmp_path_factory.mktemp("api_runs")
    folder = distgprl.train(
        "dcp", "dist-gprl", seed=0, preset="ci", steps=120, root=root, evaluate=False,
        progress=False,
    )  # fmt: skip
    assert folder == root / "ci" / "dcp" / "dist-gprl" / "seed0"
    assert (folder / "model.zip").is_file()
    return root


def test_a_loaded_policy_acts_on_an_observation_of_make_envs_environment(trained_root):
    policy = distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root=trained_root)
    env = distgprl.make_env("dcp", "dist-gprl", preset="ci")
    try:
        obs, _ = env.reset(seed=1)
        action = policy.predict(obs)
        assert action.shape == env.action_space.shape and action.dtype == np.float32
        assert np.all(np.abs(action) <= 1.0) and np.all(np.isfinite(action))
        # the deterministic action is the SAC actor's mean action (what evaluation uses)
        reference, _ = policy.model.predict(obs, deterministic=True)
        np.testing.assert_allclose(action, reference, atol=1e-5)
        assert np.array_equal(policy(obs), action)
        sampled = policy.predict(obs, deterministic=False)
        assert sampled.shape == action.shape and not np.allclose(sampled, action)
        env.step(action)
    finally:
        env.close()


def test_evaluate_through_the_api_writes_the_runs_files(trained_root):
    summary = distgprl.evaluate(
        "dcp", "dist-gprl", 0, preset="ci", episodes=2, root=trained_root, progress=False
    )
    assert 0.0 <= summary["success_rate"] <= 1.0
    assert (trained_root / "ci" / "dcp" / "dist-gprl" / "seed0" / "evaluation_n2.csv").is_file()


def test_the_demo_reference_policy_is_the_zero_action_and_needs_no_run(tmp_path):
    policy = distgprl.load_policy("dcp", "demo", 0, preset="ci", root=tmp_path)
    env = distgprl.make_env("dcp", "demo", preset="ci")
    try:
        obs, _ = env.reset(seed=1)
        assert np.array_equal(policy.predict(obs), np.zeros(env.action_space.shape))
    finally:
        env.close()


def test_load_policy_errors_are_user_input_errors(tmp_path):
    with pytest.raises(UserInputError, match="no trained model"):
        distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root=tmp_path)
    with pytest.raises(UserInputError, match="'final' or 'best'"):
        distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root=tmp_path, policy="top")
    with pytest.raises(UserInputError, match="unknown method"):
        distgprl.load_policy("dcp", "nope", 0, preset="ci", root=tmp_path)


def test_make_env_takes_a_users_preset_file(tmp_path, monkeypatch):
    monkeypatch.setenv(config_module.USER_PRESETS_ENV, "")
    path = tmp_path / "mine.yaml"
    path.write_text("env:\n  position_action_scale: 0.05\n")
    env = distgprl.make_env("dcp", "gprl-d", config=path)
    try:
        assert env.config.position_action_scale == 0.05
    finally:
        env.close()


def test_fit_skill_fits_a_shipped_demonstration(tmp_path):
    output = distgprl.fit_skill("dcp", out_dir=tmp_path)
    assert output.json_path.is_file() and output.skill.via_points.shape[0] == 15
    with pytest.raises(UserInputError, match="exactly one of task or demo"):
        distgprl.fit_skill()
