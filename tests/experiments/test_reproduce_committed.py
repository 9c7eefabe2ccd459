"""Committed `paper` results reproduce from this checkout on a clean machine.

- The `demo` reference needs no trained model: the same 100 evaluation TCs give the same
  outcomes, clearances, returns and joint speeds as the committed files (only the
  compute-time columns differ).
- Trained models are not committed, and a full run takes an hour; the full method's seed-0
  run is retrained for its first learning-curve interval and must meet its committed curve
  there. Every committed run's config hash is checked in `tests/agents/test_methods.py`.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from distgprl.data import TASK_NAMES
from distgprl.experiments.results import read_csv
from distgprl.experiments.runner import evaluate_run, train_run

PAPER_RESULTS = Path(__file__).resolve().parents[2] / "results" / "paper"
TIMING_COLUMNS = {"adaptation_ms_w1", "adaptation_ms_w2", "adaptation_ms_w3", "policy_ms"}
EXACT_COLUMNS = {"episode", "success", "collision"}


@pytest.mark.parametrize("task", TASK_NAMES)
def test_committed_demo_evaluation_reproduces_tc_by_tc(task, tmp_path):
    committed = PAPER_RESULTS / task / "demo" / "seed0" / "evaluation.csv"
    assert committed.exists(), f"{committed}: the committed reference evaluation is missing"
    meta, expected = read_csv(committed)
    evaluate_run(task, "demo", 0, "paper", root=tmp_path, show_progress=False)
    new_meta, rows = read_csv(tmp_path / "paper" / task / "demo" / "seed0" / "evaluation.csv")
    assert new_meta["config_hash"] == meta["config_hash"]
    assert len(rows) == len(expected) == 100
    assert rows[0].keys() == expected[0].keys()
    for row, old in zip(rows, expected, strict=True):
        for column in row.keys() - TIMING_COLUMNS:
            if column in EXACT_COLUMNS:
                assert row[column] == old[column], (row["episode"], column)
            else:
                assert float(row[column]) == pytest.approx(float(old[column]), rel=1e-9), (
                    row["episode"],
                    column,
                )


@pytest.mark.parametrize("task", TASK_NAMES)
def test_committed_dist_gprl_run_reproduces_its_first_curve_point(task, tmp_path, monkeypatch):
    """Seed 0 of the full method, retrained for its first learning-curve interval (1 500
    steps: 1 000 of warm-up, 500 gradient steps) from this checkout, matches the committed
    run's curve there to 1e-9: success, collision, return, clearance, L_sim, L_hap and the
    entropy coefficient — the same code path and numbers the committed run was trained with
    (the HAP subspace built afresh when the cache is empty)."""
    committed = PAPER_RESULTS / task / "dist-gprl" / "seed0" / "progress.csv"
    assert committed.exists(), f"{committed}: the committed run is missing"
    _, expected = read_csv(committed)
    steps = int(expected[1]["step"])
    monkeypatch.setenv("DISTGPRL_CHECKPOINT_ROOT", "")
    train_run(
        task,
        "dist-gprl",
        0,
        "paper",
        steps,
        root=tmp_path,
        show_progress=False,
        evaluate_after=False,
    )
    _, rows = read_csv(tmp_path / "paper" / task / "dist-gprl" / "seed0" / "progress.csv")
    assert [r["step"] for r in rows] == ["0", str(steps)]
    for row, old in zip(rows, expected[:2], strict=True):
        for column in row.keys() - {"wall_time_s"}:
            if old[column] == "":
                assert row[column] == "", (row["step"], column)
            else:
                assert float(row[column]) == pytest.approx(float(old[column]), rel=1e-9), (
                    row["step"],
                    column,
                )
