"""`distgprl.experiments.evaluation`'s terminal forms of a summary: a small table of the
headline figures (rates in percent, clearance in mm, absent figures left out) and the whole
summary as one JSON line."""

from __future__ import annotations

import json

from distgprl.experiments.evaluation import describe, summary_table

SUMMARY = {
    "episodes": 100,
    "success_rate": 0.29,
    "collision_rate": 0.4,
    "safe_success_rate": 0.29,
    "min_clearance_p5": 0.0012,
    "mean_return": 4.475486151064361,
    "evaluation_wall_time_s": 2.87,
}


def test_the_table_shows_the_headline_figures_in_reading_units():
    lines = summary_table(SUMMARY, "evaluation of dcp/gprl/seed0:").splitlines()
    assert lines[0] == "evaluation of dcp/gprl/seed0:"
    rows = {line.split("  ")[1].strip(): line.split()[-2:] for line in lines[1:]}
    assert rows["episodes"] == ["episodes", "100"]
    assert rows["success"] == ["29", "%"] and rows["collision"] == ["40", "%"]
    assert lines[-2].endswith("1.2 mm") and lines[-1].endswith("4.48")
    assert len(lines) == 1 + 6  # completion, refusals, wall time: not in it
    assert len({len(line) for line in lines[1:]}) == 1  # one column of values


def test_the_json_line_holds_every_figure():
    assert json.loads(describe(SUMMARY)) == {**SUMMARY, "mean_return": 4.4755}
