"""Twin sensor noise: seeded, level 0 is exactly today's camera, higher levels degrade it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.hardware.perception import MarkerPerception, pose_error
from distgprl.hardware.twin import (
    SENSOR_NOISE,
    NoisyCornerPerception,
    SensorNoise,
    TwinConfig,
    TwinSim,
    miscalibrated,
    sensor_noise_level,
    twin_calibration,
)
from distgprl.sim.tasks.base import TaskConfig
from distgprl.sim.transforms import pose_to_matrix

SMALL = TwinConfig(width=320, height=240)


@pytest.fixture(scope="module")
def sims():
    """One twin per noise level (320 x 240), bars placed alike."""
    out = {}
    for level, noise in SENSOR_NOISE.items():
        sim = TwinSim(dataclasses.replace(SMALL, noise=noise))
        sim.reset(TaskConfig((0.0, 0.05), (0.0, -0.05)))
        out[level] = sim
    yield out
    for sim in out.values():
        sim.close()


def test_level_zero_is_todays_image(sims):
    plain = TwinSim(SMALL)  # a twin built before sensor noise existed: no noise field set
    try:
        plain.reset(TaskConfig((0.0, 0.05), (0.0, -0.05)))
        today = plain.capture(np.random.default_rng(7))
    finally:
        plain.close()
    level0 = sims[0].capture(np.random.default_rng(7), np.random.default_rng(99))
    assert np.array_equal(level0, today)
    assert SENSOR_NOISE[0] == SensorNoise() and not SENSOR_NOISE[0].affects_image


@pytest.mark.parametrize("level", [1, 2])
def test_noise_is_seeded_and_grows_with_the_level(sims, level):
    sim = sims[level]
    a = sim.capture(np.random.default_rng(7), np.random.default_rng(3))
    b = sim.capture(np.random.default_rng(7), np.random.default_rng(3))
    c = sim.capture(np.random.default_rng(7), np.random.default_rng(4))
    assert np.array_equal(a, b)  # same seeds, same image
    assert not np.array_equal(a, c)  # another seed, another exposure / noise
    clean = sims[0].capture(None)
    difference = np.abs(a.astype(float) - clean).mean()
    lower = np.abs(sims[1].capture(np.random.default_rng(7), np.random.default_rng(3)) - clean)
    assert difference > 0.5
    if level == 2:
        assert difference > lower.astype(float).mean()


def test_blur_softens_marker_edges():
    """Gaussian blur lowers the image's gradient energy (edges spread over more pixels)."""
    blurred = SensorNoise(blur_sigma_px=1.5)
    sharp, soft = TwinSim(SMALL), TwinSim(dataclasses.replace(SMALL, noise=blurred))
    try:
        for sim in (sharp, soft):
            sim.reset(TaskConfig())
        a = sharp.capture(None).astype(float)
        b = soft.capture(None, np.random.default_rng(0)).astype(float)
    finally:
        sharp.close()
        soft.close()
    assert np.abs(np.diff(b, axis=1)).mean() < 0.8 * np.abs(np.diff(a, axis=1)).mean()


def test_corner_noise_is_seeded_and_moves_corners(sims):
    calibration = twin_calibration(SMALL)
    image = sims[0].capture(None)
    exact = MarkerPerception(calibration).detect(image)
    first = NoisyCornerPerception(calibration, 0.4, np.random.default_rng(1)).detect(image)
    again = NoisyCornerPerception(calibration, 0.4, np.random.default_rng(1)).detect(image)
    assert set(first) == set(exact) and len(exact) > 0
    offsets = np.concatenate([first[i] - exact[i] for i in exact])
    assert 0.2 < offsets.std() < 0.6
    assert all(np.array_equal(first[i], again[i]) for i in exact)


def test_base_calibration_error_is_one_rigid_seeded_move():
    calibration = twin_calibration(SMALL)
    noise = SENSOR_NOISE[2]
    moved = miscalibrated(calibration, noise, np.random.default_rng(0))
    same = miscalibrated(calibration, noise, np.random.default_rng(0))
    assert moved == same
    assert miscalibrated(calibration, SENSOR_NOISE[0], np.random.default_rng(0)) is calibration
    errors = [
        pose_error(pose_to_matrix(np.asarray(b.pose)), pose_to_matrix(np.asarray(a.pose)))
        for a, b in zip(calibration.base_markers, moved.base_markers, strict=True)
    ]
    translation = np.array([e[0] for e in errors])
    rotation = np.array([e[1] for e in errors])
    assert 0.0 < translation.max() < 0.02 and 0.0 < rotation.max() < 3.0
    assert np.ptp(rotation) < 1e-6  # one rigid error for the whole plate: equal rotations
    # marker-to-marker geometry of the plate is kept (a rigid move)
    before = np.array([a.pose[:3] for a in calibration.base_markers])
    after = np.array([b.pose[:3] for b in moved.base_markers])
    assert np.allclose(
        np.linalg.norm(before - before[0], axis=1), np.linalg.norm(after - after[0], axis=1)
    )


def test_unknown_level_is_a_user_error():
    with pytest.raises(UserInputError, match="sensor noise level"):
        sensor_noise_level(5)
