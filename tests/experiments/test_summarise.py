"""`distgprl.experiments.rollout.summarise`: the Table I numbers of one run from its
per-episode rows, checked against expectations computed here by hand (no numpy
statistics), on rows as `evaluate_policy` returns them and as the CSV gives them back."""

from __future__ import annotations

import math

import pytest

from distgprl.experiments.rollout import summarise
from distgprl.limits import SafetyLimits
from distgprl.schema import EVALUATION_FIELDS

# success, collision, min_clearance (m), return, kinematic retention, w1, w2, w3, policy (ms),
# peak joint speed (rad/s)
EPISODES = [
    (1, 0, 0.031, 12.0, 0.90, 1.0, 2.0, 3.0, 0.5, 1.2),
    (1, 1, -0.004, 4.0, 0.80, 1.5, 2.5, float("nan"), 0.5, 2.4),
    (0, 0, 0.012, -3.0, 0.70, 1.0, 1.0, 1.0, 0.2, 0.9),
    (0, 1, -0.020, -9.0, 0.60, 2.0, 2.0, 2.0, 0.3, 2.1),
    (1, 0, 0.025, 11.0, 0.95, 1.0, 1.0, 1.0, 0.4, 1.8),
    (1, 0, 0.008, 10.0, 0.85, 3.0, 3.0, 3.0, 0.6, 1.1),
    (0, 0, 0.040, 1.0, 0.75, 0.5, 0.5, 0.5, 0.1, 0.8),
    (1, 1, 0.001, 5.0, 0.65, 1.0, 1.0, 1.0, 0.2, 3.0),
    (1, 0, 0.017, 9.0, 0.88, 1.0, 2.0, 1.0, 0.3, 1.5),
    (0, 0, 0.022, 0.0, 0.92, 2.0, 1.0, 1.0, 0.7, 1.9),
]
COLUMNS = (
    "success",
    "collision",
    "min_clearance",
    "return",
    "kinematic_retention",
    "adaptation_ms_w1",
    "adaptation_ms_w2",
    "adaptation_ms_w3",
    "policy_ms",
    "peak_joint_speed",
)


def rows(as_text: bool = False) -> list[dict]:
    out = []
    for index, values in enumerate(EPISODES):
        row = dict.fromkeys(EVALUATION_FIELDS, 0.0)
        row["episode"] = index
        row.update(zip(COLUMNS, values, strict=True))
        # environment v5 rows: min_clearance is a distance (>= 0), the signed value beside it
        row["min_signed_clearance"] = row["min_clearance"]
        row["min_clearance"] = max(row["min_clearance"], 0.0)
        row["completed"] = row["success"]
        out.append({k: str(v) for k, v in row.items()} if as_text else row)
    return out


def percentile_by_hand(values: list[float], q: float) -> float:
    """Linear interpolation between order statistics (numpy's default method), written out."""
    ordered = sorted(values)
    position = q / 100 * (len(ordered) - 1)
    low = math.floor(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (position - low) * (ordered[high] - ordered[low])


def median_by_hand(values: list[float]) -> float:
    ordered, n = sorted(values), len(values)
    return ordered[n // 2] if n % 2 else (ordered[n // 2 - 1] + ordered[n // 2]) / 2


@pytest.mark.parametrize("as_text", [False, True], ids=["numbers", "csv-strings"])
def test_summarise_gives_rates_mincl_means_and_safe_success_of_the_episodes(as_text):
    """success / collision rate = share of episodes; safe success = share with success and
    no collision; MinCl = 5th percentile (linear interpolation) of the episodes' minimum
    clearance clamped at 0, and the same of the signed clearance; completion rate; means of
    clearance, return and kinematic retention; medians of adaptation time (three windows, a
    missing window skipped, plus policy time) and policy time; the 95th percentile of the peak
    joint speed and the share above the 2 rad/s safety limit."""
    summary = summarise(rows(as_text))
    success = [e[0] for e in EPISODES]
    collision = [e[1] for e in EPISODES]
    clearance = [e[2] for e in EPISODES]
    assert summary["episodes"] == 10
    assert summary["success_rate"] == pytest.approx(6 / 10)
    assert summary["collision_rate"] == pytest.approx(3 / 10)
    assert sum(success) == 6 and sum(collision) == 3
    # successes without collision: episodes 0, 4, 5, 8 (1 and 7 collided)
    assert summary["safe_success_rate"] == pytest.approx(4 / 10)
    # sorted signed clearances: -0.020, -0.004, 0.001, ...; position 0.05 * 9 = 0.45
    expected_signed_p5 = -0.020 + 0.45 * (-0.004 - -0.020)
    assert percentile_by_hand(clearance, 5) == pytest.approx(expected_signed_p5)
    assert summary["min_signed_clearance_p5"] == pytest.approx(expected_signed_p5)  # -0.0128
    # MinCl (v5) is the 5th percentile of the distance, clamped at 0: 0, 0, 0.001, ...
    distance = [max(c, 0.0) for c in clearance]
    assert summary["min_clearance_p5"] == pytest.approx(percentile_by_hand(distance, 5)) == 0.0
    assert summary["mean_min_clearance"] == pytest.approx(sum(distance) / 10)
    assert summary["completion_rate"] == pytest.approx(6 / 10)
    assert summary["mean_return"] == pytest.approx(sum(e[3] for e in EPISODES) / 10)  # 4.0
    assert summary["mean_kinematic_retention"] == pytest.approx(sum(e[4] for e in EPISODES) / 10)
    per_episode = [
        sum(w for w in e[5:8] if not math.isnan(w)) + e[8]  # ms per episode
        for e in EPISODES
    ]
    assert summary["median_adaptation_ms_per_episode"] == pytest.approx(median_by_hand(per_episode))
    assert summary["median_policy_ms_per_episode"] == pytest.approx(
        median_by_hand([e[8] for e in EPISODES])
    )
    peak = [e[9] for e in EPISODES]
    assert summary["peak_joint_speed_p95"] == pytest.approx(percentile_by_hand(peak, 95))
    assert SafetyLimits().max_joint_speed == 2.0
    assert summary["joint_speed_over_limit_rate"] == pytest.approx(3 / 10)  # 2.4, 2.1, 3.0


def test_summarise_leaves_out_joint_speed_when_episodes_do_not_record_it():
    episodes = rows()
    episodes[3]["peak_joint_speed"] = ""  # written before the column existed
    summary = summarise(episodes)
    assert "peak_joint_speed_p95" not in summary
    assert "joint_speed_over_limit_rate" not in summary
    assert summary["success_rate"] == pytest.approx(0.6)


def test_summarise_of_a_single_episode_is_that_episode():
    """One episode: every rate is 0 or 1 and MinCl is its own minimum clearance."""
    summary = summarise(rows()[1:2])  # success with collision
    assert (summary["success_rate"], summary["collision_rate"]) == (1.0, 1.0)
    assert summary["safe_success_rate"] == 0.0
    assert summary["min_clearance_p5"] == 0.0  # a distance (v5)
    assert summary["min_signed_clearance_p5"] == pytest.approx(-0.004)


def test_summarise_refuses_an_empty_evaluation():
    with pytest.raises(ValueError, match="no episodes"):
        summarise([])


@pytest.mark.parametrize("as_text", [False, True], ids=["numbers", "csv-strings"])
def test_mincl_is_over_the_collision_free_episodes_and_differs_where_5_percent_collide(as_text):
    """Environment v6's MinCl (FINDINGS "Protocol v6", rule 5): the 5th percentile of the
    episode-wise minimum clearance over the episodes without a collision, with their count.
    Here 3 of 10 collide (>= 5 %): MinCl over all episodes is 0 (v5's, kept beside it
    unchanged), over the collision-free ones it is positive."""
    summary = summarise(rows(as_text))
    free = [e[2] for e in EPISODES if e[1] == 0]  # 0.031, 0.012, 0.025, 0.008, 0.040, ...
    assert summary["collision_free_episodes"] == len(free) == 7
    # sorted: 0.008, 0.012, ...; position 0.05 * 6 = 0.3
    expected = 0.008 + 0.3 * (0.012 - 0.008)
    assert percentile_by_hand(free, 5) == pytest.approx(expected)
    assert summary["min_clearance_p5_collision_free"] == pytest.approx(expected)  # 0.0092
    assert summary["min_clearance_p5"] == 0.0 < summary["min_clearance_p5_collision_free"]


def test_mincl_of_an_evaluation_where_every_episode_collided_is_undefined_not_zero():
    """No collision-free episode: MinCl is None (JSON null) with a count of 0, the reason
    the tables state; the all-episode MinCl stays 0. No collision at all: both agree."""
    colliding = [r for r in rows() if int(r["collision"]) == 1]
    summary = summarise(colliding)
    assert summary["min_clearance_p5_collision_free"] is None
    assert summary["collision_free_episodes"] == 0
    assert summary["min_clearance_p5"] == 0.0
    clean = [r for r in rows() if int(r["collision"]) == 0]
    summary = summarise(clean)
    assert summary["collision_free_episodes"] == len(clean)
    assert summary["min_clearance_p5_collision_free"] == pytest.approx(summary["min_clearance_p5"])


def test_summarise_keeps_every_v5_field_and_adds_only_the_collision_free_mincl():
    """The v6 MinCl is an added field: every field of a v5 summary is still there with its
    meaning (MinCl over all episodes under its old name ``min_clearance_p5``: 0 here)."""
    v5_fields = {
        "episodes", "success_rate", "collision_rate", "safe_success_rate", "min_clearance_p5",
        "mean_min_clearance", "mean_return", "mean_kinematic_retention",
        "median_adaptation_ms_per_episode", "median_policy_ms_per_episode", "completion_rate",
        "min_signed_clearance_p5", "peak_joint_speed_p95", "joint_speed_over_limit_rate",
    }  # fmt: skip
    summary = summarise(rows())
    assert v5_fields | {"min_clearance_p5_collision_free", "collision_free_episodes"} <= set(
        summary
    )
    assert summary["min_clearance_p5"] == 0.0
