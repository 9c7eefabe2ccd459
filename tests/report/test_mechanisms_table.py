"""The mechanism table's cells (`distgprl.report.mechanisms`) from synthetic result frames,
and the table written from a synthetic results tree: an episode that never comes within d_min
is left out, one with r_tc = 0 is counted and left out, files that predate the columns say
"not recorded", and the writer imports neither torch nor pybullet."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

from distgprl.identity import resolve_run
from distgprl.report.mechanisms import (
    NOT_RECORDED,
    gradient_cells,
    gradient_points,
    return_cells,
    rule_one_cells,
    write_mechanisms,
)
from distgprl.schema import EVALUATION_FIELDS, PROGRESS_FIELDS, read_csv, write_csv, write_json

ROOT = Path(__file__).resolve().parents[2]
D_MIN = 0.03


def episode(clearance, tc, sd, ga):
    """An evaluation row: min clearance (m), the summed r_tc, r_sd and lambda_ga r_ga."""
    return {
        **dict.fromkeys(EVALUATION_FIELDS, 0),
        "min_clearance": clearance,
        "return": tc + sd + ga,
        "return_tc": tc,
        "return_sd": sd,
        "return_ga": ga,
    }


EPISODES = [
    episode(0.010, 2.0, -0.5, 0.2),  # within d_min: r_sd 25 %, r_ga 10 %
    episode(0.020, -1.0, -0.3, 0.05),  # within: 30 %, 5 %
    episode(0.100, 1.0, -5.0, 0.6),  # never within d_min: left out whatever its shares
    episode(0.029, 0.0, -0.1, 0.1),  # within, r_tc = 0: no ratio, counted
]


KEYS = {"task": "dcp", "method": "dist-gprl", "where": "final"}


def runs(*seeds, **scale):
    """One method's evaluation frame: the rows of each of ``seeds`` as a run of its own, with
    the run's d_min and ``scale`` columns."""
    parts = [
        pd.DataFrame(rows).assign(seed=k, d_min=D_MIN, **scale) for k, rows in enumerate(seeds)
    ]
    return pd.concat(parts, ignore_index=True)


def term_cells(seeds):
    """{term: its cell} of `return_cells` of ``seeds`` (rows per run)."""
    return {cell["item"]: cell for cell in return_cells(KEYS, runs(*seeds))}


def test_return_shares_use_the_episodes_within_d_min_with_a_task_return():
    cells = term_cells([EPISODES])
    sd, ga = cells["r_sd"], cells["r_ga"]
    assert (sd["episodes"], sd["episodes_within_d_min"], sd["episodes_zero_tc"]) == (4, 3, 1)
    assert sd["shares"] == pytest.approx([0.25, 0.3])
    assert ga["shares"] == pytest.approx([0.1, 0.05])


def test_a_task_return_that_is_zero_up_to_rounding_has_no_ratio():
    """An idle episode's progress terms sum to 0 only up to rounding (4.4e-16 recorded): like
    an exact 0 it gets no ratio (a share of ~1e15 would swamp the mean) and is counted."""
    residue = episode(0.015, 4.440892098500626e-16, -0.1, 0.1)
    sd = term_cells([[*EPISODES, residue]])["r_sd"]
    assert sd["episodes_zero_tc"] == 2 and sd["shares"] == pytest.approx([0.25, 0.3])


def test_return_term_cells_rows_without_the_return_parts_are_not_recorded():
    old = [{k: v for k, v in row.items() if not k.startswith("return_")} for row in EPISODES]
    assert term_cells([old])["r_sd"]["meets_criterion"] == NOT_RECORDED
    gap = term_cells([[{**EPISODES[0], "return_sd": math.nan}, EPISODES[1]]])["r_ga"]
    assert gap["meets_criterion"] == NOT_RECORDED and gap["recorded"] == 0


def test_return_cells_pool_the_seeds_and_judge_the_mean_against_five_percent():
    """Seed 0: the four episodes above; seed 1: one episode within d_min (r_sd 0, r_ga 2 %):
    r_sd's mean (0.25 + 0.3 + 0) / 3 passes, r_ga's (0.1 + 0.05 + 0.02) / 3 = 5.7 % too; with
    seed 1 alone r_ga is 2 %: below."""
    second = [episode(0.0, 1.0, 0.0, 0.02)]
    ga, sd = return_cells(KEYS, runs(EPISODES, second))
    assert (sd["item"], ga["item"]) == ("r_sd", "r_ga")
    counts = ("seeds", "recorded", "episodes", "episodes_within_d_min", "episodes_zero_tc")
    assert tuple(sd[key] for key in counts) == (2, 2, 5, 4, 1)
    assert sd["share_mean"] == pytest.approx(0.55 / 3)
    assert sd["share_median"] == pytest.approx(0.25)
    assert ga["share_mean"] == pytest.approx(0.17 / 3)
    assert sd["meets_criterion"] == ga["meets_criterion"] == "yes"
    assert term_cells([second])["r_ga"]["meets_criterion"] == "no"
    far = [episode(0.2, 1.0, 0.0, 0.1)]
    assert term_cells([far])["r_sd"]["meets_criterion"] == "n/a"
    old = [{k: v for k, v in row.items() if k != "return_tc"} for row in EPISODES]
    cell = term_cells([old])["r_sd"]
    assert cell["meets_criterion"] == NOT_RECORDED and cell["share_mean"] is None


NAN = math.nan


def progress(step, grad_q, grad_sim, grad_hap, active=NAN, fraction=NAN):
    row = dict.fromkeys(PROGRESS_FIELDS, NAN)
    row.update(step=step, grad_q=grad_q, grad_sim=grad_sim, grad_hap=grad_hap)
    row.update(grad_hap_active=active, hap_active_fraction=fraction)
    return row


CURVE = [
    progress(0, NAN, NAN, NAN),  # step 0: no transition, no gradient
    progress(120, 1.0, 0.2, 0.01, 0.02, 0.5),
    progress(240, 2.0, 0.2, 0.04, 0.08, 0.5),
    progress(360, 4.0, 0.1, 0.0, NAN, 0.0),  # every sample inside C_safe
]


def curves(*seeds):
    """Each of ``seeds`` (progress rows) as one run's learning curve."""
    return [pd.DataFrame(rows) for rows in seeds]


def test_gradient_points_are_the_first_middle_and_last_with_a_gradient():
    points = gradient_points(pd.DataFrame(list(reversed(CURVE))))
    assert points["step"].to_dict() == {"first": 120, "middle": 240, "last": 360}
    assert gradient_points(pd.DataFrame(CURVE[:1])).empty


def test_gradient_cells_share_of_the_q_term_per_point_over_seeds():
    """Dist-GPRL: L_sim 20 % / 10 % / 2.5 %, L_hap outside C_safe 2 %, 4 %, then inactive;
    a second seed's 5 % L_sim and inactive L_hap at every point average in. GPRL-D has L_sim
    only; an old file without grad_hap_active says "not recorded" for L_hap outside C_safe."""
    other = [progress(120 * k, 1.0, 0.05, 0.0, NAN, 0.0) for k in (1, 2, 3)]
    found = gradient_cells({"task": "dcp", "method": "dist-gprl"}, curves(CURVE, other))
    cells = {(c["item"], c["where"]): c for c in found}
    assert set(cells) == {
        (item, point)
        for item in ("l_sim", "l_hap", "l_hap_active")
        for point in ("first", "middle", "last")
    }
    assert [(c["where"], c["item"]) for c in found[:4]] == [
        ("first", "l_sim"),
        ("first", "l_hap"),
        ("first", "l_hap_active"),
        ("middle", "l_sim"),
    ]
    assert cells["l_sim", "first"]["share_mean"] == pytest.approx(0.125)
    assert cells["l_sim", "last"]["share_mean"] == pytest.approx((0.025 + 0.05) / 2)
    assert cells["l_sim", "first"]["meets_criterion"] == "yes"
    assert cells["l_sim", "last"]["meets_criterion"] == "no"
    assert cells["l_sim", "middle"]["step"] == "240" and cells["l_sim", "middle"]["seeds"] == 2
    everywhere = cells["l_hap", "middle"]
    assert everywhere["shares"] == pytest.approx((0.02, 0.0))
    assert everywhere["meets_criterion"] == "n/a"
    active = cells["l_hap_active", "middle"]
    assert active["shares"] == pytest.approx((0.04,)) and active["meets_criterion"] == "no"
    assert active["active_fraction"] == pytest.approx(0.25)  # 0.5 and 0.0 over the seeds
    assert cells["l_hap_active", "last"]["meets_criterion"] == "inactive"
    assert {
        c["item"] for c in gradient_cells({"task": "dcp", "method": "gprl-d"}, curves(CURVE))
    } == {"l_sim"}
    dropped = ("grad_hap_active", "hap_active_fraction")
    old = [{k: v for k, v in row.items() if k not in dropped} for row in CURVE]
    stale = gradient_cells({"task": "dcp", "method": "gprl-h"}, curves(old))
    verdicts = {c["meets_criterion"] for c in stale if c["item"] == "l_hap_active"}
    assert verdicts == {NOT_RECORDED}


REACH = [
    {
        "task": "dcp",
        "method": method,
        "axis": axis,
        "kind": kind,
        "one_step_min_m": low,
        "one_step_max_m": low * 1.2,
        "episode_min_m": episode_low,
        "episode_max_m": 2 * low,
        "tc_range_m": tc,
        "gate_max": gate,
    }
    for method, kind, low, episode_low, gate in (
        ("dist-gprl", "via-point", 0.2, 0.2, None),
        ("promp-rrl", "residual", 0.04, 0.1, 0.9),
    )
    for axis, tc in (("x", 0.2), ("y", 0.2), ("z", 0.0))
]
"""Dist-GPRL covers DCP's 0.2 m on x and y, ProMP-RRL's 0.1 m does not."""


def make_tree(root: Path) -> Path:
    """A ci results tree: dist-gprl seed 0 with the new columns, gprl-d seed 0 written before
    them (no return parts, no grad_hap_active), gprl (no mechanism but reach)."""
    for method, new in (("dist-gprl", True), ("gprl-d", False), ("gprl", True)):
        folder = root / "ci" / "dcp" / method / "seed0"
        run_hash = resolve_run("dcp", method, 0, "ci").hash
        config = {"config": {"env": {"sd_d_min": D_MIN}}}
        write_json(folder / "config.json", {"run": config}, config_hash=run_hash)
        write_json(folder / "summary.json", {"summary": {}}, config_hash=run_hash)
        write_json(folder / "done.json", {"steps": 240}, config_hash=run_hash)
        fields = EVALUATION_FIELDS if new else [f for f in EVALUATION_FIELDS if "return_" not in f]
        write_csv(folder / "evaluation.csv", EPISODES, fields)
        progress_fields = PROGRESS_FIELDS
        if not new:
            progress_fields = tuple(f for f in PROGRESS_FIELDS if "hap_" not in f)
        write_csv(folder / "progress.csv", CURVE, progress_fields)
    return root


def test_the_table_marks_each_cell_and_says_what_was_not_recorded(tmp_path):
    written, verdicts = write_mechanisms(make_tree(tmp_path), "ci", tmp_path / "out", REACH)
    names = sorted(p.name for p in written)
    assert names == ["mechanisms_ci.csv", "mechanisms_ci.csv.meta.json", "mechanisms_ci.md"]
    meta, rows = read_csv(tmp_path / "out" / "mechanisms_ci.csv")
    assert meta["kind"] == "table" and meta["preset"] == "ci"
    reach = {(r["method"], r["item"]): r for r in rows if r["section"] == "reach"}
    assert reach["dist-gprl", "x"]["covers_tc_range"] == "yes"
    assert reach["promp-rrl", "y"]["covers_tc_range"] == "no"
    shares = {(r["method"], r["item"]): r for r in rows if r["section"] == "return_share"}
    assert set(shares) == {(m, t) for m in ("dist-gprl", "gprl-d") for t in ("r_sd", "r_ga")}
    assert float(shares["dist-gprl", "r_sd"]["share_mean"]) == pytest.approx(0.275)
    assert shares["dist-gprl", "r_sd"]["episodes_within_d_min"] == "3"
    assert shares["dist-gprl", "r_sd"]["episodes_zero_tc"] == "1"
    assert shares["gprl-d", "r_ga"]["meets_criterion"] == NOT_RECORDED
    gradients = [r for r in rows if r["section"] == "gradient_share"]
    assert {r["method"] for r in gradients} == {"dist-gprl", "gprl-d"}
    markdown = (tmp_path / "out" / "mechanisms_ci.md").read_text()
    assert "27.5 % (median 27.5 %) ✓" in markdown  # dist-gprl r_sd
    assert "7.5 % (median 7.5 %) ✓" in markdown  # dist-gprl r_ga
    assert NOT_RECORDED in markdown and "inactive" in markdown
    assert "| DCP | ProMP-RRL | residual, × gate ≤ 0.90 |" in markdown
    assert len(verdicts) == 7 and all(f"- {line}" in markdown for line in verdicts)
    assert verdicts[0].startswith("Reach: the one-episode reach covers the TC range on x and y")
    assert "for 1 of 2 method–task pairs; not for dcp/promp-rrl" in verdicts[0]
    assert verdicts[1].startswith("r_sd / r_tc (episodes within d_min): meets the criterion")
    assert "not recorded: 1" in verdicts[1]
    assert "λ_hap L_hap / Q outside C_safe: does not meet the criterion" in verdicts[4]
    assert verdicts[5].startswith("Rule 1 (a), λ_ga Σ r_ga of an episode over a success's r_tc")
    assert verdicts[6].startswith("Rule 1 (b), an idle episode's return over the demonstration")
    scale = [r for r in rows if r["section"] == "reward_scale"]
    rule_one = {(r["method"], r["item"], r["where"]) for r in scale}
    assert ("dist-gprl", "ga_of_success", "final") in rule_one


def test_the_writer_imports_neither_torch_nor_pybullet(tmp_path):
    """In a process where importing torch, pybullet, stable_baselines3 or gymnasium raises,
    the table is written from the same tree, byte for byte the same."""
    make_tree(tmp_path)
    write_mechanisms(tmp_path, "ci", tmp_path / "here", REACH)
    code = textwrap.dedent(
        f"""
        import sys

        class Blocker:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in ("torch", "pybullet", "stable_baselines3", "gymnasium"):
                    raise ImportError(name)
                return None

        sys.meta_path.insert(0, Blocker())
        from distgprl.report.mechanisms import write_mechanisms
        write_mechanisms({str(tmp_path)!r}, "ci", {str(tmp_path / "blocked")!r}, {REACH!r})
        """
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    for name in ("mechanisms_ci.csv", "mechanisms_ci.csv.meta.json", "mechanisms_ci.md"):
        assert (tmp_path / "blocked" / name).read_text() == (tmp_path / "here" / name).read_text()


def test_the_plateau_counts_idle_episodes_and_the_alignment_reward_they_collect():
    """Idle = no success, no collision, r_tc below 5 % of the progress weight; their mean
    lambda_ga r_ga is reported; runs without the return's parts are left out."""

    def row(success, collision, tc, ga):
        return {"success": success, "collision": collision, "return_tc": tc, "return_ga": ga}

    unit = {"progress_weight": 1.0, "success_return": 2.0, "demo_return": 1.5}
    tenths = {"progress_weight": 10.0, "success_return": 20.0, "demo_return": 15.0}
    seed0 = [row(0, 0, 0.0, 0.55), row(1, 0, 2.0, 0.3), row(0, 1, -1.0, 0.1), row(0, 0, 0.04, 0.5)]
    seed1 = [row(0, 0, 0.2, 0.4), row(0, 0, 0.0, 0.6)]
    old = [{"success": 0, "collision": 0, "return_tc": NAN, "return_ga": NAN}]
    ga, idle = rule_one_cells(KEYS, runs(seed0, seed1, old, **unit))
    assert (ga["item"], idle["item"]) == ("ga_of_success", "idle_of_demo")
    assert (ga["seeds"], ga["episodes"], ga["idle"], idle["episodes"]) == (2, 6, 3, 3)
    assert ga["mean_ga"] == pytest.approx((0.55 + 0.5 + 0.6) / 3, abs=1e-12)
    # under a progress weight of 10 (r_tc in tenths of a task) 0.2 is still idle
    assert rule_one_cells(KEYS, runs(seed1, **tenths))[0]["idle"] == 2
    assert rule_one_cells(KEYS, runs(old, **unit)) == []


def test_rule_one_ratios_are_measured_per_episode_against_the_runs_own_scale():
    """(a): every episode's lambda_ga Σ r_ga over its run's success r_tc; (b): every idle
    episode's whole return (r_tc + r_sd + lambda_ga r_ga) over its run's demonstration r_tc."""
    rows = [
        {"success": 1, "collision": 0, "return_tc": 20.0, "return_sd": -0.1, "return_ga": 0.5},
        {"success": 0, "collision": 0, "return_tc": 0.2, "return_sd": -0.2, "return_ga": 0.6},
    ]
    scale = {"progress_weight": 10.0, "success_return": 20.0, "demo_return": 8.0}
    ga, idle = rule_one_cells(KEYS, runs(rows, **scale))
    assert ga["share_max"] == pytest.approx(0.6 / 20.0) and ga["episodes"] == 2
    assert ga["share_mean"] == pytest.approx((0.5 / 20.0 + 0.6 / 20.0) / 2)
    assert idle["share_max"] == pytest.approx((0.2 - 0.2 + 0.6) / 8.0) and idle["episodes"] == 1
    assert ga["meets_criterion"] == idle["meets_criterion"] == "yes"  # 3 % <= 5 %, 7.5 % <= 10 %
    _, over = rule_one_cells(KEYS, runs(rows, **{**scale, "demo_return": 5.0}))
    assert over["meets_criterion"] == "no"  # 12 % > 10 %
