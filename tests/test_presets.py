"""The shipped presets: one SAC configuration and one MDP for every task; only budgets differ."""

from __future__ import annotations

from dataclasses import replace

import pytest

from distgprl.config import load_config


@pytest.mark.parametrize("preset", ["paper", "ci"])
def test_tasks_share_the_mdp_and_sac_configuration(preset):
    dcp, dbm = load_config(preset, task="dcp"), load_config(preset, task="dbm")
    assert dcp.env == dbm.env
    assert dcp.sac == dbm.sac
    # Only the step budget may differ between tasks.
    assert replace(dcp.run, total_steps=dbm.run.total_steps) == dbm.run


def test_paper_preset_budgets():
    assert load_config("paper", task="dcp").run.total_steps == 30_000
    assert load_config("paper", task="dbm").run.total_steps == 45_000
    assert load_config("paper", task="dbm").run.eval_episodes == 100


@pytest.mark.parametrize("task", ["dcp", "dbm"])
@pytest.mark.parametrize("reading", ["unit", "signal", "correlation"])
def test_operator_study_presets_are_the_paper_preset_with_another_operator(task, reading):
    """Each operator-study preset differs from `paper` only in the reading of K in S
    (environment v6: Table I's is the zero-mean GP), so its runs compare with Table I's."""
    paper, study = load_config("paper", task=task), load_config(f"operator-{reading}", task=task)
    assert paper.env.covariance_scale == "zero-mean" and study.env.covariance_scale == reading
    assert replace(study.env, covariance_scale="zero-mean") == paper.env
    assert (study.sac, study.run) == (paper.sac, paper.run)


STUDY_PRESETS = (
    "operator-correlation",
    "operator-signal",
    "operator-signal-uncoupled",
    "operator-unit",
)

COMMITTED_CONFIG_HASHES = {
    ("operator-correlation", "dcp"): "69e402b3a01acccd",
    ("operator-correlation", "dbm"): "0cd8b666212456dc",
    ("operator-signal", "dcp"): "f6a2fbc3a65325f2",
    ("operator-signal", "dbm"): "66775c035087139a",
    ("operator-signal-uncoupled", "dcp"): "bb86a7f17d5681bc",
    ("operator-signal-uncoupled", "dbm"): "a78e6ca6aee50dd6",
    ("operator-unit", "dcp"): "7a86c34b1ba55317",
    ("operator-unit", "dbm"): "e35eef7116c65e23",
    ("paper", "dcp"): "24720bb451218cab",
    ("paper", "dbm"): "6818e3b88c650e3b",
}
"""`distgprl.io.config_hash` of each preset's resolved configuration per task, as the presets
resolved when the study presets still copied `paper`'s run block (before ``extends``): their
runs' config hashes, and so the study runs already trained, stay valid."""


@pytest.mark.parametrize(("preset", "task"), sorted(COMMITTED_CONFIG_HASHES))
def test_each_preset_resolves_to_the_configuration_its_runs_were_trained_with(preset, task):
    from distgprl.io import config_hash

    assert (
        config_hash(load_config(preset, task=task).to_dict())
        == (COMMITTED_CONFIG_HASHES[(preset, task)])
    )


@pytest.mark.parametrize("preset", STUDY_PRESETS)
def test_a_study_preset_extends_paper_in_a_few_lines(preset):
    """A study preset says ``extends: paper`` and only what differs (comments included, at
    most 15 lines), so Table I's budgets have one source."""
    import yaml

    from distgprl.config import PRESET_DIR

    text = (PRESET_DIR / f"{preset}.yaml").read_text()
    assert len(text.splitlines()) <= 15
    data = yaml.safe_load(text)
    assert data["extends"] == "paper"
    assert "run" not in data and "tasks" not in data
