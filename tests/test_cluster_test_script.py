"""``scripts/cluster_test.py``'s verdicts on a lost worker run (phases 1 and 2), from what
it saw.

The cluster test itself (``make test-cluster``) needs Ray nodes and runs in CI after the
suite; these check the classification it applies, on both outcomes a lost (killed or
frozen) worker node can have: its process ended before Ray's retry took the run's lock (the
run is resumed), or the lost process finished the run first (no retry trains it; the sweep
says ``skipped`` or ``done``).
"""

from __future__ import annotations

import time
from pathlib import Path

from _scripts import load_script

cluster_test = load_script("cluster_test")

RUN = Path("/tmp/x/results/ci/dcp/gprl-d/seed2")


def test_a_retry_after_the_lost_process_is_gone_keeps_one_writer():
    state = {"folder": RUN, "gone": 16.4, "retry": 16.7, "collision": False}
    finished, ok, detail = cluster_test.lost_outcome(state)
    assert (finished, ok) == (False, True)
    assert "retry took the lock 16.7 s" in detail


def test_a_retry_while_the_lost_process_holds_the_lock_fails():
    assert not cluster_test.lost_outcome({"gone": 17.0, "retry": 16.7, "collision": True})[1]
    assert not cluster_test.lost_outcome({"gone": 17.0, "retry": 16.7, "collision": False})[1]
    assert not cluster_test.lost_outcome({"retry": 16.7, "collision": False})[1]


def test_a_run_the_lost_process_finished_counts_as_finished_by_it():
    for state in (
        {"finished": 15.0, "gone": 16.0},
        {"finished": 15.0, "gone": 16.0, "retry": 16.5, "collision": False},
    ):
        finished, ok, detail = cluster_test.lost_outcome(state)
        assert (finished, ok) == (True, True)
        assert "finished the run 15.0 s" in detail
    # its process must still end
    assert cluster_test.lost_outcome({"finished": 15.0})[1] is False


def test_watching_sees_a_run_finished_while_no_retry_holds_it(tmp_path):
    """Phase 1's race on a loaded machine (CI): the killed node's process writes done.json
    before it ends; with no head process holding the lock, that is its own finish."""
    folder = tmp_path / "dcp" / "gprl-h" / "seed0"
    folder.mkdir(parents=True)
    dead_pid = 2**22 + 1  # above pid_max's default: no such process
    state = {"folder": folder, "jobs": [dead_pid], "at": time.monotonic()}
    cluster_test.watch_lost_run(state, head_jobs=[])
    assert "gone" in state and "finished" not in state and "retry" not in state
    (folder / "done.json").write_text("{}")
    cluster_test.watch_lost_run(state, head_jobs=[])
    assert "finished" in state
    assert cluster_test.lost_outcome(state)[:2] == (True, True)


def test_the_sweep_line_must_match_the_outcome():
    name = "dcp/gprl-d/seed2"
    resumed = f"[3/3] {name}: done in 3 s (resumed from its checkpoint of step 120)\n"
    fresh = f"[3/3] {name}: done in 1 s\n"
    skipped = f"[3/3] {name}: skipped in 0 s\n"
    other = "[2/3] dcp/gprl-h/seed2: done in 3 s (resumed from its checkpoint of step 120)\n"
    assert cluster_test.lost_run_reported(resumed, name, finished_by_lost=False)
    assert not cluster_test.lost_run_reported(fresh, name, finished_by_lost=False)
    assert not cluster_test.lost_run_reported(other + fresh, name, finished_by_lost=False)
    assert cluster_test.lost_run_reported(fresh, name, finished_by_lost=True)
    assert cluster_test.lost_run_reported(skipped, name, finished_by_lost=True)
    assert not cluster_test.lost_run_reported(other, name, finished_by_lost=True)
