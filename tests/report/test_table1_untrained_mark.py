"""Protocol v8, rule 2 in Table I: a best-policy cell where, at any of its seeds, no trained
learning-curve point beat the untrained step-0 one (the best-policy summary's
``beats_untrained`` false) still shows the best trained policy's figures and is marked `†`
with the untrained curve success beside (the mean over those seeds) and a footnote; a
summary without the field (written before it was recorded) is unknown and never marked.
Synthetic summaries only."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from distgprl.report.frame import load_frames
from distgprl.report.table1 import (
    UNTRAINED_MARK,
    UNTRAINED_NOTE,
    simulation_table,
    untrained_marks,
)
from distgprl.report.tables import write_tables
from distgprl.schema import write_json

NOT_BEATEN = "no trained policy beat the untrained one"


def best_summary(success: float, beats: bool | None, untrained: float | None) -> dict:
    """A best-policy summary with the selection's comparison (``beats`` None: not recorded,
    as before v8)."""
    summary = {"success_rate": success, "collision_rate": 0.1, "policy": "best"}
    summary["policy_step"] = 1500
    if beats is not None:
        summary |= {"beats_untrained": beats, "untrained_curve_success_rate": untrained}
    return {"summary": summary}


def write_cell(root: Path, task: str, method: str, seeds: list[tuple]) -> None:
    """One (task, method) cell of preset ``p``: per seed ``(success, beats, untrained)``."""
    for seed, (success, beats, untrained) in enumerate(seeds):
        folder = root / "p" / task / method / f"seed{seed}"
        write_json(folder / "summary_best.json", best_summary(success, beats, untrained))
        write_json(
            folder / "summary.json", {"summary": {"success_rate": 0.0, "collision_rate": 0.5}}
        )


@pytest.fixture
def marked_tree(tmp_path) -> Path:
    """DCP: Dist-GPRL beat the untrained policy at every seed, GPRL not at two of three
    seeds (untrained 0.6 and 0.8), ProMP-RRL's summaries predate the field (unknown); the
    demo reference (untrained, no best policy)."""
    write_cell(tmp_path, "dcp", "dist-gprl", [(0.9, True, 0.2), (0.8, True, 0.9)])
    write_cell(tmp_path, "dcp", "gprl", [(0.1, False, 0.6), (0.3, True, 0.1), (0.2, False, 0.8)])
    write_cell(tmp_path, "dcp", "promp-rrl", [(0.5, None, None), (0.4, None, None)])
    demo = {"summary": {"success_rate": 0.5, "collision_rate": 0.4}}
    write_json(tmp_path / "p" / "dcp" / "demo" / "seed0" / "summary.json", demo)
    return tmp_path


def test_only_an_explicit_false_counts_and_the_untrained_figure_is_their_mean():
    summaries = [best_summary(*seed)["summary"] for seed in ((0.1, False, 0.6), (0.3, True, 0.1))]
    summaries += [
        best_summary(0.2, False, 0.8)["summary"],
        best_summary(0.2, None, None)["summary"],
    ]
    marks = untrained_marks(summaries)
    assert marks["untrained_best_seeds"] == 2
    assert marks["untrained_curve_success_mean"] == pytest.approx(0.7)
    assert untrained_marks(summaries[1:2])["untrained_best_seeds"] == 0
    unknown = untrained_marks(summaries[3:])  # unknown: not an error, not marked
    assert unknown["untrained_best_seeds"] == 0
    assert np.isnan(unknown["untrained_curve_success_mean"])


def test_a_cell_is_marked_exactly_where_a_seed_did_not_beat_the_untrained_policy(marked_tree):
    rows, _ = simulation_table(load_frames(marked_tree, "p"))
    marks = {row["method"]: row["dcp_untrained_best_seeds"] for row in rows}
    assert marks == {"gprl": 2, "dist-gprl": 0, "promp-rrl": 0, "demo": 0}
    out = marked_tree / "out"
    write_tables(marked_tree, "p", out)
    markdown = (out / "table1_p.md").read_text()
    lines = {line.split(" | ")[0].removeprefix("| "): line for line in markdown.splitlines()}
    # the best trained policy's own figures stay in the cell, the mark and figure beside
    assert "| 0.20 ± 0.10 [0.00, 0.45] [3] † (untrained 0.70, 2 of 3 seeds) |" in lines["GPRL"]
    for label in ("Dist-GPRL (ours)", "ProMP-RRL", "Demo (no adaptation)"):
        assert UNTRAINED_MARK not in lines[label], label
    assert f"\n{UNTRAINED_NOTE}.\n" in markdown and NOT_BEATEN in UNTRAINED_NOTE
    latex = (out / "table1_p.tex").read_text()
    assert "$^\\dagger$ (untrained 0.70, 2 of 3 seeds)" in latex
    assert latex.count("$^\\dagger$") == 2  # the cell and its footnote
    with open(out / "table1_p.csv", newline="") as handle:
        table = {row["method"]: row for row in csv.DictReader(handle)}
    assert table["gprl"]["dcp_untrained_best_seeds"] == "2"
    assert float(table["gprl"]["dcp_untrained_curve_success_mean"]) == pytest.approx(0.7)
    assert table["dist-gprl"]["dcp_untrained_best_seeds"] == "0"
    assert table["dist-gprl"]["dcp_untrained_curve_success_mean"] == ""


def test_the_per_run_table_marks_the_runs_and_the_final_table_marks_nothing(marked_tree):
    out = marked_tree / "out"
    write_tables(marked_tree, "p", out)
    per_run = (out / "table1_p_per_seed.md").read_text()
    assert "| DCP | GPRL | 0 | best (step 1500) † (untrained 0.60) |" in per_run
    assert "| DCP | GPRL | 1 | best (step 1500) |" in per_run
    assert "| DCP | ProMP-RRL | 0 | best (step 1500) |" in per_run
    assert NOT_BEATEN in per_run
    with open(out / "table1_p_per_seed.csv", newline="") as handle:
        runs = {(r["method"], r["seed"]): r for r in csv.DictReader(handle)}
    assert runs[("gprl", "0")]["beats_untrained"] == "False"
    assert runs[("gprl", "1")]["beats_untrained"] == "True"
    assert runs[("promp-rrl", "0")]["beats_untrained"] == ""  # not recorded: unknown
    for name in ("table1_final_p.md", "table1_final_p.tex", "table1_final_p_per_seed.md"):
        assert UNTRAINED_MARK not in (out / name).read_text()
        assert "dagger" not in (out / name).read_text()


def test_a_table_without_a_marked_cell_has_no_footnote(tmp_path):
    write_cell(tmp_path, "dcp", "dist-gprl", [(0.9, True, 0.2), (0.7, None, None)])
    out = tmp_path / "out"
    write_tables(tmp_path, "p", out)
    for name in ("table1_p.md", "table1_p.tex", "table1_p_per_seed.md"):
        assert (
            UNTRAINED_MARK not in (out / name).read_text()
            and NOT_BEATEN not in (out / name).read_text()
        )
