"""Environment v6's reporting rules (docs/FINDINGS.md "Protocol v6", rules 5 and 6) in Table
I: MinCl over the collision-free episodes (v5's over all episodes beside it), and the best
learning-curve policy's evaluation in ``table1_<preset>`` with the final policy's in
``table1_final_<preset>``, the aggregates and the claims on Table I's evaluation.

Realistic fixtures are copies of archived environment-v5 runs (read, never modified); the
rest are synthetic summaries and episode rows."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.report.frame import load_frames
from distgprl.report.runs import TABLE_POLICY, run_evaluations
from distgprl.report.table1 import collect_scores, per_seed_rows, simulation_table
from distgprl.report.tables import write_tables
from distgprl.schema import EVALUATION_FIELDS, read_csv, read_json, write_csv, write_json

ARCHIVE = Path(__file__).resolve().parents[2] / "results" / "archive" / "env-v5" / "paper"
RUNS = [("dcp", "dist-gprl", 0), ("dcp", "dist-gprl", 1), ("dcp", "gprl", 0), ("dcp", "demo", 0)]
"""Archived v5 runs copied as fixtures: two trained methods (best and final evaluations,
summaries without the collision-free MinCl) and the untrained `demo` reference."""


@pytest.fixture(scope="module")
def archived(tmp_path_factory) -> Path:
    """A result tree (preset ``p``, not a shipped one: hashes not checked) of copies of
    `RUNS`' result files, the safety-layer evaluations left out."""
    root = tmp_path_factory.mktemp("archived")
    for task, method, seed in RUNS:
        source = ARCHIVE / task / method / f"seed{seed}"
        target = root / "p" / task / method / f"seed{seed}"
        shutil.copytree(source, target, ignore=shutil.ignore_patterns("*_check*", "*_repair*"))
    return root


def table_rows(path: Path) -> dict[str, dict[str, str]]:
    with open(path, newline="") as handle:
        return {row["method"]: row for row in csv.DictReader(handle)}


def by_hand(episodes: Path) -> tuple[float, float, int]:
    """(MinCl over all episodes, over the collision-free ones, their count), numpy here."""
    _, rows = read_csv(episodes)
    clearance = np.array([max(float(r["min_clearance"]), 0.0) for r in rows])
    free = np.array([int(r["collision"]) == 0 for r in rows])
    return float(np.percentile(clearance, 5)), float(np.percentile(clearance[free], 5)), free.sum()


def test_table_one_reports_the_best_policy_and_the_final_table_the_final_one(archived):
    """``table1_p`` holds each trained run's ``summary_best.json`` figures, ``table1_final_p``
    its ``summary.json`` ones; the demo's one evaluation is in both."""
    out = archived / "out"
    written = {path.name for path in write_tables(archived, "p", out)}
    for stem in ("table1_p", "table1_final_p"):
        assert {f"{stem}.csv", f"{stem}.md", f"{stem}.tex"} <= written
        assert {f"{stem}_per_seed.csv", f"{stem}_per_seed.md"} <= written
    best, final = table_rows(out / "table1_p.csv"), table_rows(out / "table1_final_p.csv")
    for method, table, name in (("gprl", best, "summary_best"), ("gprl", final, "summary")):
        expected = read_json(ARCHIVE / "dcp" / method / "seed0" / f"{name}.json")["summary"]
        assert float(table[method]["dcp_success_rate_mean"]) == pytest.approx(
            expected["success_rate"]
        )
        assert float(table[method]["dcp_collision_rate_mean"]) == pytest.approx(
            expected["collision_rate"]
        )
    # the archived gprl seed 0: best 0.18 collisions, final 0.44 (their files differ)
    assert best["gprl"]["dcp_collision_rate_mean"] != final["gprl"]["dcp_collision_rate_mean"]
    for dist in (best, final):  # two seeds of dist-gprl; same demo row in both
        assert dist["dist-gprl"]["dcp_seeds"] == "2"
    assert best["demo"] == final["demo"]
    markdown = (out / "table1_p.md").read_text()
    assert "best learning-curve policy, Algorithm 1's output" in markdown.splitlines()[0]
    assert "final policy" in (out / "table1_final_p.md").read_text().splitlines()[0]
    assert "\\label{tab:sim_results}" in (out / "table1_p.tex").read_text()
    assert "\\label{tab:sim_results_final}" in (out / "table1_final_p.tex").read_text()
    assert "Final policy in place of the best" not in markdown  # every run has its best


def test_mincl_of_v5_summaries_is_computed_from_their_episode_rows(archived):
    """The archived summaries predate the collision-free MinCl: Table I computes it from the
    matching evaluation CSV (the best's from ``evaluation_best.csv``); where >= 5 % of the
    episodes collide it is positive while the all-episode MinCl is 0."""
    rows, _ = simulation_table(load_frames(archived, "p"))
    final_rows, _ = simulation_table(load_frames(archived, "p", "final"))
    for table, csv_name in ((rows, "evaluation_best.csv"), (final_rows, "evaluation.csv")):
        gprl = next(row for row in table if row["method"] == "gprl")
        all_episodes, free, count = by_hand(ARCHIVE / "dcp" / "gprl" / "seed0" / csv_name)
        assert count <= 95 and all_episodes == 0.0 < free
        assert gprl["dcp_min_clearance_p5"].mean == all_episodes
        assert gprl["dcp_min_clearance_p5_collision_free"].mean == pytest.approx(free)
    per_seed = {(r["method"], r["seed"]): r for r in per_seed_rows(load_frames(archived, "p"))}
    _, free, count = by_hand(ARCHIVE / "dcp" / "dist-gprl" / "seed1" / "evaluation_best.csv")
    ours = per_seed[("dist-gprl", 1)]
    assert ours["min_clearance_p5_collision_free"] == pytest.approx(free)
    assert ours["collision_free_episodes"] == count
    step = read_json(ARCHIVE / "dcp" / "dist-gprl" / "seed1" / "summary_best.json")["summary"]
    assert (ours["policy"], ours["policy_step"]) == ("best", step["policy_step"])
    assert (per_seed[("demo", 0)]["policy"], per_seed[("demo", 0)]["policy_step"]) == (
        "untrained",
        "",
    )
    out = archived / "out_per_seed"
    write_tables(archived, "p", out)
    text = (out / "table1_p_per_seed.md").read_text()
    assert f"| DCP | Dist-GPRL (ours) | 1 | best (step {step['policy_step']}) | {count} |" in text
    assert "over the episodes without a collision" in (out / "table1_p.md").read_text()


def test_the_aggregates_and_claims_read_the_same_evaluation_as_table_one(archived):
    """`collect_scores` (what the aggregates and the claims bootstrap) defaults to Table I's
    policy, the best: its rates are the best evaluations', not the final ones'."""
    assert TABLE_POLICY == "best"
    scores = collect_scores(load_frames(archived, "p"))
    assert scores == collect_scores(load_frames(archived, "p", "best"))
    best = read_json(ARCHIVE / "dcp" / "gprl" / "seed0" / "summary_best.json")["summary"]
    final = read_json(ARCHIVE / "dcp" / "gprl" / "seed0" / "summary.json")["summary"]
    assert scores[("dcp", "gprl")][0]["collision_rate"] == best["collision_rate"]
    assert (
        collect_scores(load_frames(archived, "p", "final"))[("dcp", "gprl")][0]["collision_rate"]
        == (final["collision_rate"])
    )
    out = archived / "out_scores"
    write_tables(archived, "p", out)
    _, aggregates = read_csv(out / "aggregates_p.csv")
    mean = next(
        r
        for r in aggregates
        if (r["task"], r["method"], r["metric"], r["statistic"])
        == ("dcp", "gprl", "collision_rate", "mean")
    )
    assert float(mean["value"]) == pytest.approx(best["collision_rate"])


def episode(collision: int, clearance: float) -> dict[str, object]:
    row: dict[str, object] = dict.fromkeys(EVALUATION_FIELDS, 0)
    row.update(success=1 - collision, completed=1 - collision, collision=collision)
    row.update(min_clearance=clearance, min_signed_clearance=clearance if collision == 0 else -0.01)
    return row


def write_run(root: Path, method: str, seed: int, rows: list[dict[str, object]], best: bool):
    """A run's evaluation CSV and v5-style summary (no collision-free MinCl) from ``rows``:
    the best policy's files if ``best`` (and a final evaluation beside them), else only the
    final's."""
    from distgprl.experiments.rollout import summarise

    folder = root / "p" / "dcp" / method / f"seed{seed}"
    names = [("evaluation.csv", "summary.json")]
    if best:
        names.append(("evaluation_best.csv", "summary_best.json"))
    for csv_name, summary_name in names:
        summary = summarise(rows)
        del summary["min_clearance_p5_collision_free"], summary["collision_free_episodes"]
        write_csv(folder / csv_name, rows, EVALUATION_FIELDS)
        write_json(folder / summary_name, {"summary": summary})


def test_an_all_colliding_run_has_no_mincl_with_the_reason_and_other_seeds_say_how_many(
    tmp_path,
):
    """Every episode of gprl's seed 0 collides: its MinCl is empty, "– (all collided)", not
    0; the Table I cell is over seed 1 alone, "(n=1)". Where every seed collides always, the
    cell says so. v5's all-episode MinCl is 0 for both and stays a number."""
    colliding = [episode(1, 0.0) for _ in range(20)]
    mixed = [episode(1, 0.0)] * 2 + [episode(0, 0.002 * (k + 1)) for k in range(18)]  # 10 %
    write_run(tmp_path, "gprl", 0, colliding, best=True)
    write_run(tmp_path, "gprl", 1, mixed, best=True)
    write_run(tmp_path, "dist-gprl", 0, colliding, best=True)
    write_tables(tmp_path, "p", tmp_path / "out")
    table = table_rows(tmp_path / "out" / "table1_p.csv")
    free = float(np.percentile([0.002 * (k + 1) for k in range(18)], 5))
    assert float(table["gprl"]["dcp_min_clearance_p5_collision_free_mean"]) == pytest.approx(free)
    assert table["gprl"]["dcp_min_clearance_p5_collision_free_seeds"] == "1"
    assert table["gprl"]["dcp_all_collided_seeds"] == "1"
    assert float(table["gprl"]["dcp_min_clearance_p5_mean"]) == 0.0  # v5's: 0 at 10 %
    ours = table["dist-gprl"]
    assert ours["dcp_min_clearance_p5_collision_free_mean"] == ""
    assert (ours["dcp_min_clearance_p5_collision_free_seeds"], ours["dcp_all_collided_seeds"]) == (
        "0",
        "1",
    )
    assert ours["dcp_min_clearance_p5_mean"] == "0"
    markdown = (tmp_path / "out" / "table1_p.md").read_text()
    assert f"| {free:.3f} (n=1) | 0.000 ± 0.000 |" in markdown
    assert "| Dist-GPRL (ours) | 0.00 [1] | 1.00 | – (all collided) | 0.000 |" in markdown
    assert "every episode of every seed collided, so MinCl is undefined (not 0)" in markdown
    assert "– (all collided)" in (tmp_path / "out" / "table1_p_per_seed.md").read_text()
    assert "-- (all collided)" in (tmp_path / "out" / "table1_p.tex").read_text()
    _, per_seed = read_csv(tmp_path / "out" / "table1_p_per_seed.csv")
    first = next(r for r in per_seed if (r["method"], r["seed"]) == ("gprl", "0"))
    assert (first["min_clearance_p5_collision_free"], first["collision_free_episodes"]) == ("", "0")


def test_a_recorded_collision_free_mincl_is_read_not_recomputed(tmp_path):
    """A v6 summary records MinCl (`summarise`); the table reads it (None: every episode
    collided) and does not recompute it from the episode rows."""
    rows = [episode(0, 0.01), episode(1, 0.0)]
    folder = tmp_path / "p" / "dcp" / "demo" / "seed0"
    write_csv(folder / "evaluation.csv", rows, EVALUATION_FIELDS)
    document = {"summary": {"success_rate": 0.5, "collision_rate": 0.5}}
    document["summary"].update(min_clearance_p5_collision_free=0.123, collision_free_episodes=1)
    write_json(folder / "summary.json", document)
    (row,), _ = simulation_table(load_frames(tmp_path, "p"))
    assert row["dcp_min_clearance_p5_collision_free"].mean == 0.123
    document["summary"].update(min_clearance_p5_collision_free=None, collision_free_episodes=0)
    write_json(folder / "summary.json", document)
    (row,), _ = simulation_table(load_frames(tmp_path, "p"))
    assert row["dcp_min_clearance_p5_collision_free"].n == 0 and row["dcp_all_collided_seeds"] == 1


def test_a_trained_run_without_its_best_evaluation_shows_its_final_one_and_is_listed(tmp_path):
    """A trained run whose best policy was not evaluated (or whose best evaluation records
    another configuration) is in Table I with its final policy, named under the table and
    marked ``final`` per run, never left out silently; the final table is unaffected."""
    write_run(tmp_path, "gprl", 0, [episode(0, 0.01)] * 4, best=False)
    write_run(tmp_path, "gprl", 1, [episode(0, 0.01)] * 4, best=True)
    write_run(tmp_path, "gprl", 2, [episode(0, 0.01)] * 4, best=True)
    folder = tmp_path / "p" / "dcp" / "gprl" / "seed2"
    best = {"summary": read_json(folder / "summary_best.json")["summary"]}
    write_json(folder / "summary_best.json", best, config_hash="another")
    selection = run_evaluations(tmp_path, "p")
    assert [e.policy for e in selection.evaluations] == ["final", "best", "final"]
    assert selection.substituted == ("dcp/gprl/seed0", "dcp/gprl/seed2")
    assert [e.policy for e in run_evaluations(tmp_path, "p", "final").evaluations] == ["final"] * 3
    write_tables(tmp_path, "p", tmp_path / "out")
    markdown = (tmp_path / "out" / "table1_p.md").read_text()
    assert "Final policy in place of the best (2; no best-policy evaluation" in markdown
    assert "dcp/gprl/seed0; dcp/gprl/seed2" in markdown
    assert "Final policy in place" not in (tmp_path / "out" / "table1_final_p.md").read_text()
    per_seed = (tmp_path / "out" / "table1_p_per_seed.md").read_text()
    assert "| DCP | GPRL | 0 | final | 4 |" in per_seed
    with pytest.raises(UserInputError, match="unknown policy 'worst'"):
        run_evaluations(tmp_path, "p", "worst")
