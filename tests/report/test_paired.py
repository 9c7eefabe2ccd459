"""Paired comparison with a reference run: discordant TCs counted, exact McNemar p-values,
mismatched TCs refused, method references paired seed by seed, supplementary evaluations
paired apart from the preset's, no stale table, an exploration preset paired run by run with
the preset it varies."""

from __future__ import annotations

import shutil

import pytest

from distgprl.errors import UserInputError
from distgprl.report.paired import (
    FINAL_POLICY,
    OUTCOMES,
    mcnemar_exact,
    paired_rows,
    paired_table,
    supplementary_sizes,
)
from distgprl.report.tables import write_tables
from distgprl.schema import evaluation_file_names, write_csv, write_json

FIELDS = ("episode", "object_offset_x", "object_offset_y", "obstacle_offset_x")
FIELDS += ("obstacle_offset_y", "success", "collision")


def write_evaluation(
    root,
    task,
    method,
    seed,
    outcomes,
    shift=0.0,
    supplementary=False,
    policy="final",
    preset="p",
):
    """An ``evaluation.csv`` with TC k at offsets (0.01 k + shift, ...) and the given
    (success, collision) per TC, and its ``summary.json`` (``supplementary``: as
    ``evaluation_n<len(outcomes)>.csv`` and ``summary_n<...>.json``; ``policy="best"``: the
    ``_best`` files of a best learning-curve policy's evaluation), under preset ``preset``."""
    folder = root / preset / task / method / f"seed{seed}"
    rows = [
        {
            "episode": k,
            "object_offset_x": 0.01 * k + shift,
            "object_offset_y": -0.02 * k,
            "obstacle_offset_x": 0.0,
            "obstacle_offset_y": 0.03 * k,
            "success": s,
            "collision": c,
        }
        for k, (s, c) in enumerate(outcomes)
    ]
    n = len(outcomes)
    csv_name, summary_name = evaluation_file_names(n if supplementary else None, policy)
    write_csv(folder / csv_name, rows, FIELDS)
    summary = {
        "success_rate": sum(s for s, _ in outcomes) / n,
        "collision_rate": sum(c for _, c in outcomes) / n,
        "min_clearance_p5": 0.0,
        "mean_kinematic_retention": 0.5,
    }
    write_json(folder / summary_name, {"summary": summary})
    if method != "demo":  # a finished trained run (the reports use finished runs only)
        write_json(folder / "done.json", {"steps": 100})


def by_outcome(rows, method, seed):
    return {r["outcome"]: r for r in rows if r["method"] == method and r["seed"] == seed}


def test_exact_mcnemar_matches_the_binomial_by_hand():
    # Only one side discordant, 6 TCs: 2 * 0.5**6.
    assert mcnemar_exact(0, 6) == pytest.approx(2 * 0.5**6)
    assert mcnemar_exact(6, 0) == pytest.approx(2 * 0.5**6)
    # 1 of 5: 2 * (C(5,0) + C(5,1)) / 2**5 = 12 / 32.
    assert mcnemar_exact(1, 4) == pytest.approx(12 / 32)
    assert mcnemar_exact(3, 3) == pytest.approx(1.0)
    assert mcnemar_exact(0, 0) == 1.0


def test_discordant_tcs_are_counted_per_outcome(tmp_path):
    reference = [(1, 1), (1, 0), (0, 1), (0, 0), (1, 0), (1, 1)]
    run = [(1, 0), (0, 0), (1, 0), (0, 0), (1, 0), (1, 1)]
    write_evaluation(tmp_path, "dcp", "demo", 0, reference)
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, run)
    rows = paired_rows(tmp_path, "p")
    assert [r["outcome"] for r in rows] == list(OUTCOMES)
    pairs = by_outcome(rows, "dist-gprl", 0)
    # success: run only TC 2, reference only TC 1
    assert (pairs["success"]["only_run"], pairs["success"]["only_reference"]) == (1, 1)
    # collision: the reference collides in TCs 0 and 2, the run never
    assert (pairs["collision"]["only_run"], pairs["collision"]["only_reference"]) == (0, 2)
    # safe success: run TCs 0, 2, 4; reference TCs 1, 4
    assert (pairs["safe_success"]["only_run"], pairs["safe_success"]["only_reference"]) == (
        2,
        1,
    )
    assert pairs["success"]["run_rate"] == pytest.approx(4 / 6)
    assert pairs["success"]["reference_rate"] == pytest.approx(4 / 6)
    assert pairs["collision"]["p_value"] == pytest.approx(mcnemar_exact(0, 2))
    assert all(r["tcs"] == 6 for r in rows)


def test_runs_in_table_order_and_only_tasks_with_a_reference(tmp_path):
    outcomes = [(1, 0), (0, 1), (1, 0)]
    write_evaluation(tmp_path, "dbm", "demo", 0, outcomes)
    for method, seed in (("dist-gprl", 1), ("gprl", 0), ("dist-gprl", 0)):
        write_evaluation(tmp_path, "dbm", method, seed, outcomes)
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, outcomes)  # no DCP reference
    rows = paired_rows(tmp_path, "p")
    runs = [(r["task"], r["method"], r["seed"]) for r in rows[:: len(OUTCOMES)]]
    assert runs == [("dbm", "gprl", 0), ("dbm", "dist-gprl", 0), ("dbm", "dist-gprl", 1)]
    # Identical outcomes: nothing discordant, p = 1.
    assert {(r["only_run"], r["only_reference"], r["p_value"]) for r in rows} == {(0, 0, 1.0)}
    _, (_, markdown), _ = paired_table(tmp_path, "p")
    assert markdown.count("| DBM |") == 3


def test_a_run_evaluated_on_other_tcs_is_refused(tmp_path):
    write_evaluation(tmp_path, "dcp", "demo", 0, [(1, 0), (0, 0)])
    write_evaluation(tmp_path, "dcp", "gprl-d", 0, [(1, 0), (0, 0)], shift=0.001)
    with pytest.raises(ValueError, match="gprl-d/seed0/evaluation.csv: evaluation TC 0 differs"):
        paired_rows(tmp_path, "p")
    write_evaluation(tmp_path, "dcp", "gprl-d", 0, [(1, 0)])
    with pytest.raises(ValueError, match="1 evaluation TCs, the reference"):
        paired_rows(tmp_path, "p")


def test_write_tables_writes_the_pairs_and_removes_a_stale_table(tmp_path):
    write_evaluation(tmp_path, "dcp", "demo", 0, [(1, 1), (0, 0)])
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, [(1, 0), (1, 0)])
    out = tmp_path / "out"
    written = {p.name for p in write_tables(tmp_path, "p", out)}
    assert {"paired_vs_demo_p.csv", "paired_vs_demo_p.md"} <= written
    assert (
        "| DCP | Dist-GPRL (ours) | 0 | 2 | 1.00 / 0.50 | 1 / 0 |"
        in (out / "paired_vs_demo_p.md").read_text()
    )
    assert not (out / "paired_vs_dist-gprl_p.md").exists()  # nothing to pair with it yet
    write_evaluation(tmp_path, "dcp", "gprl-d", 0, [(0, 0), (1, 0)])
    written = {p.name for p in write_tables(tmp_path, "p", out)}
    assert {"paired_vs_dist-gprl_p.csv", "paired_vs_dist-gprl_p.md"} <= written
    assert (
        "| DCP | GPRL-D | 0 | 2 | 0.50 / 1.00 | 0 / 1 |"
        in (out / "paired_vs_dist-gprl_p.md").read_text()
    )
    for method in ("demo", "dist-gprl"):  # the references' runs are gone
        shutil.rmtree(tmp_path / "p" / "dcp" / method / "seed0")
    written = {p.name for p in write_tables(tmp_path, "p", out)}
    assert not any(name.startswith("paired_vs") for name in written)
    assert not list(out.glob("paired_vs*"))


def test_a_method_reference_is_paired_seed_by_seed(tmp_path):
    write_evaluation(tmp_path, "dcp", "demo", 0, [(0, 1), (0, 1), (0, 1)])
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, [(1, 0), (1, 0), (1, 0)])
    write_evaluation(tmp_path, "dcp", "dist-gprl", 1, [(0, 0), (0, 0), (0, 0)])
    write_evaluation(tmp_path, "dcp", "gprl-d", 0, [(1, 0), (0, 0), (0, 0)])
    write_evaluation(tmp_path, "dcp", "gprl-d", 1, [(1, 0), (0, 0), (0, 0)])
    write_evaluation(tmp_path, "dcp", "gprl-d", 2, [(1, 0), (0, 0), (0, 0)])  # no seed-2 ref
    rows = paired_rows(tmp_path, "p", reference="dist-gprl")
    # Neither the reference's own runs nor the unadapted demo are rows.
    assert [(r["method"], r["seed"]) for r in rows[:: len(OUTCOMES)]] == [
        ("gprl-d", 0),
        ("gprl-d", 1),
    ]
    seed0, seed1 = by_outcome(rows, "gprl-d", 0), by_outcome(rows, "gprl-d", 1)
    assert (seed0["success"]["only_run"], seed0["success"]["only_reference"]) == (0, 2)
    assert (seed1["success"]["only_run"], seed1["success"]["only_reference"]) == (1, 0)
    assert seed1["success"]["reference_rate"] == 0.0
    stem, (_, markdown), _ = paired_table(tmp_path, "p", "dist-gprl")
    assert stem == "paired_vs_dist-gprl_p"
    assert "against Dist-GPRL (ours) of the same seed" in markdown
    with pytest.raises(ValueError, match="unknown reference method"):
        paired_rows(tmp_path, "p", reference="bogus")


def test_supplementary_evaluations_are_paired_apart_from_the_presets(tmp_path):
    # Preset evaluation on 2 TCs: a tie. Supplementary on 8 TCs: the run wins 6 / 0.
    write_evaluation(tmp_path, "dbm", "demo", 0, [(1, 0), (0, 0)])
    write_evaluation(tmp_path, "dbm", "dist-gprl", 0, [(0, 0), (1, 0)])
    write_evaluation(tmp_path, "dbm", "demo", 0, [(0, 0)] * 6 + [(1, 0)] * 2, supplementary=True)
    write_evaluation(tmp_path, "dbm", "dist-gprl", 0, [(1, 0)] * 8, supplementary=True)
    # A run with only the preset's evaluation has no supplementary pair.
    write_evaluation(tmp_path, "dbm", "gprl", 0, [(1, 1), (1, 1)])
    assert supplementary_sizes(tmp_path, "p") == [8]
    preset = by_outcome(paired_rows(tmp_path, "p"), "dist-gprl", 0)["success"]
    assert (preset["tcs"], preset["only_run"], preset["only_reference"]) == (2, 1, 1)
    rows = paired_rows(tmp_path, "p", episodes=8)
    assert {r["method"] for r in rows} == {"dist-gprl"}
    success = by_outcome(rows, "dist-gprl", 0)["success"]
    assert (success["tcs"], success["only_run"], success["only_reference"]) == (8, 6, 0)
    assert success["p_value"] == pytest.approx(2 * 0.5**6)
    stem, (_, markdown), _ = paired_table(tmp_path, "p", episodes=8)
    assert stem == "paired_vs_demo_p_n8" and "first 8 TCs" in markdown


def test_write_tables_writes_supplementary_pairs_and_removes_them_when_gone(tmp_path):
    write_evaluation(tmp_path, "dbm", "demo", 0, [(1, 0), (0, 0)])
    write_evaluation(tmp_path, "dbm", "dist-gprl", 0, [(0, 0), (1, 0)])
    write_evaluation(tmp_path, "dbm", "demo", 0, [(0, 0)] * 3, supplementary=True)
    write_evaluation(tmp_path, "dbm", "dist-gprl", 0, [(1, 0)] * 3, supplementary=True)
    out = tmp_path / "figures"
    write_tables(tmp_path, "p", out)
    supplementary = out / "paired_vs_demo_p_n3.md"
    assert supplementary.exists() and (out / "paired_vs_demo_p.md").exists()
    assert "| 3 |" in supplementary.read_text()
    for name in ("evaluation_n3.csv", "summary_n3.json"):
        for method in ("demo", "dist-gprl"):
            (tmp_path / "p" / "dbm" / method / "seed0" / name).unlink()
    write_tables(tmp_path, "p", out)
    assert not list(out.glob("paired_vs_*_n3.*"))
    assert (out / "paired_vs_demo_p.md").exists()


def test_a_best_policy_is_paired_with_its_own_runs_final_policy(tmp_path):
    """Each run with a best-policy evaluation against its own final one (not Dist-GPRL's
    or another seed's); runs without one are not rows; table order."""
    final = [(1, 0), (0, 1), (0, 0), (1, 1)]
    best = [(1, 0), (1, 0), (1, 0), (0, 0)]
    write_evaluation(tmp_path, "dcp", "dist-gprl", 1, final)
    write_evaluation(tmp_path, "dcp", "dist-gprl", 1, best, policy="best")
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, [(0, 1)] * 4)  # its final only
    write_evaluation(tmp_path, "dcp", "gprl", 0, best)
    write_evaluation(tmp_path, "dcp", "gprl", 0, best, policy="best")
    rows = paired_rows(tmp_path, "p", FINAL_POLICY)
    runs = [(r["method"], r["seed"]) for r in rows[:: len(OUTCOMES)]]
    assert runs == [("gprl", 0), ("dist-gprl", 1)]
    pairs = by_outcome(rows, "dist-gprl", 1)
    # success: best only TCs 1, 2; final only TC 3
    assert (pairs["success"]["only_run"], pairs["success"]["only_reference"]) == (2, 1)
    # collision: final only TCs 1, 3
    assert (pairs["collision"]["only_run"], pairs["collision"]["only_reference"]) == (0, 2)
    # safe success: best TCs 0, 1, 2; final TC 0
    assert (pairs["safe_success"]["only_run"], pairs["safe_success"]["only_reference"]) == (2, 0)
    assert {(r["only_run"], r["only_reference"]) for r in by_outcome(rows, "gprl", 0).values()} == {
        (0, 0)
    }
    _, (_, markdown), _ = paired_table(tmp_path, "p", FINAL_POLICY)
    assert "its own final policy" in markdown and markdown.count("| DCP |") == 2


def test_a_best_policy_evaluated_on_other_tcs_is_refused(tmp_path):
    write_evaluation(tmp_path, "dbm", "gprl-h", 2, [(1, 0), (0, 0)])
    write_evaluation(tmp_path, "dbm", "gprl-h", 2, [(1, 0), (0, 0)], shift=0.5, policy="best")
    with pytest.raises(ValueError, match="evaluation_best.csv: evaluation TC 0 differs"):
        paired_rows(tmp_path, "p", FINAL_POLICY)


def test_write_tables_writes_best_vs_final_pairs_and_removes_them_when_gone(tmp_path):
    write_evaluation(tmp_path, "dcp", "demo", 0, [(1, 1), (0, 0)])
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, [(1, 0), (0, 0)])
    out = tmp_path / "out"
    write_tables(tmp_path, "p", out)
    assert not (out / "paired_best_vs_final_p.md").exists()
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, [(1, 0), (1, 0)], policy="best")
    written = write_tables(tmp_path, "p", out)
    assert out / "paired_best_vs_final_p.md" in written
    assert (
        "| DCP | Dist-GPRL (ours) | 0 | 2 | 1.00 / 0.50 | 1 / 0 |"
        in (out / "paired_best_vs_final_p.md").read_text()
    )
    (tmp_path / "p" / "dcp" / "dist-gprl" / "seed0" / "evaluation_best.csv").unlink()
    write_tables(tmp_path, "p", out)
    assert not (out / "paired_best_vs_final_p.md").exists()


def test_a_preset_is_paired_run_by_run_with_the_same_run_of_another_preset(tmp_path):
    base = [(1, 0), (0, 1), (1, 1), (0, 0)]
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, base, preset="base")
    write_evaluation(tmp_path, "dcp", "dist-gprl", 1, [(0, 0)] * 4, preset="base")
    # variant run: success on TCs 0, 1, 3 and no collision, against the base run's seed 0
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, [(1, 0), (1, 0), (0, 0), (1, 0)])
    write_evaluation(tmp_path, "dbm", "dist-gprl", 0, [(1, 0)] * 4)  # no counterpart
    write_evaluation(tmp_path, "dcp", "demo", 0, base)  # the reference is not a row
    write_evaluation(tmp_path, "dcp", "demo", 0, base, preset="base")
    rows = paired_rows(tmp_path, "p", base_preset="base")
    assert {(r["task"], r["method"], r["seed"]) for r in rows} == {("dcp", "dist-gprl", 0)}
    pairs = by_outcome(rows, "dist-gprl", 0)
    assert (pairs["success"]["only_run"], pairs["success"]["only_reference"]) == (2, 1)
    assert (pairs["collision"]["only_run"], pairs["collision"]["only_reference"]) == (0, 2)
    assert (pairs["safe_success"]["only_run"], pairs["safe_success"]["only_reference"]) == (
        2,
        0,
    )
    assert pairs["success"]["reference_rate"] == pytest.approx(0.5)
    _, (_, markdown), _ = paired_table(tmp_path, "p", base_preset="base")
    assert "same task, method and seed in the base preset" in markdown
    assert "| DCP | Dist-GPRL (ours) | 0 | 4 | 0.75 / 0.50 | 2 / 1 |" in markdown


def test_presets_evaluated_on_other_tcs_or_the_same_preset_are_refused(tmp_path):
    write_evaluation(tmp_path, "dcp", "gprl", 0, [(1, 0), (0, 0)], preset="base")
    write_evaluation(tmp_path, "dcp", "gprl", 0, [(1, 0)])
    with pytest.raises(UserInputError, match="presets p and base do not evaluate on the same"):
        paired_rows(tmp_path, "p", base_preset="base")
    with pytest.raises(UserInputError, match="pair a preset with another preset"):
        paired_rows(tmp_path, "p", base_preset="p")


def test_write_tables_against_a_preset_writes_its_pairs_or_says_there_are_none(tmp_path):
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, [(1, 0), (0, 0)])
    out = tmp_path / "out"
    with pytest.raises(UserInputError, match="no run of .* has a finished counterpart"):
        write_tables(tmp_path, "p", out, against="base")
    assert not out.exists()  # a refused pairing writes nothing, not even Table I
    write_evaluation(tmp_path, "dcp", "dist-gprl", 0, [(0, 0), (0, 1)], preset="base")
    written = write_tables(tmp_path, "p", out, against="base")
    assert {out / "paired_p_vs_base.csv", out / "paired_p_vs_base.md"} <= set(written)
    assert (
        "| DCP | Dist-GPRL (ours) | 0 | 2 | 0.50 / 0.00 | 1 / 0 |"
        in (out / "paired_p_vs_base.md").read_text()
    )
    assert "paired_p_vs_base.md" not in {p.name for p in write_tables(tmp_path, "p", out)}


def test_cli_tables_against_a_preset_writes_the_pairs_and_refuses_other_tcs_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from distgprl.cli import app

    write_evaluation(tmp_path, "dbm", "gprl", 2, [(1, 0), (0, 0)], preset="base")
    write_evaluation(tmp_path, "dbm", "gprl", 2, [(1, 0), (1, 0)])
    out = tmp_path / "out"
    command = ["tables", "--root", str(tmp_path), "--preset", "p", "--out-dir", str(out)]
    result = CliRunner().invoke(app, [*command, "--against", "base"])
    assert result.exit_code == 0, result.output
    assert f"wrote {out / 'paired_p_vs_base.md'}" in result.output
    write_evaluation(tmp_path, "dbm", "gprl", 2, [(1, 0)], preset="base")
    result = CliRunner().invoke(app, [*command, "--against", "base"])
    assert result.exit_code == 2, result.output
    assert result.output.strip().startswith("error: ")
    assert "presets p and base do not evaluate on the same TCs" in result.output
