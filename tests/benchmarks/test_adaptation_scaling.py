"""``benchmarks/adaptation_scaling.py`` at its tiny size: one row per via-point count and per
obstacle count, every timing positive and finite. No timing thresholds."""

from __future__ import annotations

import math

from _scripts import load_script


def test_a_tiny_study_measures_every_point_of_both_curves():
    study = load_script("adaptation_scaling", "benchmarks")
    document = study.run_study("tiny")
    sizes = study.SIZES["tiny"]
    via_points = document["via_points"]
    assert [row["n_via_points"] for row in via_points] == list(sizes["via_points"])
    for row in via_points:
        assert row["window_size"] == row["n_via_points"] // 3
        assert row["action_size"] == 6 * row["window_size"]  # 6-D poses of the window
    obstacles = document["obstacles"]
    assert [row["n_obstacles"] for row in obstacles] == list(sizes["obstacles"])
    for row in [*via_points, *obstacles]:
        for key, timing in row.items():
            if isinstance(timing, dict):
                assert math.isfinite(timing["median_us"]) and timing["median_us"] > 0, key
    assert all(row["edf_vs_pybullet"] > 0 for row in obstacles)
    assert "boxes" in study.describe(document)


def test_random_boxes_are_seeded():
    study = load_script("adaptation_scaling", "benchmarks")
    first, again = study.random_boxes(3, seed=1), study.random_boxes(3, seed=1)
    assert [box.position.tolist() for box in first] == [box.position.tolist() for box in again]
