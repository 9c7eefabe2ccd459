"""Table aggregation: mean, std and 95 % interval over seeds; schema errors are clear."""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from distgprl.machine import machine_info
from distgprl.report.frame import load_frames
from distgprl.report.table1 import (
    LATE_CURVE_POINTS,
    aggregate,
    late_curve,
    per_seed_rows,
    simulation_table,
)
from distgprl.report.table2 import binomial_interval, hardware_table, select_trial_files
from distgprl.report.tables import write_tables
from distgprl.schema import PROGRESS_FIELDS, SchemaVersionError, moved_robot, write_csv, write_json


def test_aggregate_mean_std_and_t_interval():
    cell = aggregate([0.2, 0.4, 0.6])
    assert cell.mean == pytest.approx(0.4)
    assert cell.std == pytest.approx(0.2)
    half = 4.302652729911275 * 0.2 / np.sqrt(3)  # t_{0.975, 2}
    assert cell.ci_low == pytest.approx(0.4 - half)
    assert cell.ci_high == pytest.approx(0.4 + half)
    assert aggregate([0.5]).text() == "0.50"
    assert aggregate([]).text() == "–"


def summary(success, collision, clearance, free=None):
    """A v5 summary: completion as success (no episode completed before a collision), the
    signed clearance percentile as MinCl's over all episodes; with ``free`` a v6 one, whose
    MinCl over the collision-free episodes is ``free``."""
    document = {
        "summary": {
            "success_rate": success,
            "collision_rate": collision,
            "min_clearance_p5": clearance,
            "min_signed_clearance_p5": clearance,
            "completion_rate": success,
            "mean_kinematic_retention": 0.9,
        }
    }
    if free is not None:
        document["summary"]["min_clearance_p5_collision_free"] = free
        document["summary"]["collision_free_episodes"] = 10
    return document


def test_rows_follow_the_paper_order_with_the_demo_last(tmp_path):
    for method, seeds in (("demo", [0]), ("dist-gprl", [0, 1]), ("gprl", [0])):
        for seed in seeds:
            write_json(
                tmp_path / "p" / "dcp" / method / f"seed{seed}" / "summary.json",
                summary(0.5 + 0.1 * seed, 0.1, 0.01),
            )
    rows, tasks = simulation_table(load_frames(tmp_path, "p"))
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


EPISODE_FIELDS = ("episode", "object_offset_x", "object_offset_y", "obstacle_offset_x")
EPISODE_FIELDS += ("obstacle_offset_y", "success", "collision")


def episodes(pairs):
    """Minimal per-episode rows from (success, collision) pairs."""
    return [{"episode": i, "success": s, "collision": c} for i, (s, c) in enumerate(pairs)]


def test_safe_success_counts_only_successes_without_collision():
    from distgprl.schema import safe_success_rate

    rows = episodes([(1, 0), (1, 1), (0, 0), (0, 1)])
    assert safe_success_rate(rows) == pytest.approx(0.25)


def test_check_flags_success_above_completion_and_rates_past_one(tmp_path):
    """v5: success (completion without collision) cannot exceed completion, and success and
    collision exclude each other, so they sum to at most 1; MinCl is a distance (>= 0)."""
    from distgprl.report.check import check_table

    for method, (success, collision, completed, clearance) in {
        "demo": (0.4, 0.5, 0.4, 0.0),
        "dist-gprl": (0.6, 0.5, 0.5, -0.01),
    }.items():
        document = summary(success, collision, clearance)
        document["summary"]["completion_rate"] = completed
        write_json(tmp_path / "p" / "dcp" / method / "seed0" / "summary.json", document)
    out = tmp_path / "out"
    write_tables(tmp_path, "p", out)
    problems = check_table(out / "table1_p.csv", ["dcp"])
    assert "dist-gprl dcp success above completion: 0.6 > 0.5" in problems
    assert "dist-gprl dcp success + collision above 1: 1.1" in problems
    assert "dist-gprl dcp MinCl negative: -0.01" in problems
    assert not any(p.startswith("demo dcp") for p in problems)


def test_per_seed_table_lists_every_run_with_its_wall_and_cpu_time(tmp_path):
    """Wall time, CPU time per step and the machine's numerics come from ``done.json``; a
    run made before the CPU time was recorded shows none (the gprl run here)."""
    for method, seeds in (("demo", [0]), ("dist-gprl", [1, 0]), ("gprl", [0])):
        for seed in seeds:
            folder = tmp_path / "p" / "dbm" / method / f"seed{seed}"
            write_json(
                folder / "summary.json",
                summary(0.5 + 0.1 * seed, 0.1, 0.01),
                config_hash=f"h{seed}",
            )
            if method != "demo":
                done = {"train_wall_time_s": 600.0 * (seed + 1)}
                if method == "dist-gprl":
                    done["cpu_s_per_step"] = 0.0375 * (seed + 1)
                write_json(folder / "done.json", done)
                write_csv(
                    folder / "evaluation.csv",
                    [{**dict.fromkeys(EPISODE_FIELDS, 0), "success": 1}],
                    EPISODE_FIELDS,
                )
    rows = per_seed_rows(load_frames(tmp_path, "p"))
    assert [(r["method"], r["seed"]) for r in rows] == [
        ("gprl", 0),
        ("dist-gprl", 0),
        ("dist-gprl", 1),
        ("demo", 0),
    ]
    assert rows[2]["success_rate"] == pytest.approx(0.6)
    assert rows[2]["train_wall_min"] == 20.0 and rows[2]["config_hash"] == "h1"
    assert rows[3]["train_wall_min"] == ""
    assert rows[2]["train_cpu_ms_per_step"] == 75.0 and rows[0]["train_cpu_ms_per_step"] == ""
    assert rows[2]["numerics"] == machine_info()["numerics"] and rows[3]["numerics"] == ""
    write_tables(tmp_path, "p", tmp_path / "out")
    markdown = (tmp_path / "out" / "table1_p_per_seed.md").read_text()
    assert (  # no best-policy evaluation: the final policy's, listed under Table I
        "| DBM | Dist-GPRL (ours) | 1 | final | – | 0.60 | 0.10 | – | 0.010 | 0.010 | 0.60 "
        "| 0.90 | – | – | – | – | 20.0 | 75.0 |" in markdown
    )
    assert "| DBM | GPRL | 0 |" in markdown and "| 10.0 | – |" in markdown


def _curve(path, successes):
    rows = []
    for index, success in enumerate(successes):
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(step=1500 * index, success_rate=success, collision_rate=0.0)
        rows.append(row)
    write_csv(path, rows, PROGRESS_FIELDS)


def _points(successes):
    """One run's curve points (`distgprl.report.frame.curves_of`), every 1 500 steps."""
    return pd.DataFrame(
        {"step": [1500 * k for k in range(len(successes))], "success_rate": successes}
    )


def test_late_curve_averages_the_last_curve_points_only():
    assert late_curve(_points([])) == {"late_curve_success": "", "late_curve_success_range": ""}
    early = [0.9, 0.0, 0.1, 0.2]  # step 0 (untrained) and early training are left out
    late = [0.8, 0.6, 0.9, 0.7, 0.5]
    assert len(late) == LATE_CURVE_POINTS
    assert late_curve(_points(early + late)) == {
        "late_curve_success": pytest.approx(0.7),
        "late_curve_success_range": pytest.approx(0.4),
    }
    only_untrained = late_curve(_points([0.9]))  # the untrained step-0 point: nothing to report
    assert only_untrained["late_curve_success"] == ""


def test_per_seed_table_shows_the_late_curve_next_to_the_final_success(tmp_path):
    folder = tmp_path / "p" / "dcp" / "dist-gprl" / "seed0"
    write_json(folder / "summary.json", summary(0.74, 0.06, 0.0))
    _curve(folder / "progress.csv", [0.9, 0.1, 0.8, 0.9, 0.7, 0.8, 0.9])
    write_tables(tmp_path, "p", tmp_path / "out")
    markdown = (tmp_path / "out" / "table1_p_per_seed.md").read_text()
    assert "Late curve succ | Late curve range |" in markdown
    assert "| 0.74 | 0.06 | – | 0.000 |" in markdown and "| 0.82 | 0.20 |" in markdown


def test_table2_is_written_as_csv_markdown_and_latex_without_mixing_backends(tmp_path):
    write_json(tmp_path / "p" / "dbm" / "demo" / "seed0" / "summary.json", summary(0.9, 0.3, 0.0))
    fields = ["trial", "backend", "status", "success", "collision", "min_clearance"]
    fields.append("execution_s")
    trials = {
        "twin": [("ok", 1, 0, 0.02, 0.2), ("refused", 0, 0, 0.05, 0.0), ("ok", 1, 1, -0.01, 0.3)],
        "ur": [("ok", 0, 0, 0.03, 0.2)],
    }
    for backend, outcomes in trials.items():
        rows = [
            dict(zip(fields, (k, backend, *outcome), strict=True))
            for k, outcome in enumerate(outcomes)
        ]
        write_csv(
            tmp_path / "hardware" / "dist-gprl" / f"trials_{backend}.csv", rows, fields, preset="p"
        )
    written = {path.name for path in write_tables(tmp_path, "p", tmp_path / "out")}
    assert {"table2_p.csv", "table2_p.md", "table2_p.tex"} <= written
    out = tmp_path / "out"
    lines = (out / "table2_p.csv").read_text().splitlines()
    assert lines[0] == (
        "method,backend,protocol,repair,sensor_noise,trials,refused,protective_stops,"
        "success_rate,collision_rate,min_clearance_p5,executed,success_rate_ci_low,"
        "success_rate_ci_high,collision_rate_ci_low,collision_rate_ci_high"
    )
    twin = dict(zip(lines[0].split(","), lines[1].split(","), strict=True))
    # a file without a protocol in its meta ran behind the safety layer (every v7 file)
    assert [twin[k] for k in ("method", "backend", "protocol", "repair", "sensor_noise")] == [
        "dist-gprl", "twin", "safety-layer", "–", "0"
    ]  # fmt: skip
    assert (twin["trials"], twin["refused"], twin["protective_stops"]) == ("3", "1", "0")
    assert float(twin["success_rate"]) == pytest.approx(2 / 3)
    assert float(twin["collision_rate"]) == pytest.approx(1 / 3)
    assert float(twin["min_clearance_p5"]) == pytest.approx(np.percentile([0.02, -0.01], 5))
    assert twin["executed"] == "2"  # moved only
    # Clopper-Pearson 95 %: 2 of 3 [0.0943, 0.9916], 1 of 3 [0.0084, 0.9057] (beta quantiles)
    bounds = [twin[f"{r}_rate_ci_{e}"] for r in ("success", "collision") for e in ("low", "high")]
    assert [float(x) for x in bounds] == pytest.approx([0.0943, 0.9916, 0.0084, 0.9057], abs=1e-4)
    assert lines[2].split(",")[:3] == ["dist-gprl", "ur", "safety-layer"]
    markdown = (out / "table2_p.md").read_text()
    paper_empty = "– | – | – | – | –"  # no trial of the paper's protocol in these files
    assert (
        f"| Dist-GPRL (ours) | twin | 0 | {paper_empty} | 3 | 1 | 0.67 [0.09, 0.99] | "
        "0.33 [0.01, 0.91] | -0.009 (n=2) |"
    ) in markdown
    assert (
        f"| Dist-GPRL (ours) | ur | – | {paper_empty} | 1 | 0 | 0.00 [0.00, 0.97] | "
        "0.00 [0.00, 0.97] | 0.030 |"
    ) in markdown
    latex = (out / "table2_p.tex").read_text()
    assert (
        "Dist-GPRL (ours) & twin & 0 & -- & -- & -- & -- & -- & 3 & 1 & 0.67 [0.09, 0.99] & "
        "0.33 [0.01, 0.91] &"
    ) in latex
    assert not (out / "table2_noise_p.md").exists()  # one noise level: no robustness table
    assert latex.count("\\\\") == 4  # the group header, the header and two rows


def test_table2_disappears_with_its_trial_files(tmp_path):
    write_json(tmp_path / "p" / "dbm" / "demo" / "seed0" / "summary.json", summary(0.9, 0.3, 0.0))
    fields = ["trial", "backend", "status", "success", "collision", "min_clearance"]
    trials = tmp_path / "hardware" / "demo" / "trials_twin.csv"
    write_csv(
        trials, [dict(zip(fields, (0, "twin", "ok", 1, 0, 0.02), strict=True))], fields, preset="p"
    )
    write_tables(tmp_path, "p", tmp_path / "out")
    assert (tmp_path / "out" / "table2_p.md").exists()
    trials.unlink()  # e.g. moved to results/exploration/ when its scene changed
    written = write_tables(tmp_path, "p", tmp_path / "out")
    assert not any(path.name.startswith("table2") for path in written)
    assert not list((tmp_path / "out").glob("table2_p.*"))


def test_table1_markdown_and_latex_show_the_95_percent_interval_on_success_and_collision(
    tmp_path,
):
    """With >= 2 seeds the Markdown and LaTeX Success and Collision cells read
    ``mean ± std [low, high]`` with the Student-t 95 % interval (clipped to [0, 1]), the
    other columns stay ``mean ± std``, single-seed cells stay ``mean`` with the seed count,
    the caption says so, and the CSV's rate intervals are clipped to [0, 1] too (its other
    intervals are not: MinCl's may fall below zero)."""
    seeds = {
        0: summary(0.80, 0.10, 0.010, free=0.020),
        1: summary(0.90, 0.20, 0.020, free=0.030),
        2: summary(1.00, 0.30, 0.030, free=0.040),
    }
    for seed, document in seeds.items():
        folder = tmp_path / "p" / "dcp" / "dist-gprl" / f"seed{seed}"
        write_json(folder / "summary_best.json", document)
        write_json(folder / "summary.json", summary(0.1, 0.9, 0.0, free=0.0))  # final: not shown
    write_json(tmp_path / "p" / "dcp" / "demo" / "seed0" / "summary.json", summary(0.5, 0.4, 0.0))
    write_tables(tmp_path, "p", tmp_path / "out")
    half = 4.302652729911275 * 0.1 / np.sqrt(3)  # t_{0.975, 2}; both rates' sample std 0.1
    assert (0.9 - half, 0.2 + half) == pytest.approx((0.6516, 0.4484), abs=1e-4)
    success = "0.90 ± 0.10 [0.65, 1.00]"  # t-interval [0.65, 1.15], clipped to the rate's range
    collision = "0.20 ± 0.10 [0.00, 0.45]"  # t-interval [-0.05, 0.45]
    markdown = (tmp_path / "out" / "table1_p.md").read_text()
    assert (
        f"| Dist-GPRL (ours) | {success} [3] | {collision} | 0.030 ± 0.010 | 0.020 ± 0.010 | "
        "0.020 ± 0.010 | 0.90 ± 0.10 | 0.90 ± 0.00 |" in markdown
    )
    assert (
        "| Demo (no adaptation) | 0.50 [1] | 0.40 | – | 0.000 | 0.000 | 0.50 | 0.90 |" in markdown
    )
    assert "95 % t-interval" in markdown.splitlines()[0]
    latex = (tmp_path / "out" / "table1_p.tex").read_text()
    pm = "$\\pm$"
    assert (
        f"Dist-GPRL (ours) & 0.90 {pm} 0.10 [0.65, 1.00] & 0.20 {pm} 0.10 [0.00, 0.45] &" in latex
    )
    assert (
        f"[0.00, 0.45] & 0.030 {pm} 0.010 & 0.020 {pm} 0.010 & 0.020 {pm} 0.010 & 0.90 {pm} 0.10 "
        f"& 0.90 {pm} 0.00" in latex
    )
    assert "Demo (no adaptation) & 0.50 & 0.40 & -- & 0.000 &" in latex
    assert "95\\,\\% t-interval" in latex
    with open(tmp_path / "out" / "table1_p.csv", newline="") as handle:
        ours = {row["method"]: row for row in csv.DictReader(handle)}["dist-gprl"]
    assert float(ours["dcp_success_rate_ci_low"]) == pytest.approx(0.9 - half, rel=1e-5)
    assert float(ours["dcp_success_rate_ci_high"]) == 1.0  # t: 1.15
    assert float(ours["dcp_collision_rate_ci_low"]) == 0.0  # t: -0.05
    assert float(ours["dcp_collision_rate_ci_high"]) == pytest.approx(0.2 + half, rel=1e-5)
    clearance_half = 4.302652729911275 * 0.01 / np.sqrt(3)
    assert float(ours["dcp_min_clearance_p5_ci_low"]) == pytest.approx(
        0.02 - clearance_half, rel=1e-5
    )  # -0.005: a distance's interval is not a rate's


def test_every_table_csv_has_a_meta_sidecar_and_reads_with_plain_pandas(tmp_path):
    """Each CSV `write_tables` makes reads with a default ``pandas.read_csv`` (header, one
    row per method/run) and with `read_csv` through its ``.csv.meta.json`` sidecar, whose
    columns are the CSV's; the sidecars are deterministic (the same bytes when remade)."""
    pandas = pytest.importorskip("pandas")
    from distgprl.schema import read_csv

    for seed in (0, 1):
        folder = tmp_path / "p" / "dcp" / "dist-gprl" / f"seed{seed}"
        write_json(folder / "summary.json", summary(0.5 + 0.1 * seed, 0.1, 0.01))
    write_json(tmp_path / "p" / "dcp" / "demo" / "seed0" / "summary.json", summary(0.5, 0.4, 0))
    written = write_tables(tmp_path, "p", tmp_path / "out")
    csvs = [path for path in written if path.suffix == ".csv"]
    assert {path.name for path in csvs} >= {"table1_p.csv", "table1_p_per_seed.csv"}
    for path in csvs:
        sidecar = path.with_name(path.name + ".meta.json")
        assert sidecar in written
        frame = pandas.read_csv(path)
        meta, rows = read_csv(path)
        assert meta["kind"] == "table" and meta["preset"] == "p"
        assert json.loads(sidecar.read_text())["columns"] == list(frame.columns)
        assert len(frame) == len(rows) > 0
    assert pandas.read_csv(tmp_path / "out" / "table1_p.csv")["method"].tolist() == [
        "dist-gprl",
        "demo",
    ]
    before = {path: path.read_bytes() for path in written}
    write_tables(tmp_path, "p", tmp_path / "out")
    assert {path: path.read_bytes() for path in written} == before


def test_table2_min_clearance_is_over_trials_that_moved_the_robot_only(tmp_path):
    """A trial refused in its first window never moved (execution_s 0; its clearance is
    the start pose's): it counts in the rates but not in MinCl, and the table says over how
    many trials MinCl is. A trial refused after executing earlier windows did move and
    counts. With no trial that moved, MinCl is empty / "–", not a number."""
    write_json(tmp_path / "p" / "dbm" / "demo" / "seed0" / "summary.json", summary(0.9, 0.3, 0.0))
    fields = ["trial", "backend", "status", "success", "collision", "min_clearance"]
    fields.append("execution_s")
    moved = [("ok", 1, 0, 0.012, 0.2), ("ok", 1, 0, 0.004, 0.2), ("refused", 0, 0, 0.008, 0.05)]
    unmoved = [("refused", 0, 0, 0.1, 0.0), ("refused", 0, 0, 0.1, 0.0)]
    rows = [dict(zip(fields, (k, "twin", *t), strict=True)) for k, t in enumerate(moved + unmoved)]
    write_csv(tmp_path / "hardware" / "dist-gprl" / "trials_twin.csv", rows, fields, preset="p")
    never = [dict(zip(fields, (k, "twin", *t), strict=True)) for k, t in enumerate(unmoved)]
    write_csv(tmp_path / "hardware" / "gprl" / "trials_twin.csv", never, fields, preset="p")
    table = {row["method"]: row for row in hardware_table(tmp_path, "p")}
    ours = table["dist-gprl"]
    assert (ours["trials"], ours["refused"], ours["executed"]) == (5, 3, 3)
    assert ours["success_rate"] == pytest.approx(2 / 5)  # rates: over all trials
    ordered = sorted([0.012, 0.004, 0.008])
    position = 0.05 * (len(ordered) - 1)  # numpy's default (linear) percentile
    expected = ordered[0] + (position - int(position)) * (ordered[1] - ordered[0])
    assert ours["min_clearance_p5"] == pytest.approx(expected)
    assert np.isnan(table["gprl"]["min_clearance_p5"]) and table["gprl"]["executed"] == 0
    write_tables(tmp_path, "p", tmp_path / "out")
    out = tmp_path / "out"
    markdown = (out / "table2_p.md").read_text()
    ours_cells = f"| 5 | 3 | 0.40 [0.05, 0.85] | 0.00 [0.00, 0.52] | {expected:.3f} (n=3) |"
    paper_empty = "| – | – | – | – | – "  # no trial of the paper's protocol in these files
    assert f"| Dist-GPRL (ours) | twin | 0 {paper_empty}{ours_cells}" in markdown
    gprl = (
        f"| GPRL | twin | 0 {paper_empty}| 2 | 2 | 0.00 [0.00, 0.84] | 0.00 [0.00, 0.84] | "
        "– (n=0) |"
    )
    assert gprl in markdown
    assert "MinCl is over the trials that moved the robot" in markdown.splitlines()[0]
    latex = (out / "table2_p.tex").read_text()
    assert f"& {expected:.3f} (n=3) \\\\" in latex and "& -- (n=0) \\\\" in latex
    lines = (out / "table2_p.csv").read_text().splitlines()
    gprl = dict(zip(lines[0].split(","), lines[1].split(","), strict=True))
    assert (gprl["method"], gprl["min_clearance_p5"], gprl["executed"]) == ("gprl", "", "0")


def test_moved_robot_reads_status_and_execution_time():
    """``ok`` trials and any with execution time moved; refused-before-motion, stopped
    before motion and not-perceived trials did not."""
    assert moved_robot({"status": "ok", "execution_s": ""})
    assert moved_robot({"status": "refused", "execution_s": "0.069"})
    assert moved_robot({"status": "stopped", "execution_s": "0.1"})
    assert not moved_robot({"status": "refused", "execution_s": "0.0"})
    assert not moved_robot({"status": "not_perceived", "execution_s": "0.0"})
    assert not moved_robot({"status": "refused"})


@pytest.mark.parametrize(
    ("successes", "trials", "expected"),
    [(0, 10, (0.0, 0.3085)), (10, 10, (0.6915, 1.0)), (7, 10, (0.3475, 0.9333))],
)
def test_binomial_interval_is_the_exact_clopper_pearson_interval(successes, trials, expected):
    """Against the published exact 95 % intervals for 0, 7 and 10 successes in 10 trials."""
    assert binomial_interval(successes, trials) == pytest.approx(expected, abs=1e-4)


def test_binomial_interval_is_scipys_exact_interval():
    """Clopper-Pearson by the beta quantiles is `binomtest(...).proportion_ci`'s exact
    interval (scipy finds it by root-finding: the two agree to 1e-12, not to the bit)."""
    for trials in (1, 7, 10, 50):
        for successes in range(trials + 1):
            exact = stats.binomtest(successes, trials).proportion_ci(method="exact")
            assert binomial_interval(successes, trials) == pytest.approx(
                (exact.low, exact.high), abs=1e-12
            )


def test_table2_of_a_preset_counts_its_current_unforced_policies_only(tmp_path):
    """Table II of the `ci` preset counts the trials of ci policies of the current
    configuration; trials run with the pre-flight check overridden (--force) or with a
    policy of another configuration are listed under it, not counted; another preset's
    trials are not this table's, and its Table II file is left alone."""
    from distgprl.identity import resolve_run

    write_json(
        tmp_path / "ci" / "dbm" / "demo" / "seed0" / "summary.json",
        summary(0.9, 0.3, 0.0),
        config_hash=resolve_run("dbm", "demo", 0, "ci").hash,
    )
    fields = ["trial", "backend", "status", "success", "collision", "min_clearance"]
    current = resolve_run("dbm", "dist-gprl", 0, "ci").hash

    def trials(name, outcomes, **meta):
        rows = [dict(zip(fields, (k, "twin", *o), strict=True)) for k, o in enumerate(outcomes)]
        write_csv(tmp_path / "hardware" / "dist-gprl" / name, rows, fields, **meta)

    policy = {"run_config_hash": current}
    trials("a.csv", [("ok", 1, 0, 0.02)] * 2, preset="ci", seed=0, policy=policy)
    trials("b.csv", [("ok", 0, 1, -0.01)], preset="ci", seed=0, policy=policy, force=True)
    old = {"run_config_hash": "0123456789abcdef"}
    trials("c.csv", [("ok", 0, 1, -0.01)], preset="ci", seed=0, policy=old)
    trials("d.csv", [("ok", 0, 1, -0.01)], preset="paper", seed=0, policy=old)
    selection = select_trial_files(tmp_path, "ci")
    assert [(method, len(rows)) for method, _, rows in selection.counted] == [("dist-gprl", 2)]
    assert selection.excluded == (
        "dist-gprl/b.csv (pre-flight check overridden, --force)",
        "dist-gprl/c.csv (policy config hash 0123456789abcdef, not the current one)",
    )
    (row,) = hardware_table(tmp_path, "ci")
    assert (row["trials"], row["success_rate"], row["collision_rate"]) == (2, 1.0, 0.0)
    out = tmp_path / "out"
    out.mkdir()
    (out / "table2_paper.md").write_text("the paper preset's Table II")
    write_tables(tmp_path, "ci", out)
    markdown = (out / "table2_ci.md").read_text()
    assert "Not tabulated (2): dist-gprl/b.csv" in markdown and "dist-gprl/d.csv" not in markdown
    assert (out / "table2_paper.md").read_text() == "the paper preset's Table II"
    latex = (out / "table2_ci.tex").read_text()
    assert "95\\,\\% binomial interval" in latex and " % " not in latex


def test_table1_iqm_columns_are_the_aggregates_bootstrap_estimates(tmp_path):
    """Table I's Success / Collision IQM columns are the interquartile mean over seeds (four
    seeds: the mean of the middle two) with the 95 % stratified-bootstrap interval, the very
    numbers of the aggregates table (same estimate, same generator); one seed gives the IQM
    alone."""
    for seed, success in enumerate((0.6, 0.8, 0.9, 1.0)):
        path = tmp_path / "p" / "dcp" / "dist-gprl" / f"seed{seed}" / "summary.json"
        write_json(path, summary(success, 1.0 - success, 0.01))
    write_json(tmp_path / "p" / "dcp" / "demo" / "seed0" / "summary.json", summary(0.5, 0.4, 0.0))
    write_tables(tmp_path, "p", tmp_path / "out")
    with open(tmp_path / "out" / "table1_p.csv", newline="") as handle:
        rows = {row["method"]: row for row in csv.DictReader(handle)}
    ours = rows["dist-gprl"]
    assert float(ours["dcp_success_rate_iqm"]) == pytest.approx(0.85)
    assert float(ours["dcp_collision_rate_iqm"]) == pytest.approx(0.15)
    with open(tmp_path / "out" / "aggregates_p.csv", newline="") as handle:
        aggregates = [
            r
            for r in csv.DictReader(handle)
            if (r["task"], r["method"], r["statistic"]) == ("dcp", "dist-gprl", "iqm")
        ]
    by_metric = {r["metric"]: r for r in aggregates}
    for key in ("success_rate", "collision_rate"):
        for part, column in (("iqm", "value"), ("iqm_low", "ci_low"), ("iqm_high", "ci_high")):
            assert float(ours[f"dcp_{key}_{part}"]) == pytest.approx(
                float(by_metric[key][column]), abs=1e-6
            )
    low, high = float(ours["dcp_success_rate_iqm_low"]), float(ours["dcp_success_rate_iqm_high"])
    assert 0.6 <= low < 0.85 < high <= 1.0
    markdown = (tmp_path / "out" / "table1_p.md").read_text()
    assert f"| 0.85 [{low:.2f}, {high:.2f}] |" in markdown
    assert (
        rows["demo"]["dcp_success_rate_iqm"] == "0.5"
        and rows["demo"]["dcp_success_rate_iqm_low"] == ""
    )
    assert "stratified-bootstrap" in markdown.splitlines()[0]


def test_table2_keeps_repair_and_noise_apart_and_the_noise_table_pivots_the_twin(tmp_path):
    """Trial files of one method with plan repair off, retime, and retime at noise levels 1 and
    2 make four Table II rows (never pooled), and the robustness table shows the twin's
    retime rows against the noise level, with '–' where a setting did not run at a level."""
    write_json(tmp_path / "p" / "dbm" / "demo" / "seed0" / "summary.json", summary(0.9, 0.3, 0.0))
    fields = ["trial", "backend", "status", "success", "collision", "min_clearance"]
    fields += ["perception_error_mm"]
    settings = {  # name: (meta, outcomes)
        "off.csv": ({"repair": False, "sensor_noise": 0}, [("refused", 0, 0, 0.05, 2)] * 2),
        "retime.csv": ({"repair": True, "sensor_noise": 0}, [("ok", 1, 0, 0.02, 3)] * 2),
        "noisy1.csv": (
            {"repair": True, "sensor_noise": 1},
            [("ok", 1, 0, 0.02, 6), ("ok", 0, 1, 0, 10)],
        ),
        "noisy2.csv": ({"repair": True, "sensor_noise": 2}, [("ok", 0, 1, -0.01, 20)] * 2),
    }
    for name, (meta, outcomes) in settings.items():
        rows = [
            dict(zip(fields, (k, "twin", *outcome), strict=True))
            for k, outcome in enumerate(outcomes)
        ]
        write_csv(tmp_path / "hardware" / "demo" / name, rows, fields, preset="p", **meta)
    rows = hardware_table(tmp_path, "p")
    assert [(r["repair"], r["sensor_noise"], r["trials"]) for r in rows] == [
        ("off", "0", 2),
        ("retime", "0", 2),
        ("retime", "1", 2),
        ("retime", "2", 2),
    ]
    assert [r["success_rate"] for r in rows] == [0.0, 1.0, 0.5, 0.0]
    assert [r["perception_error_mm_median"] for r in rows] == [2.0, 3.0, 8.0, 20.0]
    write_tables(tmp_path, "p", tmp_path / "out")
    noise = (tmp_path / "out" / "table2_noise_p.md").read_text()
    assert "Noise 0 Success | Noise 0 Collision | Noise 1 error (mm) | Noise 1 Success" in noise
    assert (
        "| Demo (no adaptation) | retime | 3 | 1.00 [0.16, 1.00] | 0.00 [0.00, 0.84] | 8 | 0.50"
        in noise
    )
    assert (
        "| Demo (no adaptation) | off | 2 | 0.00 [0.00, 0.84] | 0.00 [0.00, 0.84] | – | – | – | – "
        "| – | – |" in noise
    )
    # the noise curve: the repair-on twin rows against the median perception error
    from distgprl.report.curves import write_curves
    from distgprl.report.noise_curve import curve_series

    assert [r["sensor_noise"] for r in curve_series(rows)["demo"]] == ["0", "1", "2"]
    names = {p.name for p in write_curves(tmp_path, "p", tmp_path / "out")}
    assert {"table2_noise_p.png", "table2_noise_p.pdf"} <= names


def test_table2_counts_one_twin_file_per_policy_seed_and_setting(tmp_path):
    """The twin draws a seed's bar positions from the seed, so an interrupted run's partial
    file and its complete re-run hold the same first trials: Table II counts the file with
    the most trials (the newest on a tie) and lists the repeat. Another seed or setting is
    not a repeat, and trials on the real robot are new executions: all counted."""
    write_json(tmp_path / "p" / "dbm" / "demo" / "seed0" / "summary.json", summary(0.9, 0.3, 0.0))
    fields = ["trial", "backend", "status", "success", "collision", "min_clearance"]

    def trials(name, count, backend="twin", **meta):
        rows = [
            dict(zip(fields, (k, backend, "ok", 1, 0, 0.02), strict=True)) for k in range(count)
        ]
        meta = {"preset": "p", "backend": backend, "repair": True, "sensor_noise": 0} | meta
        write_csv(tmp_path / "hardware" / "demo" / name, rows, fields, **meta)

    trials("trials_twin_seed0_1.csv", 1, seed=0)  # interrupted
    trials("trials_twin_seed0_2.csv", 3, seed=0)  # its complete re-run
    trials("trials_twin_seed0_3.csv", 3, seed=0, sensor_noise=1)  # another setting
    trials("trials_twin_seed1_1.csv", 3, seed=1)  # another seed
    trials("trials_twin_seed1_2.csv", 3, seed=1)  # the same again: the newest counts
    trials("trials_ur_seed0_1.csv", 2, backend="ur", seed=0)
    trials("trials_ur_seed0_2.csv", 2, backend="ur", seed=0)
    selection = select_trial_files(tmp_path, "p")
    assert sorted(len(rows) for _, _, rows in selection.counted) == [2, 2, 3, 3, 3]
    assert selection.excluded == (
        "demo/trials_twin_seed0_1.csv (repeats the twin trials of trials_twin_seed0_2.csv: "
        "same seed and setting, same bar positions; 1 trials)",
        "demo/trials_twin_seed1_1.csv (repeats the twin trials of trials_twin_seed1_2.csv: "
        "same seed and setting, same bar positions; 3 trials)",
    )
    rows = {(r["backend"], r["sensor_noise"]): r["trials"] for r in hardware_table(tmp_path, "p")}
    assert rows == {("twin", "0"): 6, ("twin", "1"): 3, ("ur", "–"): 4}


def _write_runs(root, runs):
    """Summaries of (method, seed, success) DCP runs of the unchecked preset ``p``."""
    for method, seed, success in runs:
        folder = root / "p" / "dcp" / method / f"seed{seed}"
        write_json(folder / "summary.json", summary(success, 0.1, 0.01))


def test_the_one_demo_study_is_its_own_table_and_leaves_table_1_and_the_claims_unchanged(
    tmp_path,
):
    """Runs of the study methods (`STUDY_METHODS`) in the preset's folder make
    ``one_demo_study_<preset>`` — Table I's ProMP-RRL and nominal above their one-demonstration
    versions — and change no byte of any other table; without them the study table is gone."""
    table_one = [("dist-gprl", 0, 0.9), ("promp-rrl", 0, 0.6), ("promp-rrl", 1, 0.7)]
    table_one += [("promp-nominal", 0, 0.7), ("demo", 0, 0.5)]
    study = [("promp-rrl-1demo", 0, 0.2), ("promp-rrl-1demo", 1, 0.4)]
    study += [("promp-nominal-1demo", 0, 0.65)]
    _write_runs(tmp_path / "without", table_one)
    _write_runs(tmp_path / "with", table_one + study)
    without = write_tables(tmp_path / "without", "p", tmp_path / "out_without")
    with_study = write_tables(tmp_path / "with", "p", tmp_path / "out_with")
    written = {path.name: path.read_bytes() for path in without}
    added = {path.name: path.read_bytes() for path in with_study if path.name not in written}
    assert {path.name: path.read_bytes() for path in with_study if path.name in written} == written
    assert set(added) == {"one_demo_study_p.csv", "one_demo_study_p.csv.meta.json"} | {
        "one_demo_study_p.md"
    }
    frame = pd.read_csv(tmp_path / "out_with" / "one_demo_study_p.csv")
    assert frame["method"].tolist() == [
        "promp-rrl",
        "promp-rrl-1demo",
        "promp-nominal",
        "promp-nominal-1demo",
    ]
    assert frame["dcp_success_rate_mean"].tolist() == pytest.approx([0.65, 0.3, 0.7, 0.65])
    assert "ProMP-RRL (1 demo)" in (tmp_path / "out_with" / "one_demo_study_p.md").read_text()
    for name in ("promp-rrl-1demo", "promp-nominal-1demo"):  # the study's runs removed:
        shutil.rmtree(tmp_path / "with" / "p" / "dcp" / name)  # its table goes with them
    write_tables(tmp_path / "with", "p", tmp_path / "out_with")
    assert not (tmp_path / "out_with" / "one_demo_study_p.md").exists()
