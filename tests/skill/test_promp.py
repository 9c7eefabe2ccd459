"""Object-centric ProMP: fit, object-frame shift, conditioning, sampling, persistence."""

from __future__ import annotations

import json

import numpy as np
import pytest
from movement_primitives.promp import ProMP

from distgprl.skill.promp import ObjectCentricProMP, ProMPConfig

HOME = np.array([0.40, -0.30, 0.35])
"""Fixed robot start position (m): in the object frame the start varies between demos."""
NOMINAL_OBJECT = np.array([0.55, 0.00, 0.05])


def minimum_jerk_through(waypoints: np.ndarray, samples: int) -> np.ndarray:
    """Rest-to-rest minimum-jerk segments through waypoints (C2-smooth), (samples, d)."""
    segments = len(waypoints) - 1
    progress = np.linspace(0.0, segments, samples)
    index = np.minimum(progress.astype(int), segments - 1)
    fraction = progress - index
    blend = 10 * fraction**3 - 15 * fraction**4 + 6 * fraction**5
    return waypoints[index] + (waypoints[index + 1] - waypoints[index]) * blend[:, None]


def push_demonstration(
    rng: np.random.Generator, object_position: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Home -> above the object -> behind it -> push through; duration 4-6 s at 50 Hz."""
    waypoints = np.array(
        [
            HOME,
            object_position + [0.0, -0.12, 0.12],
            object_position + [0.0, -0.08, 0.02],
            object_position + [0.0, 0.15, 0.02],
        ]
    )
    duration = rng.uniform(4.0, 6.0)
    samples = int(round(duration / 0.02)) + 1
    times = np.linspace(0.0, duration, samples) + rng.uniform(0.0, 10.0)  # arbitrary t0
    rotation = np.tile([np.pi, 0.0, 0.0], (samples, 1))
    rotation[:, 2] = 0.1 * np.sin(np.pi * np.linspace(0.0, 1.0, samples))
    return times, np.hstack([minimum_jerk_through(waypoints, samples), rotation])


@pytest.fixture(scope="module")
def demonstrations():
    rng = np.random.default_rng(11)
    object_positions = NOMINAL_OBJECT + rng.uniform(-0.1, 0.1, size=(20, 3)) * [1.0, 1.0, 0.0]
    demos = [push_demonstration(rng, position) for position in object_positions]
    return demos, object_positions


@pytest.fixture(scope="module")
def promp(demonstrations):
    demos, object_positions = demonstrations
    return ObjectCentricProMP.fit(demos, object_positions)


def object_frame_mean(demos, object_positions, phase: np.ndarray) -> np.ndarray:
    """Pointwise mean over demos (object frame) at the given phases, (m, 6)."""
    frames = []
    for (times, poses), position in zip(demos, object_positions, strict=True):
        demo_phase = (times - times[0]) / (times[-1] - times[0])
        shifted = poses - np.r_[position, 0.0, 0.0, 0.0]
        frames.append(np.stack([np.interp(phase, demo_phase, channel) for channel in shifted.T], 1))
    return np.mean(frames, axis=0)


def test_mean_reproduces_demonstration_mean_in_object_frame(demonstrations, promp):
    """Fitted mean ≈ pointwise demo mean (object frame): < 1 mm and < 1 mrad everywhere."""
    demos, object_positions = demonstrations
    phase = np.linspace(0.0, 1.0, 201)
    error = np.abs(promp.mean_trajectory(phase) - object_frame_mean(demos, object_positions, phase))
    assert error[:, :3].max() < 1e-3
    assert error[:, 3:].max() < 1e-3
    assert promp.demonstration_count == 20
    durations = [times[-1] - times[0] for times, _ in demos]
    assert promp.duration == pytest.approx(np.mean(durations))


def test_demo_variability_shows_in_trajectory_std(promp):
    """The start (fixed in the world, varying in the object frame) is uncertain; the push is not."""
    start_std, end_std = promp.trajectory_std(np.array([0.0, 1.0]))
    assert start_std[0] > 0.03 and start_std[1] > 0.03  # objects vary ±10 cm in x and y
    assert np.all(end_std[:3] < 1e-3)  # the push ends at a fixed point relative to the object


def test_world_frame_mean_is_object_frame_mean_plus_object_position(promp):
    """mean_trajectory(phase, p) = frame mean + (p, 0, 0, 0) exactly."""
    phase = np.linspace(0.0, 1.0, 37)
    position = np.array([0.61, -0.07, 0.05])
    shift = promp.mean_trajectory(phase, position) - promp.mean_trajectory(phase)
    np.testing.assert_allclose(shift, np.tile(np.r_[position, 0, 0, 0], (37, 1)), atol=1e-12)
    samples = promp.sample(np.random.default_rng(0), phase, 2, object_position=position)
    frame_samples = promp.sample(np.random.default_rng(0), phase, 2)
    np.testing.assert_allclose(samples - frame_samples, np.broadcast_to(shift, samples.shape))


def test_world_frame_mean_follows_a_new_object(demonstrations, promp):
    """For an unseen object position the world mean pushes through that object's contact point."""
    position = np.array([0.50, 0.06, 0.05])
    end = promp.mean_trajectory(np.array([1.0]), position)[0, :3]
    np.testing.assert_allclose(end, position + [0.0, 0.15, 0.02], atol=1e-3)


def test_conditioning_moves_mean_to_position_and_keeps_it_smooth(promp):
    """Conditioning at phase 0 on a start position: mean hits it within 1e-3 m, stays smooth,
    and the well-determined push (phase 1) is unchanged."""
    object_position = np.array([0.55, 0.02, 0.05])
    start = HOME + [0.03, -0.02, 0.0]  # world frame
    conditioned = promp.conditioned(0.0, start, noise=1e-4, object_position=object_position)
    phase = np.linspace(0.0, 1.0, 401)
    mean = conditioned.mean_trajectory(phase, object_position)
    np.testing.assert_allclose(mean[0, :3], start, atol=1e-3)
    original = promp.mean_trajectory(phase, object_position)
    assert np.abs(mean[-1] - original[-1]).max() < 1e-3
    # Smoothness: second differences no larger than those of the unconditioned mean (x 1.5).
    curvature = np.abs(np.diff(mean[:, :3], n=2, axis=0)).max()
    original_curvature = np.abs(np.diff(original[:, :3], n=2, axis=0)).max()
    assert curvature < 1.5 * original_curvature
    # The conditioned start became certain.
    assert np.all(conditioned.trajectory_std(np.array([0.0]))[0, :3] < 2e-4)
    # The original ProMP was not modified.
    assert np.abs(promp.mean_trajectory(phase[:1], object_position)[0, :3] - start).max() > 0.01


def test_conditioning_on_full_pose_in_object_frame(promp):
    """A (6,) target in the object frame is reached in all channels at an interior phase."""
    target = promp.mean_trajectory(np.array([0.2]))[0] + [0.01, -0.01, 0.0, 0.0, 0.0, 0.0]
    conditioned = promp.conditioned(0.2, target, noise=1e-5)
    np.testing.assert_allclose(conditioned.mean_trajectory(np.array([0.2]))[0], target, atol=1e-3)


def test_large_noise_barely_moves_the_mean(promp):
    """With noise far above the demo spread the observation is ignored (Gaussian update)."""
    start = promp.mean_trajectory(np.array([0.0]))[0, :3] + [0.05, 0.0, 0.0]
    conditioned = promp.conditioned(0.0, start, noise=10.0)
    moved = (
        conditioned.mean_trajectory(np.array([0.0]))[0, :3]
        - promp.mean_trajectory(np.array([0.0]))[0, :3]
    )
    assert np.linalg.norm(moved) < 1e-3


def test_start_conditioned_mean_starts_at_the_robot_and_engages_the_new_object(promp):
    """The nominal for a new object (ProMP-RRL's, Protocol v8 rule 3): it starts at the
    robot's pose (within 2 mm: conditioning noise 1e-4 and 20 demonstrations), and behind
    the object (the demonstrations' second key pose, phase 2/3) it is where the
    demonstrations put it relative to that object (within 5 mm); an equivalent start
    rotation vector (2 pi apart) gives the same nominal."""
    new_object = NOMINAL_OBJECT + [0.07, -0.06, 0.0]
    start = np.r_[HOME, np.pi, 0.0, 0.0]
    phase = np.linspace(0.0, 1.0, 61)
    nominal = promp.start_conditioned_mean(phase, new_object, start)
    assert nominal.shape == (61, 6)
    np.testing.assert_allclose(nominal[0, :3], HOME, atol=2e-3)
    behind = nominal[40, :3]  # phase 2/3
    np.testing.assert_allclose(behind, new_object + [0.0, -0.08, 0.02], atol=5e-3)
    wrapped = start.copy()
    wrapped[3] -= 2 * np.pi
    np.testing.assert_allclose(
        promp.start_conditioned_mean(phase, new_object, wrapped), nominal, atol=1e-9
    )
    unconditioned = promp.mean_trajectory(phase, new_object)
    assert np.abs(unconditioned[0, :3] - HOME).max() > 0.03  # what the conditioning fixes


def test_basis_and_conditioning_agree_with_movement_primitives():
    """Same basis family and Eqs. (5)-(6) as movement_primitives.promp.ProMP (width matched)."""
    n_basis = 12
    width = np.sqrt(-1.0 / (8.0 * n_basis**2 * np.log(0.7)))  # that package's fixed width
    config = ProMPConfig(n_basis=n_basis, basis_width=width)
    rng = np.random.default_rng(3)
    size = 6 * n_basis
    factor = rng.normal(scale=0.05, size=(size, size))
    ours = ObjectCentricProMP(
        config, rng.normal(size=size), factor @ factor.T + 1e-6 * np.eye(size), 5.0, 1
    )
    theirs = ProMP(n_dims=6, n_weights_per_dim=n_basis)
    theirs.from_weight_distribution(ours.weight_mean.copy(), ours.weight_covariance.copy())
    phase = np.linspace(0.0, 1.0, 23)
    np.testing.assert_allclose(ours.mean_trajectory(phase), theirs.mean_trajectory(phase.copy()))
    target = rng.normal(size=6)
    noise = 0.01
    ours_conditioned = ours.conditioned(0.4, target, noise=noise)
    theirs_conditioned = theirs.condition_position(target, noise**2 * np.eye(6), t=0.4)
    np.testing.assert_allclose(
        ours_conditioned.mean_trajectory(phase),
        theirs_conditioned.mean_trajectory(phase.copy()),
        atol=1e-9,
    )
    np.testing.assert_allclose(
        ours_conditioned.weight_covariance, theirs_conditioned.weight_cov, atol=1e-9
    )


def test_mean_velocity_matches_finite_differences(promp):
    """mean_velocity (m/s) = d(mean)/d(phase) / duration."""
    phase = np.linspace(0.05, 0.95, 19)
    step = 1e-6
    finite = (promp.mean_trajectory(phase + step) - promp.mean_trajectory(phase - step)) / (
        2 * step * promp.duration
    )
    np.testing.assert_allclose(promp.mean_velocity(phase), finite, atol=1e-6)
    np.testing.assert_allclose(
        promp.mean_velocity(phase, duration=2 * promp.duration), finite / 2, atol=1e-6
    )


def test_sampling_is_reproducible_and_matches_moments(promp):
    """Same generator seed -> same samples; at every phase and channel the sample mean and
    std match the ProMP's mean_trajectory and trajectory_std.

    With n = 20000 Gaussian samples the relative standard error of a sample std is
    1/sqrt(2(n-1)) ~ 0.5 %, and that of a sample mean is std/sqrt(n): rtol 3 % (~6 SE)
    and 5 SE bound all 66 (phase, channel) entries, while a missing square root, a wrong
    covariance block or a sqrt(2) scale error is off by far more. Relative bounds matter
    here: most channels only carry the ~5e-6 covariance jitter, which an absolute
    tolerance in mm would never test.
    """
    phase = np.linspace(0.0, 1.0, 11)
    first = promp.sample(np.random.default_rng(5), phase, 200)
    second = promp.sample(np.random.default_rng(5), phase, 200)
    np.testing.assert_array_equal(first, second)
    assert first.shape == (200, 11, 6)
    assert not np.array_equal(first, promp.sample(np.random.default_rng(6), phase, 200))

    n = 20_000
    samples = promp.sample(np.random.default_rng(5), phase, n)
    std = promp.trajectory_std(phase)
    assert std.shape == (11, 6) and np.all(std > 0)
    np.testing.assert_allclose(samples.std(axis=0, ddof=1), std, rtol=0.03, atol=0)
    mean_error = np.abs(samples.mean(axis=0) - promp.mean_trajectory(phase))
    assert np.all(mean_error <= 5 * std / np.sqrt(n)), (mean_error / (std / np.sqrt(n))).max()


def test_to_dict_round_trip_through_json(promp):
    """to_dict -> JSON -> from_dict reproduces weights, settings and trajectories."""
    restored = ObjectCentricProMP.from_dict(json.loads(json.dumps(promp.to_dict())))
    np.testing.assert_array_equal(restored.weight_mean, promp.weight_mean)
    np.testing.assert_allclose(restored.weight_covariance, promp.weight_covariance, atol=0)
    assert restored.config == promp.config
    assert restored.duration == promp.duration
    phase = np.linspace(0.0, 1.0, 9)
    np.testing.assert_array_equal(restored.mean_trajectory(phase), promp.mean_trajectory(phase))
    with pytest.raises(ValueError, match="format"):
        ObjectCentricProMP.from_dict({**promp.to_dict(), "format": "other"})


def test_fit_keywords_override_config_and_single_demo_works(demonstrations):
    """n_basis/ridge keywords override the config; one demo gives a jitter-only covariance."""
    demos, object_positions = demonstrations
    single = ObjectCentricProMP.fit(demos[:1], object_positions[:1], n_basis=15, ridge=1e-8)
    assert single.config.n_basis == 15 and single.config.ridge == 1e-8
    assert single.weight_mean.shape == (90,)
    np.testing.assert_allclose(
        single.weight_covariance, single.config.covariance_jitter * np.eye(90), atol=1e-20
    )
    times, poses = demos[0]
    phase = (times - times[0]) / (times[-1] - times[0])
    reproduced = single.mean_trajectory(phase, object_positions[0])
    assert np.abs(reproduced[:, :3] - poses[:, :3]).max() < 2e-3


def test_invalid_inputs_are_rejected(demonstrations, promp):
    """Shapes, time order, phases and targets are validated."""
    demos, object_positions = demonstrations
    with pytest.raises(ValueError, match="object_positions"):
        ObjectCentricProMP.fit(demos, object_positions[:3])
    times, poses = demos[0]
    with pytest.raises(ValueError, match="increasing"):
        ObjectCentricProMP.fit([(times[::-1], poses)], object_positions[:1])
    with pytest.raises(ValueError, match="phase"):
        promp.mean_trajectory(np.array([1.2]))
    with pytest.raises(ValueError, match="target"):
        promp.conditioned(0.5, np.zeros(4))
    with pytest.raises(ValueError, match="n_basis"):
        ProMPConfig(n_basis=1)
