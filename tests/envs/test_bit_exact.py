"""The environments' numerics are those of the code the committed runs were made with.

``data/env_trace_v<ENVIRONMENT_VERSION>*.npz`` hold paper-preset episodes of dist-gprl,
promp-rrl, gprl and demo on both tasks with fixed seeds and fixed pseudo-random actions
(`_env_trace.record_trace`), recorded with the code the runs of that environment version are
made with, one file per CPU numerics (`_env_trace` module docstring).

What each test expects, and where:

- **On a machine with the numerics of a recording** (same OpenBLAS kernels and numpy SIMD
  targets, `distgprl.machine.numerics_fingerprint`): every observation, reward, info value and
  simulator state bit for bit. On a machine whose numerics no trace was recorded with, this
  test is skipped, saying so and how to record one; the next holds there.
- **On any x86-64 machine**, against every recording: the same episodes — keys, dtypes and
  shapes (every episode the same number of steps), the terminated flags, and every step's
  success and collision outcome. Floats are not compared: between CPU families the BLAS
  kernels differ in the last bits and contact physics amplifies that (measured between two
  machines: up to O(1) relative in the object pose after a DCP contact, ≤ 1e-7 before it),
  the same caveat as the committed-run reproduction tests, which also compare outcomes.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from _env_trace import (
    DATA,
    FINGERPRINT_KEY,
    TRACE_RUNS,
    numerics_fingerprint,
    record_trace,
    trace_fingerprint,
)

from distgprl.config_types import ENVIRONMENT_VERSION

TRACES = sorted(DATA.glob(f"env_trace_v{ENVIRONMENT_VERSION}*.npz"))
OUTCOMES = ("terminated", "info/success", "info/collision")


@cache
def _recorded(task: str, method: str, episodes: int) -> dict[str, np.ndarray]:
    return record_trace(task, method, episodes)


def _keys(reference, task: str, method: str) -> list[str]:
    return sorted(k for k in reference.files if k.startswith(f"{task}/{method}/"))


def test_the_trace_files_are_of_distinct_machines():
    fingerprints = [trace_fingerprint(path) for path in TRACES]
    assert TRACES and len(set(fingerprints)) == len(fingerprints)
    for path, fingerprint in zip(TRACES, fingerprints, strict=True):
        if fingerprint is not None:  # the file name says which machine it is of
            assert path.name == f"env_trace_v{ENVIRONMENT_VERSION}_{fingerprint}.npz"


@pytest.mark.parametrize(("task", "method", "episodes"), TRACE_RUNS)
def test_episodes_reproduce_this_machines_trace_bit_for_bit(task, method, episodes):
    fingerprint = numerics_fingerprint()
    own = [path for path in TRACES if trace_fingerprint(path) == fingerprint]
    if not own:
        pytest.skip(
            f"no trace recorded with this machine's numerics ({fingerprint}); record one "
            "with code that passes on a recorded machine: python tests/envs/_env_trace.py"
        )
    with np.load(own[0]) as reference:
        trace = _recorded(task, method, episodes)
        expected = _keys(reference, task, method)
        assert sorted(trace) == expected
        for key in expected:
            assert trace[key].dtype == reference[key].dtype, key
            equal_nan = trace[key].dtype.kind == "f"
            assert np.array_equal(trace[key], reference[key], equal_nan=equal_nan), key


@pytest.mark.parametrize("trace_file", TRACES, ids=lambda path: path.stem)
@pytest.mark.parametrize(("task", "method", "episodes"), TRACE_RUNS)
def test_episodes_have_every_recordings_steps_and_outcomes(task, method, episodes, trace_file):
    with np.load(trace_file) as reference:
        trace = _recorded(task, method, episodes)
        expected = _keys(reference, task, method)
        assert sorted(trace) == expected and FINGERPRINT_KEY not in trace
        for key in expected:
            assert trace[key].dtype == reference[key].dtype, key
            assert trace[key].shape == reference[key].shape, key
        for name in OUTCOMES:
            key = f"{task}/{method}/{name}"
            assert np.array_equal(trace[key], reference[key], equal_nan=True), key
