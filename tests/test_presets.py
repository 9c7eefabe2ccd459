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
