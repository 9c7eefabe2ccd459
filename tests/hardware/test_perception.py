"""ArUco perception on digital-twin renders: accuracy, calibration files, sensor model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.hardware.perception import (
    MarkerPerception,
    calibration_from_dict,
    load_calibration,
    pose_error,
    save_calibration,
)
from distgprl.hardware.twin import SHIPPED_CALIBRATION, TwinConfig, TwinSim, twin_calibration
from distgprl.sim.tasks.base import TaskConfig
from distgprl.sim.tasks.dbm import sample_dbm_tc
from distgprl.sim.transforms import invert_transform


@pytest.fixture(scope="module")
def twin():
    sim = TwinSim(TwinConfig())  # the cell's camera: 1920 x 1440, ~1 m from the bars
    yield sim
    sim.close()


def test_marker_poses_within_5mm_and_2deg_at_working_distance(twin):
    config = twin.twin
    perception = MarkerPerception(twin_calibration(config))
    rng = np.random.default_rng(3)
    camera = config.base_from_camera()
    errors, distances = [], []
    for tc in [TaskConfig((0.0, 0.15), (0.0, -0.15))] + [sample_dbm_tc(rng) for _ in range(2)]:
        twin.reset(tc)
        percept = perception.perceive(twin.capture(rng), stamp=0.0)
        assert percept.base_visible
        base_error = pose_error(percept.camera_from_base, invert_transform(camera))
        assert base_error[0] < 0.005 and base_error[1] < 2.0, base_error
        truth = twin.object_transforms()
        assert set(percept.objects) == {"target_bar", "other_bar"}
        for name, pose in percept.objects.items():
            errors.append(pose_error(pose.transform, truth[name]))
            distances.append(np.linalg.norm(truth[name][:3, 3] - camera[:3, 3]))
    errors = np.array(errors)
    assert 0.7 < min(distances) and max(distances) < 1.3  # the cell's working distance, m
    assert errors[:, 0].max() < 0.005, errors
    assert errors[:, 1].max() < 2.0, errors


def test_pixel_noise_is_seeded_and_latency_moves_the_world():
    from distgprl.hardware.backends import TwinBackend

    config = TwinConfig(width=320, height=240, pixel_noise_std=3.0, latency_s=0.2)
    robot = TwinBackend(config, rng=np.random.default_rng(0))
    try:
        robot.start_trial(TaskConfig())
        clean = robot.sim.capture(None)
        noisy_a = robot.sim.capture(np.random.default_rng(5))
        noisy_b = robot.sim.capture(np.random.default_rng(5))
        assert np.array_equal(noisy_a, noisy_b)
        assert 1.5 < np.std(noisy_a.astype(float) - clean) < 4.5
        other_before = robot.ground_truth()["other_bar"][1, 3]
        _, stamp = robot.capture()
        assert stamp == 0.0 and robot.now() == pytest.approx(0.2, abs=0.021)
        moved = robot.ground_truth()["other_bar"][1, 3] - other_before
        assert moved == pytest.approx(0.04 * robot.now(), abs=1e-6)
    finally:
        robot.close()


def test_shipped_calibration_is_the_default_twins():
    shipped = load_calibration(SHIPPED_CALIBRATION)
    exact = twin_calibration(TwinConfig())
    assert shipped.to_dict() == json.loads(json.dumps(exact.to_dict()))


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_calibration_round_trip(tmp_path, suffix):
    calibration = twin_calibration(TwinConfig(width=640, height=480))
    path = save_calibration(tmp_path / f"cell{suffix}", calibration)
    loaded = load_calibration(path)
    assert np.allclose(loaded.camera_matrix, calibration.camera_matrix)
    assert loaded.object_markers == calibration.object_markers
    scaled = loaded.scaled_to(1280, 960)
    assert scaled.camera_matrix[0, 0] == pytest.approx(2 * calibration.camera_matrix[0, 0])


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.update(format="v0"), "format"),
        (lambda d: d["camera"].update(camera_matrix=[[1, 0], [0, 1]]), "camera_matrix"),
        (lambda d: d["aruco"].update(dictionary="DICT_NOPE"), "dictionary"),
        (lambda d: d["markers"]["other_bar"][0].update(id=10), "unique"),
        (lambda d: d["markers"].pop("base"), "markers.base"),
        (lambda d: d["markers"]["target_bar"][0].update(pose=[0, 0]), "pose"),
    ],
)
def test_bad_calibration_is_a_user_error(edit, message):
    data = json.loads(json.dumps(twin_calibration().to_dict()))
    edit(data)
    with pytest.raises(UserInputError, match=message):
        calibration_from_dict(data)


def test_missing_calibration_file(tmp_path):
    with pytest.raises(UserInputError, match="not found"):
        load_calibration(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.json"
    bad.write_text("{oops")
    with pytest.raises(UserInputError, match="not valid"):
        load_calibration(bad)


def test_base_markers_required(twin):
    perception = MarkerPerception(twin_calibration(twin.twin))
    blank = np.full((twin.twin.height, twin.twin.width, 3), 255, dtype=np.uint8)
    with pytest.raises(UserInputError, match="base markers not visible"):
        perception.perceive(blank, 0.0)
