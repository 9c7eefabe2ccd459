"""The environments' numerics are those of the code the committed runs were made with.

``data/env_trace_v5.npz`` was recorded by `_env_trace.record_all` before the issue 28/29
simulation refactor (Robot protocol, control-loop module, batched PyBullet calls), on this
machine's CPU family: paper-preset episodes of dist-gprl, promp-rrl, gprl and demo on both
tasks with fixed seeds and fixed pseudo-random actions. Property checked: a re-recording
gives every observation, reward, info value and simulator state bit for bit (booleans
exactly). On a CPU of another family, contact physics may amplify ulp differences of the
BLAS kernels, and the comparison can fail there without a change of the code (the same
caveat as the committed-run reproduction tests).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _env_trace import TRACE_RUNS, record_trace

REFERENCE = Path(__file__).parent / "data" / "env_trace_v5.npz"


@pytest.mark.parametrize(("task", "method", "episodes"), TRACE_RUNS)
def test_episodes_reproduce_the_reference_trace_bit_for_bit(task, method, episodes):
    reference = np.load(REFERENCE)
    trace = record_trace(task, method, episodes)
    expected = sorted(k for k in reference.files if k.startswith(f"{task}/{method}/"))
    assert sorted(trace) == expected
    for key in expected:
        assert trace[key].dtype == reference[key].dtype, key
        assert np.array_equal(trace[key], reference[key], equal_nan=trace[key].dtype.kind == "f"), (
            key
        )
