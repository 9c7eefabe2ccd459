"""Minimum-jerk key-pose profiles: how the scripted experts join their key poses.

Shared by :mod:`distgprl.sim.experts` and the experts that live with their task module
(:func:`distgprl.sim.tasks.dbm.dbm_expert`), so neither imports the other. Numerics only.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SAMPLE_RATE", "minimum_jerk"]

SAMPLE_RATE = 100.0
"""Samples per second of the written demonstrations."""


def minimum_jerk(
    key_times: np.ndarray, key_poses: np.ndarray, rate: float = SAMPLE_RATE
) -> tuple[np.ndarray, np.ndarray]:
    """Minimum-jerk interpolation through key poses, each reached at rest.

    Args:
        key_times: (k,) s, strictly increasing, starting at 0.
        key_poses: (k, 6) TCP poses (m, rad).
        rate: samples per second.
    Returns:
        times (n,) s and poses (n, 6), sampled at ``rate`` from 0 to ``key_times[-1]``.
    """
    key_times = np.asarray(key_times, dtype=float)
    key_poses = np.asarray(key_poses, dtype=float)
    count = int(round(key_times[-1] * rate)) + 1
    times = np.arange(count) / rate
    segment = np.clip(np.searchsorted(key_times, times, side="right") - 1, 0, len(key_times) - 2)
    start, end = key_times[segment], key_times[segment + 1]
    x = np.clip((times - start) / (end - start), 0.0, 1.0)
    blend = x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)
    poses = key_poses[segment] + blend[:, None] * (key_poses[segment + 1] - key_poses[segment])
    return np.round(times, 6), poses
