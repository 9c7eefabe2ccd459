"""Table I + repair (`distgprl.report.repair`) from synthetic run folders: rates are means
over seeds of the per-run rates, the TC-by-TC counts compare each TC's plain outcome with
its repair outcome, and evaluations of another configuration or other TCs are left out."""

from __future__ import annotations

from distgprl.report.repair import repair_table, repair_texts
from distgprl.schema import (
    EVALUATION_FIELDS,
    REPAIR_EVALUATION_FIELDS,
    repair_evaluation_file_names,
    run_dir,
    write_csv,
    write_json,
)

PRESET = "synthetic"  # not a shipped preset: select_runs does not resolve its hashes


def _rows(fields, outcomes, refused=False):
    rows = []
    for index, outcome in enumerate(outcomes):
        row = dict.fromkeys(fields, "0")
        row.update(episode=str(index), object_offset_x=str(0.01 * index))
        row["success"], row["collision"] = str(int(outcome == "s")), str(int(outcome == "c"))
        if refused:
            row["refused"] = str(int(outcome == "r"))
        rows.append(row)
    return rows


def _run(root, seed, plain, check, repair, retimed=0, config_hash="h", method="dist-gprl"):
    folder = run_dir(root, PRESET, "dbm", method, seed)
    folder.mkdir(parents=True)
    write_json(folder / "config.json", {"config_hash": "h"}, config_hash="h")
    write_json(folder / "summary.json", {"summary": {}}, config_hash="h")
    write_csv(folder / "evaluation.csv", _rows(EVALUATION_FIELDS, plain), EVALUATION_FIELDS)
    for mode, outcomes in (("check", check), ("repair", repair)):
        csv_name, summary_name = repair_evaluation_file_names(None, "final", mode)
        rows = _rows(REPAIR_EVALUATION_FIELDS, outcomes, refused=True)
        write_csv(folder / csv_name, rows, REPAIR_EVALUATION_FIELDS, config_hash=config_hash)
        refused = outcomes.count("r")
        summary = {
            "windows_none": 3 * len(outcomes) - retimed - refused,
            "windows_retimed": retimed,
            "windows_refused": refused,
            "mean_time_added_s": 0.1 * retimed,
        }
        write_json(folder / summary_name, {"summary": summary}, config_hash=config_hash)
    return folder


def test_rates_are_seed_means_and_tc_counts_are_summed_over_seeds(tmp_path):
    # s success, c collision, f failure, r refused
    _run(tmp_path, 0, "sscf", "ssrf", "ssrf", retimed=0)
    _run(tmp_path, 1, "scff", "srff", "ssff", retimed=2)
    (row,), excluded = repair_table(tmp_path, PRESET)
    assert excluded == []
    assert (row["seeds"], row["n_seeds"], row["episodes"]) == ("0 1", 2, 8)
    assert row["plain_success"] == (0.5 + 0.25) / 2 and row["plain_collision"] == 0.25
    assert row["check_refused"] == 0.25 and row["check_collision"] == 0.0
    assert row["repair_success"] == 0.5 and row["repair_refused"] == 0.125
    assert row["repair_retimed_windows"] == 2 / 24 and row["repair_time_added_s"] == 0.1
    # seed 1's TC 1 collided plain and succeeds repaired; seed 0's TC 2 collided, refused
    assert (row["gained"], row["lost"], row["averted"]) == (1, 0, 2)
    csv_text, markdown = repair_texts(tmp_path, PRESET)
    assert csv_text.splitlines()[0].startswith("task,method,seeds,n_seeds")
    assert "| DBM | Dist-GPRL (ours) | 0 1 | 0.38 / 0.25 |" in markdown


def test_an_evaluation_of_another_configuration_or_other_tcs_is_left_out(tmp_path):
    _run(tmp_path, 0, "ss", "ss", "ss", config_hash="old")
    folder = _run(tmp_path, 1, "ss", "ss", "ss")
    rows = _rows(EVALUATION_FIELDS, "sss")  # a third TC the repaired runs lack
    write_csv(folder / "evaluation.csv", rows, EVALUATION_FIELDS)
    rows, excluded = repair_table(tmp_path, PRESET)
    assert rows == []
    assert excluded[0].startswith("dbm/dist-gprl/seed0 (check evaluation of config hash old")
    assert excluded[1] == "dbm/dist-gprl/seed1 (check evaluation on other TCs than the plain one)"
    assert repair_texts(tmp_path, PRESET) is None


def test_a_run_without_both_modes_is_not_a_row(tmp_path):
    folder = _run(tmp_path, 0, "ss", "ss", "ss")
    (folder / repair_evaluation_file_names(None, "final", "check")[1]).unlink()
    assert repair_table(tmp_path, PRESET) == ([], [])
