"""`distgprl.hardware.trial_rows`: a trial that never moved the robot is a failure with
infinite clearance; the bookkeeping columns are the trial's timings and worst perception
error; the operator is asked again until the answer is yes or no."""

from __future__ import annotations

import time

import numpy as np

from distgprl.hardware.trial_rows import ask_yes_no, finish_row
from distgprl.schema import TRIAL_FIELDS


def empty_row() -> dict:
    return dict.fromkeys(TRIAL_FIELDS, "")


def test_a_trial_stopped_before_moving_is_a_failure_with_infinite_clearance():
    timings = {"perception": [], "policy": 0.0, "check": 0.0, "execution": 0.0}
    row = finish_row(empty_row(), time.perf_counter(), timings, [], np.inf, judge_skip=True)
    assert row["success"] == 0 and row["collision"] == 0
    assert row["min_clearance"] == np.inf and row["planned_min_clearance"] == np.inf
    assert row["perception_error_mm"] == "" and row["perception_ms"] == ""


def test_the_bookkeeping_columns_are_the_trials_timings_and_worst_errors():
    timings = {"perception": [2.0, 4.0], "policy": 0.0015, "check": 0.25, "execution": 3.5}
    errors = [(0.002, 0.5), (0.004, 0.25)]  # (m, deg) per perceived pose
    row = finish_row(empty_row(), time.perf_counter(), timings, errors, 0.031)
    assert row["success"] == ""  # judged elsewhere: finish_row leaves it alone
    assert row["planned_min_clearance"] == 0.031
    assert row["perception_error_mm"] == 4.0 and row["perception_error_deg"] == 0.5
    assert row["perception_ms"] == 3.0
    assert (row["policy_ms"], row["check_ms"], row["execution_s"]) == (1.5, 250.0, 3.5)
    assert 0.0 <= row["trial_s"] < 60.0


def test_the_operator_is_asked_until_the_answer_is_yes_or_no():
    answers = iter(["maybe", "", " Yes ", "n"])
    asked = []

    def ask(prompt: str) -> str:
        asked.append(prompt)
        return next(answers)

    assert ask_yes_no(ask, "lifted?") == 1
    assert asked == ["lifted? [y/n] "] * 3
    assert ask_yes_no(ask, "touched?") == 0
