"""The tidy frames of a preset's runs: one row per run (its summary), per run × evaluation
episode and per run × curve point, of the runs that count only, with the files' own values."""

from __future__ import annotations

import math

from distgprl.report.frame import (
    EVALUATION_KEYS,
    RUN_COLUMNS,
    csv_frame,
    curve_frame,
    episode_frame,
    number,
    run_frame,
    summaries,
)
from distgprl.report.runs import current_hash
from distgprl.schema import write_csv, write_json

EPISODE = ("episode", "object_offset_x", "object_offset_y", "obstacle_offset_x")
EPISODE += ("obstacle_offset_y", "success", "collision", "min_clearance")


def _tree(root, study_run):
    """DCP: Dist-GPRL seeds 0 and 1 (seed 1's evaluation: three episodes, its summary with a
    count and a field seed 0 lacks), GPRL seed 0 of a stale configuration."""
    study_run(root, "paper", "dcp", "dist-gprl", 0, [0.1, 0.3, 0.5])
    study_run(root, "paper", "dcp", "dist-gprl", 1, [0.0, 0.2])
    folder = root / "paper" / "dcp" / "dist-gprl" / "seed1"
    config_hash = current_hash("dcp", "dist-gprl", 1, "paper")
    summary = {"success_rate": 0.1, "collision_rate": 0.3, "collision_free_episodes": 2}
    summary["min_clearance_p5_collision_free"] = None
    write_json(folder / "summary.json", {"summary": summary}, config_hash=config_hash)
    episodes = [
        {**dict.fromkeys(EPISODE, 0), "episode": k, "min_clearance": value}
        for k, value in enumerate(("0.1", "0.30000000000000004", ""))
    ]
    write_csv(folder / "evaluation.csv", episodes, EPISODE, config_hash=config_hash)
    study_run(root, "paper", "dcp", "gprl", 0, [0.0, 0.9])
    stale = root / "paper" / "dcp" / "gprl" / "seed0"
    for name in ("summary.json", "done.json"):
        write_json(stale / name, {"summary": summary, "steps": 1500}, config_hash="0" * 16)


def test_run_frame_has_one_row_per_run_that_counts_with_its_summarys_values(tmp_path, study_run):
    _tree(tmp_path, study_run)
    frame = run_frame(tmp_path, "paper", "final")
    assert list(frame.columns[:4]) == list(EVALUATION_KEYS)
    assert frame[["task", "method", "seed", "policy"]].values.tolist() == [
        ["dcp", "dist-gprl", 0, "final"],
        ["dcp", "dist-gprl", 1, "final"],
    ]
    one = frame.iloc[1]
    assert type(one["collision_free_episodes"]) is int and one["collision_free_episodes"] == 2
    assert one["min_clearance_p5_collision_free"] is None  # recorded as None: all collided
    assert frame.iloc[0]["collision_free_episodes"] is None  # not in seed 0's summary
    assert one["config_hash"] == current_hash("dcp", "dist-gprl", 1, "paper")
    assert "dcp/gprl/seed0 (configuration changed since" in frame.attrs["note"]


def test_summaries_give_each_run_its_summary_without_the_fields_it_lacks(tmp_path, study_run):
    _tree(tmp_path, study_run)
    (_, first), (key, second) = summaries(run_frame(tmp_path, "paper", "final"))
    assert key == ("dcp", "dist-gprl", 1, "final")
    assert second["collision_free_episodes"] == 2 and "collision_free_episodes" not in first
    assert "min_clearance_p5_collision_free" not in second


def test_the_best_policys_frame_falls_back_to_the_final_evaluation_and_says_so(tmp_path, study_run):
    """The fixture writes summary_best.json of the run's configuration: the best policy
    stands; a run without it is shown with its final policy and named in the note."""
    _tree(tmp_path, study_run)
    (tmp_path / "paper" / "dcp" / "dist-gprl" / "seed0" / "summary_best.json").unlink()
    frame = run_frame(tmp_path, "paper")
    assert frame["policy"].tolist() == ["final", "best"]
    assert "Final policy in place of the best (1" in frame.attrs["note"]


def test_episode_frame_has_one_row_per_run_and_episode_with_pythons_numbers(tmp_path, study_run):
    _tree(tmp_path, study_run)
    frame = episode_frame(tmp_path, "paper", "final")
    assert frame.groupby("seed").size().to_dict() == {0: 1, 1: 3}
    clearance = frame[frame["seed"] == 1]["min_clearance"].tolist()
    assert clearance[:2] == [0.1, 0.30000000000000004] and math.isnan(clearance[2])
    assert frame["episode"].dtype.kind == "i"


def test_curve_frame_has_one_row_per_finished_run_and_curve_point(tmp_path, study_run):
    _tree(tmp_path, study_run)
    (tmp_path / "paper" / "dcp" / "dist-gprl" / "seed0" / "done.json").unlink()  # unfinished
    frame = curve_frame(tmp_path, "paper")
    assert frame[["seed", "step", "success_rate"]].values.tolist() == [[1, 0, 0.0], [1, 1500, 0.2]]
    assert frame["step"].dtype.kind == "i"
    assert "dcp/gprl/seed0" in frame.attrs["note"]


def test_an_empty_preset_gives_empty_frames_with_the_key_columns(tmp_path):
    (tmp_path / "paper" / "dcp").mkdir(parents=True)
    assert list(run_frame(tmp_path, "paper").columns) == list(RUN_COLUMNS)
    assert list(episode_frame(tmp_path, "paper").columns) == list(EVALUATION_KEYS)
    assert list(curve_frame(tmp_path, "paper").columns) == ["task", "method", "seed"]


def test_a_cell_is_pythons_int_or_float_or_stays_text():
    assert type(number("3")) is int and number("0.1") == 0.1 and number("1e-05") == 1e-05
    assert math.isnan(number("")) and math.isnan(number("nan"))
    assert number("refused") == "refused"


def test_a_result_csv_without_rows_still_has_its_key_columns(tmp_path):
    path = write_csv(tmp_path / "evaluation.csv", [], EPISODE, config_hash="0" * 16)
    frame = csv_frame(path, {"task": "dcp", "seed": 3})
    assert list(frame.columns) == ["task", "seed"] and frame.empty
    assert frame["seed"].nunique() == 0
