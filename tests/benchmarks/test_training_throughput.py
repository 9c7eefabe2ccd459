"""``benchmarks/training_throughput.py`` at its tiny size: the breakdown of a training step adds
up to its wall time, and every worker count is measured by that many worker processes (this
file's ``--worker`` entry), so the speed-up is like for like. No timing thresholds."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from _scripts import REPOSITORY, load_script


def test_a_tiny_study_measures_the_breakdown_and_the_workers():
    study = load_script("training_throughput", "benchmarks")
    document = study.run_study("tiny")
    training = document["training"]
    assert training["steps"] == study.SIZES["tiny"]["steps"]
    assert math.isfinite(training["steps_per_s"]) and training["steps_per_s"] > 0
    breakdown = training["breakdown"]
    assert sum(part["fraction"] for part in breakdown.values()) == pytest.approx(1.0)
    assert training["calls_per_step"]["sac_update"] > 0
    rows = document["workers"]
    assert [row["workers"] for row in rows] == list(study.SIZES["tiny"]["workers"])
    for row in rows:
        assert len(row["steps_per_s_each"]) == row["workers"]
        assert row["aggregate_steps_per_s"] == pytest.approx(sum(row["steps_per_s_each"]))
        assert all(rate > 0 for rate in row["steps_per_s_each"])
    assert rows[0]["speedup_vs_one"] == 1.0
    text = study.describe(document)
    assert "steps/s" in text and "worker process(es)" in text


def test_the_script_runs_from_the_repository_with_its_worker_entry():
    result = subprocess.run(
        [sys.executable, str(REPOSITORY / "benchmarks" / "training_throughput.py"), "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert "--worker TASK LEARNING_STARTS STEPS" in result.stdout
    assert "--size {full,quick,tiny}" in result.stdout
