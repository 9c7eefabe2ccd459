"""The HAP build's progress bars (distgprl/safety/hap_build.py: tqdm_progress)."""

from __future__ import annotations

import io

from distgprl.safety.hap_build import tqdm_progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bars_per_stage_on_a_terminal():
    """One bar per stage, labelled with the stage, advanced to its total and then closed."""
    stream = Terminal()
    report = tqdm_progress(stream, leave=True, mininterval=0.0)
    for done in (1, 51, 100):
        report("ik", done, 100)
    report("expand", 1, 2)
    report("expand", 2, 2)
    text = stream.getvalue()
    assert "HAP ik" in text and "100/100" in text
    assert "HAP expand" in text and "2/2" in text


def test_default_bars_are_cleared_when_done():
    """By default a finished stage's bar is erased (the CLI prints its own summary line)."""
    stream = Terminal()
    report = tqdm_progress(stream)
    report("ik", 1, 2)
    report("ik", 2, 2)
    assert "HAP ik" in stream.getvalue()
    assert stream.getvalue().rstrip(" ").endswith("\r")


def test_progress_bars_stay_silent_off_a_terminal():
    """Piped or captured stderr gets no bar (tqdm's ``disable=None``)."""
    stream = io.StringIO()
    report = tqdm_progress(stream)
    report("ik", 1, 10)
    report("ik", 10, 10)
    assert stream.getvalue() == ""
