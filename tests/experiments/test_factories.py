"""`distgprl.experiments.factories.load_model`: a saved model is loaded only into an
environment whose observation and action spaces are the model's; anything else is one clear
`UserInputError` (what `distgprl evaluate` and the hardware trials report)."""

from __future__ import annotations

import pytest

from distgprl.errors import UserInputError
from distgprl.experiments.factories import load_model, make_agent, make_env
from distgprl.identity import resolve_run


@pytest.fixture(scope="module")
def saved_dcp_model(tmp_path_factory):
    """An untrained dcp ``gprl-d`` agent (`ci` preset) saved as a run's ``model.zip``."""
    run = resolve_run("dcp", "gprl-d", 0, "ci")
    env = make_env(run)
    try:
        path = tmp_path_factory.mktemp("model") / "model.zip"
        make_agent(env, run).save(path)
    finally:
        env.close()
    return path


def test_a_model_loads_into_the_environment_of_its_spaces(saved_dcp_model):
    env = make_env(resolve_run("dcp", "gprl-d", 0, "ci"))
    try:
        model = load_model(saved_dcp_model, env, "dcp", "gprl-d")
        assert model.observation_space == env.observation_space
        assert model.action_space == env.action_space
    finally:
        env.close()


def test_a_model_of_other_spaces_is_refused(saved_dcp_model):
    """A windowed method's model in the global method's environment (78 actions, not 30)."""
    env = make_env(resolve_run("dcp", "gprl", 0, "ci"))
    try:
        with pytest.raises(UserInputError, match="spaces do not match the dcp/gprl env"):
            load_model(saved_dcp_model, env, "dcp", "gprl")
    finally:
        env.close()


def test_an_unreadable_model_is_refused(tmp_path):
    path = tmp_path / "model.zip"
    path.write_bytes(b"not a zip")
    env = make_env(resolve_run("dcp", "demo", 0, "ci"))
    try:
        with pytest.raises(UserInputError, match="cannot load model"):
            load_model(path, env, "dcp", "demo")
    finally:
        env.close()
