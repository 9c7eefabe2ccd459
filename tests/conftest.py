"""Shared fixtures: small, fast, deterministic."""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

from distgprl.skill.demos import Demonstration, save_demonstration  # noqa: E402


def smooth_demo_poses(times: np.ndarray) -> np.ndarray:
    """A smooth synthetic 6-D trajectory, shape (n, 6), m and rad."""
    tau = (times - times[0]) / (times[-1] - times[0])
    return np.stack(
        [
            0.4 + 0.15 * np.sin(2 * np.pi * 0.7 * tau),
            -0.2 + 0.3 * tau**2,
            0.3 + 0.1 * np.cos(3 * tau),
            np.pi - 0.1 * tau,
            0.05 * np.sin(2 * tau),
            0.2 * tau,
        ],
        axis=1,
    )


@pytest.fixture
def smooth_demo() -> Demonstration:
    times = np.linspace(0.0, 4.0, 401)
    return Demonstration(times=times, poses=smooth_demo_poses(times), name="synthetic")


@pytest.fixture
def smooth_demo_file(tmp_path, smooth_demo):
    path = tmp_path / "synthetic.csv"
    save_demonstration(path, smooth_demo.times, smooth_demo.poses)
    return path
