"""Which runs the reports use: those of the current configuration only (a run of an older
configuration is listed, not averaged in)."""

from __future__ import annotations

from distgprl.identity import resolve_run
from distgprl.report.curves import common_curves
from distgprl.report.frame import curve_frame, load_frames
from distgprl.report.runs import select_runs
from distgprl.report.seed_curves import run_curves
from distgprl.report.table1 import simulation_table
from distgprl.report.tables import write_tables
from distgprl.schema import PROGRESS_FIELDS, write_csv, write_json

SUMMARY = {
    "success_rate": 0.5,
    "collision_rate": 0.1,
    "min_clearance_p5": 0.01,
    "mean_kinematic_retention": 0.5,
    "safe_success_rate": 0.45,
}

EPISODE = ("episode", "object_offset_x", "object_offset_y", "obstacle_offset_x")
EPISODE += ("obstacle_offset_y", "success", "collision")
"""Columns of the minimal evaluation.csv of a finished, evaluated run."""


def _run(root, method, seed, config_hash, success=0.5):
    folder = root / "ci" / "dcp" / method / f"seed{seed}"
    summary = {**SUMMARY, "success_rate": success}
    write_json(folder / "summary.json", {"summary": summary}, config_hash=config_hash)
    write_json(folder / "done.json", {"steps": 120}, config_hash=config_hash)
    write_csv(folder / "evaluation.csv", [{**dict.fromkeys(EPISODE, 0), "success": 1}], EPISODE)
    row = dict.fromkeys(PROGRESS_FIELDS, "")
    row.update(step=0, episodes=0, success_rate=success, collision_rate=0.1, mean_return=1.0)
    row.update(min_clearance_p5=0.0, wall_time_s=1.0)
    write_csv(folder / "progress.csv", [row], PROGRESS_FIELDS)
    return folder


def test_a_run_of_an_older_configuration_is_left_out_and_listed(tmp_path):
    """Seed 0 carries the hash the code resolves now, seed 1 an old one: Table I, the curves
    and the selection use seed 0 only, and the Markdown table names seed 1 as left out."""
    current = _run(tmp_path, "gprl", 0, resolve_run("dcp", "gprl", 0, "ci").hash, 0.2)
    _run(tmp_path, "gprl", 1, "0123456789abcdef", 0.9)
    selection = select_runs(tmp_path, "ci")
    assert selection.checked and selection.current == {current}
    assert selection.excluded == (
        "dcp/gprl/seed1 (configuration changed since; `distgprl status`: stale)",
    )
    rows, _ = simulation_table(load_frames(tmp_path, "ci"))
    (row,) = rows
    assert row["dcp_seeds"] == 1 and row["dcp_success_rate"].mean == 0.2
    steps, values = common_curves(run_curves(curve_frame(tmp_path, "ci"), "dcp", "gprl"))
    assert values["success_rate"].tolist() == [[0.2]]
    write_tables(tmp_path, "ci", tmp_path / "out")
    assert "Not tabulated (1): dcp/gprl/seed1" in (tmp_path / "out" / "table1_ci.md").read_text()


def test_a_tree_of_an_unknown_preset_is_used_but_says_its_hashes_were_not_checked(tmp_path):
    folder = tmp_path / "elsewhere" / "dcp" / "gprl" / "seed0"
    write_json(folder / "summary.json", {"summary": SUMMARY}, config_hash="anything")
    selection = select_runs(tmp_path, "elsewhere")
    assert not selection.checked and selection.current == {folder}
    assert "Config hashes not checked" in selection.note()


def test_a_result_file_of_an_unknown_schema_stops_the_reports_of_a_checked_preset(tmp_path):
    """In a preset of this checkout, a summary.json or done.json of an unknown schema is an
    error for the tables and the curves (SchemaVersionError, the CLI's exit 2), never a run
    quietly left out of them."""
    import json

    import pytest

    from distgprl.schema import SchemaVersionError

    _run(tmp_path, "gprl", 0, resolve_run("dcp", "gprl", 0, "ci").hash)
    odd = _run(tmp_path, "gprl", 1, resolve_run("dcp", "gprl", 1, "ci").hash)
    for name in ("summary.json", "done.json"):
        document = json.loads((odd / name).read_text())
        document["meta"]["schema_version"] = 999
        (odd / name).write_text(json.dumps(document))
    with pytest.raises(SchemaVersionError, match="schema_version 999"):
        select_runs(tmp_path, "ci")
    with pytest.raises(SchemaVersionError, match="schema_version 999"):
        write_tables(tmp_path, "ci", tmp_path / "out")
    with pytest.raises(SchemaVersionError, match="schema_version 999"):
        common_curves(run_curves(curve_frame(tmp_path, "ci"), "dcp", "gprl"))


def test_tables_of_a_tree_moved_to_another_root_are_byte_identical(tmp_path):
    """The same result files under another root give the same bytes, including the list of
    runs left out (named by task/method/seed, not by their path)."""
    import shutil

    first = tmp_path / "a" / "results"
    _run(first, "gprl", 0, resolve_run("dcp", "gprl", 0, "ci").hash, 0.2)
    _run(first, "gprl", 1, "0123456789abcdef", 0.9)
    second = tmp_path / "b" / "elsewhere"
    shutil.copytree(first, second)
    written_a = write_tables(first, "ci", tmp_path / "out_a")
    written_b = write_tables(second, "ci", tmp_path / "out_b")
    assert [p.name for p in written_a] == [p.name for p in written_b]
    for a, b in zip(written_a, written_b, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert "Not tabulated (1): dcp/gprl/seed1" in (tmp_path / "out_a" / "table1_ci.md").read_text()
