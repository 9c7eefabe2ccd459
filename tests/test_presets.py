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
def test_correlated_preset_is_the_paper_preset_but_for_the_correlation_length_scale(task):
    """The exploration preset changes one thing (K's length scale in S), so its runs compare
    with the paper runs of the same method and seed."""
    paper, correlated = load_config("paper", task=task), load_config("correlated", task=task)
    assert correlated.env.correlation_length_scale == pytest.approx(1 / 7)
    assert replace(correlated.env, correlation_length_scale=0.0) == paper.env
    assert (correlated.sac, correlated.run) == (paper.sac, paper.run)


@pytest.mark.parametrize("task", ["dcp", "dbm"])
def test_unit_covariance_preset_is_the_paper_preset_with_v4s_operator(task):
    """The `unit-covariance` ablation differs from `paper` only in the scale of K in S."""
    paper, unit = load_config("paper", task=task), load_config("unit-covariance", task=task)
    assert paper.env.covariance_scale == "signal" and unit.env.covariance_scale == "unit"
    assert replace(unit.env, covariance_scale="signal") == paper.env
    assert (unit.sac, unit.run) == (paper.sac, paper.run)
