"""The committed `paper` reference evaluations reproduce from this checkout, TC by TC.

The `demo` reference needs no trained model, so a clean machine can re-run it: the same
100 evaluation TCs, the same outcomes and the same clearances, returns and joint speeds as
the committed files (only the compute-time columns differ). The trained runs' models are
not committed; their config hashes are checked in `tests/agents/test_methods.py`.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from distgprl.data import TASK_NAMES
from distgprl.experiments.results import read_csv
from distgprl.experiments.runner import evaluate_run

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
