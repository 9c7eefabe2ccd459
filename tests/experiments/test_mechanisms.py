"""Reach for the mechanism table (`distgprl.experiments.mechanisms`) against hand
computations, the reach rule on the real layouts, the committed table's reach rows under two
BLAS kernels, and `distgprl mechanisms` end to end on two ci-size runs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from distgprl.adaptation.layout import ActionLayout, build_action_layout
from distgprl.config import load_config
from distgprl.experiments.mechanisms import layout_reach, residual_reach
from distgprl.methods import METHODS, get_method
from distgprl.schema import read_csv

#: ProMP-RRL as residual RL (``residual-control``; named ``promp-rrl`` from environment v6).
RESIDUAL_RL = next(
    name
    for name, spec in METHODS.items()
    if spec.action_mode == "residual-control" and spec.trainable
)

S0 = np.array([[0.5, 0.2, 0.0], [0.1, 0.6, 0.1], [0.0, -0.3, 0.4]])  # row sums 0.7 0.8 0.7
S1 = np.array([[0.9, 0.0, 0.0], [0.2, -0.2, 0.2], [0.0, 0.0, 1.0]])  # row sums 0.9 0.6 1.0
SCALE = np.array([0.1, 0.2, 0.3, 0.05, 0.05, 0.05])


def windowed(frozen=()):
    """Two windows of three via-points sharing via-point 3, S0 then S1 on every axis."""
    operators = np.stack([np.tile(S, (6, 1, 1)) for S in (S0, S1)])
    indices = np.array([[1, 2, 3], [3, 4, 5]])
    return ActionLayout(indices, operators, np.array([0.0, 0.5, 1.0]), SCALE, tuple(frozen))


def test_windowed_reach_by_hand():
    """One step: scale x row sums {0.7, 0.8, 0.7, 0.9, 0.6, 1.0}, so 0.6-1.0; one episode per
    via-point 1..5: 0.7, 0.8, 0.7 + 0.9 (the overlap, two steps), 0.6, 1.0, so 0.6-1.6."""
    reach = layout_reach(windowed())
    np.testing.assert_allclose(reach["one_step_min"], 0.6 * SCALE[:3])
    np.testing.assert_allclose(reach["one_step_max"], 1.0 * SCALE[:3])
    np.testing.assert_allclose(reach["episode_min"], 0.6 * SCALE[:3])
    np.testing.assert_allclose(reach["episode_max"], 1.6 * SCALE[:3])


def test_a_frozen_via_point_is_left_out():
    """Via-point 4 (row sum 0.6) frozen: one step 0.7-1.0, one episode 0.7-1.6."""
    reach = layout_reach(windowed(frozen=(4,)))
    np.testing.assert_allclose(reach["one_step_min"], 0.7 * SCALE[:3])
    np.testing.assert_allclose(reach["episode_min"], 0.7 * SCALE[:3])
    np.testing.assert_allclose(reach["episode_max"], 1.6 * SCALE[:3])


def test_global_reach_adds_up_over_the_three_steps():
    """Identity operators, every interior via-point at each of 3 steps: one step = the
    scale, one episode = 3 x the scale."""
    identity = np.tile(np.eye(4), (3, 6, 1, 1))
    layout = ActionLayout(np.tile(np.arange(1, 5), (3, 1)), identity, np.linspace(0, 1, 4), SCALE)
    reach = layout_reach(layout)
    np.testing.assert_allclose(reach["one_step_min"], SCALE[:3])
    np.testing.assert_allclose(reach["one_step_max"], SCALE[:3])
    np.testing.assert_allclose(reach["episode_min"], 3 * SCALE[:3])
    np.testing.assert_allclose(reach["episode_max"], 3 * SCALE[:3])


def test_residual_reach_is_slew_limited_per_step_and_its_range_per_episode():
    scale = np.array([0.2, 0.2, 0.1, 0.05, 0.05, 0.05])
    reach = residual_reach(scale, np.array([0.08, 0.12, 0.08]), 0.4)
    np.testing.assert_allclose(reach["one_step_min"], [0.04, 0.04, 0.02])
    np.testing.assert_allclose(reach["one_step_max"], [0.06, 0.06, 0.03])
    np.testing.assert_allclose(reach["episode_min"], scale[:3])
    np.testing.assert_allclose(reach["episode_max"], scale[:3])


@pytest.mark.parametrize("task", ["dcp", "dbm"])
def test_real_layouts_follow_the_reach_rule(task):
    """Protocol v6 rule 2 on the fitted skills: Dist-GPRL's smallest one-step reach is
    max(TC range, 0.1 m) on each axis; GPRL (global, episode_range, TC via-point frozen)
    reaches a third of its episode per step and at least the TC range per episode."""
    from distgprl.envs.tasks import load_task_skill
    from distgprl.sim.tasks import get_task

    env = load_config("ci", task=task).env
    spec = get_task(task)
    skill = load_task_skill(task, env.n_via_points)
    tc_range = np.asarray(spec.tc_range)
    floor = np.maximum(tc_range, env.minimum_position_reach)
    ours = layout_reach(build_action_layout(skill, env, get_method("dist-gprl"), (), tc_range))
    np.testing.assert_allclose(ours["one_step_min"], floor, rtol=1e-9)
    assert np.all(ours["episode_min"] >= floor - 1e-9)
    frozen = (skill.nearest_via_index(spec.interaction_time),)
    gprl = build_action_layout(skill, env, get_method("gprl"), frozen, tc_range)
    reach = layout_reach(gprl)
    np.testing.assert_allclose(reach["episode_min"], 3 * reach["one_step_min"])
    assert np.all(reach["episode_min"] >= floor - 1e-9)


REPOSITORY = Path(__file__).resolve().parents[2]

REACH_TABLE = """
import json, sys
from distgprl.experiments.mechanisms import reach_rows
from distgprl.machine import numerics_fingerprint
from distgprl.report.mechanisms import mechanism_texts

rows = reach_rows(sys.argv[1], "paper")
csv_text, markdown, _ = mechanism_texts("paper", rows)
exact = [{key: repr(value) for key, value in row.items()} for row in rows]
print(json.dumps(
    {"numerics": numerics_fingerprint(), "csv": csv_text, "markdown": markdown, "rows": exact}
))
"""
"""Prints the mechanism table's reach rows of the committed `paper` runs: as the table's CSV
and Markdown write them, and every number as its repr (all its bits)."""
FITTED_AT_LOAD = {"gate_max"}
"""Reach-row fields computed from a fit made when the environment is built, with BLAS, not
from a committed one: ProMP-RRL's variance gate (its ProMP over 20 demonstrations). Its last
bits follow the BLAS kernel (DCP: 0.9604333359703792 under the default AVX-512 kernel,
0.9604333359703835 under Haswell); the table writes it to two decimals."""


def reach_table_under(kernel: str | None) -> dict:
    """`REACH_TABLE`'s output in a process whose OpenBLAS kernel is ``kernel`` (None: the
    default numpy picks; read when numpy loads, so it needs a process of its own)."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    if kernel is not None:
        env["OPENBLAS_CORETYPE"] = kernel
    completed = subprocess.run(
        [sys.executable, "-c", REACH_TABLE, str(REPOSITORY / "results")],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    result: dict = json.loads(completed.stdout.strip().splitlines()[-1])
    return result


def test_the_committed_reach_rows_are_the_same_under_both_blas_kernels():
    """Issue 68: the mechanism table's reach rows, which rebuild each committed run's
    environment from the committed skill fit (`reach_rows`), are the same bit for bit under
    numpy's default BLAS kernel and OpenBLAS' AVX2 kernel (``OPENBLAS_CORETYPE=Haswell``,
    checked to take effect) but for the fields of `FITTED_AT_LOAD`; the table's CSV and
    Markdown reach rows are the same byte for byte, and the CSV lines are the committed
    table's (`tests/report/test_committed_tables.py` checks the rest of the table)."""
    default, haswell = reach_table_under(None), reach_table_under("Haswell")
    assert haswell["numerics"].startswith("openblas-Haswell_"), haswell["numerics"]
    assert default["rows"], "no committed trainable run under results/paper"
    assert len(default["rows"]) == len(haswell["rows"])
    for ours, theirs in zip(default["rows"], haswell["rows"], strict=True):
        differing = sorted(k for k in ours.keys() | theirs.keys() if ours.get(k) != theirs.get(k))
        assert set(differing) <= FITTED_AT_LOAD, (ours, theirs, default["numerics"])
    assert default["csv"] == haswell["csv"]
    assert default["markdown"] == haswell["markdown"]
    committed = (REPOSITORY / "paper_figures" / "mechanisms_paper.csv").read_text()
    reach_lines = [line for line in committed.splitlines() if line.startswith("reach,")]
    assert default["csv"].splitlines()[1:] == reach_lines


def test_the_command_tabulates_two_trained_ci_runs(tmp_path):
    """`distgprl train --preset ci` for Dist-GPRL and ProMP-RRL on DCP, then `distgprl
    mechanisms`: reach for both (ProMP-RRL's residual), the shaping and gradient shares for
    Dist-GPRL only, the verdicts printed, CSV (with sidecar) and Markdown written."""
    from distgprl.cli import app

    runner = CliRunner()
    env = {"COLUMNS": "200", "NO_COLOR": "1"}
    for method in ("dist-gprl", RESIDUAL_RL):
        args = ["train", "--method", method, "--task", "dcp", "--preset", "ci"]
        result = runner.invoke(app, [*args, "--root", str(tmp_path)], env=env)
        assert result.exit_code == 0, result.output
    out = tmp_path / "figures"
    args = ["mechanisms", "--preset", "ci", "--root", str(tmp_path), "--out-dir", str(out)]
    result = runner.invoke(app, args, env=env)
    assert result.exit_code == 0, result.output
    assert "Reach: the one-episode reach covers the TC range" in result.output
    assert "λ_sim L_sim / Q:" in result.output and "outside C_safe:" in result.output
    _, rows = read_csv(out / "mechanisms_ci.csv")
    reach = {(r["method"], r["item"]): r for r in rows if r["section"] == "reach"}
    assert set(reach) == {(m, a) for m in ("dist-gprl", RESIDUAL_RL) for a in "xyz"}
    assert reach[RESIDUAL_RL, "x"]["kind"] == "residual"
    assert float(reach[RESIDUAL_RL, "y"]["episode_min_m"]) == pytest.approx(0.2)
    assert reach["dist-gprl", "x"]["covers_tc_range"] == "yes"
    assert float(reach["dist-gprl", "x"]["one_step_min_m"]) == pytest.approx(0.2, rel=1e-5)
    shares = [r for r in rows if r["section"] == "return_share"]
    assert {(r["method"], r["where"]) for r in shares} == {
        ("dist-gprl", "final"),
        ("dist-gprl", "best"),
    }
    assert all(r["meets_criterion"] != "not recorded" for r in shares)
    gradients = [r for r in rows if r["section"] == "gradient_share"]
    assert {r["method"] for r in gradients} == {"dist-gprl"}
    active = [r for r in gradients if r["item"] == "l_hap_active"]
    assert len(active) == 3 and all(r["meets_criterion"] != "not recorded" for r in active)
    markdown = (out / "mechanisms_ci.md").read_text()
    assert "### Reach of a raw action" in markdown and "### Verdicts" in markdown


@pytest.mark.parametrize("method", ["dist-gprl", RESIDUAL_RL])
def test_episode_rows_split_the_return_into_its_terms(method):
    """`run_episode`'s ``return_tc`` + ``return_sd`` + ``return_ga`` is the return (no
    signature reward here): r_sd <= 0; the residual-RL env has r_tc's terms only."""
    from distgprl.experiments.factories import make_env
    from distgprl.experiments.rollout import run_episode
    from distgprl.identity import resolve_run

    env = make_env(resolve_run("dcp", method, 0, "ci"))
    try:
        rng = np.random.default_rng(0)
        for tc in env.spec_task.training_curve_tcs(2):
            row = run_episode(env, tc, lambda _: rng.uniform(-1, 1, env.action_space.shape))
            parts = row["return_tc"] + row["return_sd"] + row["return_ga"]
            assert row["return"] == pytest.approx(parts, abs=1e-12)
            assert row["return_sd"] <= 0.0
            if method == RESIDUAL_RL:
                assert row["return_sd"] == row["return_ga"] == 0.0
    finally:
        env.close()
