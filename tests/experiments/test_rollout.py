"""`distgprl.experiments.rollout.evaluate_policy`'s progress bar is drawn on a terminal only:
a log file (stderr not a terminal) gets no bar redraws."""

from __future__ import annotations

import io
import sys

from distgprl.experiments import rollout


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_evaluation_bar_is_drawn_on_a_terminal_only(monkeypatch):
    monkeypatch.setattr(rollout, "run_episode", lambda env, tc, policy: {"success": 1})
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    rows = rollout.evaluate_policy(None, [0, 1, 2], progress=True)
    assert [row["episode"] for row in rows] == [0, 1, 2]
    assert log.getvalue() == ""
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    rollout.evaluate_policy(None, [0, 1, 2], progress=True)
    assert "evaluate" in terminal.getvalue()
