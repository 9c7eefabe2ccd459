"""Table aggregation: mean, std and 95 % interval over seeds; schema errors are clear."""

from __future__ import annotations

import json

import numpy as np
import pytest

from distgprl.experiments.results import SchemaVersionError, write_csv, write_json
from distgprl.experiments.runner import PROGRESS_FIELDS
from distgprl.report.tables import (
    LATE_CURVE_POINTS,
    aggregate,
    late_curve,
    per_seed_rows,
    simulation_table,
    write_tables,
)


def test_aggregate_mean_std_and_t_interval():
    cell = aggregate([0.2, 0.4, 0.6])
    assert cell.mean == pytest.approx(0.4)
    assert cell.std == pytest.approx(0.2)
    half = 4.302652729911275 * 0.2 / np.sqrt(3)  # t_{0.975, 2}
    assert cell.ci_low == pytest.approx(0.4 - half)
    assert cell.ci_high == pytest.approx(0.4 + half)
    assert aggregate([0.5]).text() == "0.50"
    assert aggregate([]).text() == "–"


def summary(success, collision, clearance):
    return {
        "summary": {
            "success_rate": success,
            "collision_rate": collision,
            "min_clearance_p5": clearance,
            "mean_kinematic_retention": 0.9,
        }
    }


def test_rows_follow_the_paper_order_with_the_demo_last(tmp_path):
    for method, seeds in (("demo", [0]), ("dist-gprl", [0, 1]), ("gprl", [0])):
        for seed in seeds:
            write_json(
                tmp_path / "p" / "dcp" / method / f"seed{seed}" / "summary.json",
                summary(0.5 + 0.1 * seed, 0.1, 0.01),
            )
    rows, tasks = simulation_table(tmp_path, "p")
    assert tasks == ["dcp"]
    assert [r["method"] for r in rows] == ["gprl", "dist-gprl", "demo"]
    assert rows[1]["dcp_success_rate"].mean == pytest.approx(0.55)
    assert rows[1]["dcp_seeds"] == 2


def test_unknown_schema_version_is_a_clear_error(tmp_path):
    path = tmp_path / "p" / "dcp" / "demo" / "seed0" / "summary.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps({"meta": {"schema_version": 99}, "summary": {}}))
    with pytest.raises(SchemaVersionError, match="schema_version 99 is not supported"):
        write_tables(tmp_path, "p", tmp_path / "out")


def episodes(pairs):
    """Minimal per-episode rows from (success, collision) pairs."""
    return [{"episode": i, "success": s, "collision": c} for i, (s, c) in enumerate(pairs)]


def test_safe_success_counts_only_successes_without_collision():
    from distgprl.experiments.runner import safe_success_rate

    rows = episodes([(1, 0), (1, 1), (0, 0), (0, 1)])
    assert safe_success_rate(rows) == pytest.approx(0.25)


def test_summaries_without_safe_success_fall_back_to_the_episode_file(tmp_path):
    from distgprl.experiments.results import write_csv

    folder = tmp_path / "p" / "dbm" / "dist-gprl" / "seed0"
    write_json(folder / "summary.json", summary(0.75, 0.5, 0.01))  # no safe_success_rate
    write_csv(
        folder / "evaluation.csv",
        episodes([(1, 0), (1, 1), (1, 1), (0, 0)]),
        ("episode", "success", "collision"),
    )
    rows, _ = simulation_table(tmp_path, "p")
    assert rows[0]["dbm_safe_success_rate"].mean == pytest.approx(0.25)


def test_check_flags_safe_success_above_success(tmp_path):
    from distgprl.report.check import check_table

    for method in ("demo", "dist-gprl"):
        document = summary(0.5, 0.2, 0.01)
        document["summary"]["safe_success_rate"] = 0.4 if method == "demo" else 0.6
        write_json(tmp_path / "p" / "dcp" / method / "seed0" / "summary.json", document)
    out = tmp_path / "out"
    write_tables(tmp_path, "p", out)
    problems = check_table(out / "table1_p.csv", ["dcp"])
    assert "dist-gprl dcp safe success not in [0, success]: 0.6" in problems
    assert not any(p.startswith("demo dcp") for p in problems)


def test_per_seed_table_lists_every_run_with_its_wall_time(tmp_path):
    for method, seeds in (("demo", [0]), ("dist-gprl", [1, 0]), ("gprl", [0])):
        for seed in seeds:
            folder = tmp_path / "p" / "dbm" / method / f"seed{seed}"
            write_json(
                folder / "summary.json",
                summary(0.5 + 0.1 * seed, 0.1, 0.01),
                config_hash=f"h{seed}",
            )
            if method != "demo":
                write_json(folder / "done.json", {"train_wall_time_s": 600.0 * (seed + 1)})
    rows = per_seed_rows(tmp_path, "p")
    assert [(r["method"], r["seed"]) for r in rows] == [
        ("gprl", 0),
        ("dist-gprl", 0),
        ("dist-gprl", 1),
        ("demo", 0),
    ]
    assert rows[2]["success_rate"] == pytest.approx(0.6)
    assert rows[2]["train_wall_min"] == 20.0 and rows[2]["config_hash"] == "h1"
    assert rows[3]["train_wall_min"] == ""
    write_tables(tmp_path, "p", tmp_path / "out")
    markdown = (tmp_path / "out" / "table1_p_per_seed.md").read_text()
    assert (
        "| DBM | Dist-GPRL (ours) | 1 | 0.60 | 0.10 | 0.010 | 0.90 | – | – | – | – | – | 20.0 |"
        in markdown
    )


def _curve(path, successes):
    rows = []
    for index, success in enumerate(successes):
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(step=1500 * index, success_rate=success, collision_rate=0.0)
        rows.append(row)
    write_csv(path, rows, PROGRESS_FIELDS)


def test_late_curve_averages_the_last_curve_points_only(tmp_path):
    path = tmp_path / "progress.csv"
    assert late_curve(path) == {"late_curve_success": "", "late_curve_success_range": ""}
    early = [0.9, 0.0, 0.1, 0.2]  # step 0 (untrained) and early training are left out
    late = [0.8, 0.6, 0.9, 0.7, 0.5]
    assert len(late) == LATE_CURVE_POINTS
    _curve(path, early + late)
    assert late_curve(path) == {
        "late_curve_success": pytest.approx(0.7),
        "late_curve_success_range": pytest.approx(0.4),
    }
    _curve(path, [0.9])  # only the untrained step-0 point: nothing to report
    assert late_curve(path)["late_curve_success"] == ""


def test_per_seed_table_shows_the_late_curve_next_to_the_final_success(tmp_path):
    folder = tmp_path / "p" / "dcp" / "dist-gprl" / "seed0"
    write_json(folder / "summary.json", summary(0.74, 0.06, 0.0))
    _curve(folder / "progress.csv", [0.9, 0.1, 0.8, 0.9, 0.7, 0.8, 0.9])
    write_tables(tmp_path, "p", tmp_path / "out")
    markdown = (tmp_path / "out" / "table1_p_per_seed.md").read_text()
    assert "Late curve succ | Late curve range |" in markdown
    assert "| 0.74 | 0.06 | 0.000 |" in markdown and "| 0.82 | 0.20 |" in markdown


def test_table2_is_written_as_csv_markdown_and_latex_without_mixing_backends(tmp_path):
    write_json(tmp_path / "p" / "dbm" / "demo" / "seed0" / "summary.json", summary(0.9, 0.3, 0.0))
    fields = ["trial", "backend", "status", "success", "collision", "min_clearance"]
    trials = {
        "twin": [("ok", 1, 0, 0.02), ("refused", 0, 0, 0.05), ("ok", 1, 1, -0.01)],
        "ur": [("ok", 0, 0, 0.03)],
    }
    for backend, outcomes in trials.items():
        rows = [
            dict(zip(fields, (k, backend, *outcome), strict=True))
            for k, outcome in enumerate(outcomes)
        ]
        write_csv(tmp_path / "hardware" / "dist-gprl" / f"trials_{backend}.csv", rows, fields)
    written = {path.name for path in write_tables(tmp_path, "p", tmp_path / "out")}
    assert {"table2_hardware.csv", "table2_hardware.md", "table2_hardware.tex"} <= written
    out = tmp_path / "out"
    lines = (out / "table2_hardware.csv").read_text().splitlines()
    assert lines[0] == "method,backend,trials,refused,success_rate,collision_rate,min_clearance_p5"
    twin = lines[1].split(",")
    assert twin[:4] == ["dist-gprl", "twin", "3", "1"]
    assert float(twin[4]) == pytest.approx(2 / 3) and float(twin[5]) == pytest.approx(1 / 3)
    assert float(twin[6]) == pytest.approx(np.percentile([0.02, 0.05, -0.01], 5))
    assert lines[2].split(",")[:4] == ["dist-gprl", "ur", "1", "0"]
    markdown = (out / "table2_hardware.md").read_text()
    assert "| Dist-GPRL (ours) | twin | 3 | 1 | 0.67 | 0.33 |" in markdown
    assert "| Dist-GPRL (ours) | ur | 1 | 0 | 0.00 | 0.00 | 0.030 |" in markdown
    latex = (out / "table2_hardware.tex").read_text()
    assert "Dist-GPRL (ours) & twin & 3 & 1 & 0.67 & 0.33 &" in latex
    assert latex.count("\\\\") == 3  # header and two rows


def test_table2_disappears_with_its_trial_files(tmp_path):
    write_json(tmp_path / "p" / "dbm" / "demo" / "seed0" / "summary.json", summary(0.9, 0.3, 0.0))
    fields = ["trial", "backend", "status", "success", "collision", "min_clearance"]
    trials = tmp_path / "hardware" / "demo" / "trials_twin.csv"
    write_csv(trials, [dict(zip(fields, (0, "twin", "ok", 1, 0, 0.02), strict=True))], fields)
    write_tables(tmp_path, "p", tmp_path / "out")
    assert (tmp_path / "out" / "table2_hardware.md").exists()
    trials.unlink()  # e.g. moved to results/exploration/ when its scene changed
    written = write_tables(tmp_path, "p", tmp_path / "out")
    assert not any(path.name.startswith("table2") for path in written)
    assert not list((tmp_path / "out").glob("table2_hardware.*"))
