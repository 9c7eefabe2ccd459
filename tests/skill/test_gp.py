"""Properties of the GP via-point skill model (distgprl/skill/gp.py)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from distgprl.skill.gp import FitConfig, GPSkill, fit_skill, reconstruction_error
from distgprl.skill.kernels import KernelParams


def make_skill(length_scale=0.12, noise=1e-10, n=15, duration=4.0, seed=0) -> GPSkill:
    rng = np.random.default_rng(seed)
    return GPSkill(
        kernel=KernelParams(length_scale, 1.3, noise),
        via_times=np.linspace(0.0, 1.0, n),
        via_points=rng.normal(size=(n, 6)) * 0.1 + 0.3,
        prior_mean=np.full(6, 0.25),
        duration=duration,
    )


def test_posterior_mean_passes_through_via_points_as_noise_vanishes():
    skill = make_skill(noise=1e-12)
    gamma = skill.via_points + np.random.default_rng(1).normal(size=skill.via_points.shape) * 0.05
    np.testing.assert_allclose(skill.position(gamma, skill.via_times), gamma, atol=1e-6)


def test_posterior_mean_approaches_via_points_monotonically_as_noise_shrinks():
    errors = []
    for noise in (1e-2, 1e-4, 1e-6, 1e-8):
        skill = make_skill(noise=noise)
        residual = skill.position(skill.via_points, skill.via_times) - skill.via_points
        errors.append(np.abs(residual).max())
    assert all(a > b for a, b in zip(errors, errors[1:], strict=False))


@pytest.mark.parametrize("length_scale", [0.08, 0.15, 0.4])
def test_velocity_and_acceleration_maps_match_finite_differences(length_scale):
    skill = make_skill(length_scale=length_scale, noise=1e-6)
    tau = np.linspace(0.05, 0.95, 37)
    h = 1e-5
    dt = h * skill.duration  # seconds per tau step
    position_plus = skill.position_map(tau + h)
    position_minus = skill.position_map(tau - h)
    finite_velocity = (position_plus - position_minus) / (2 * dt)
    velocity = skill.velocity_map(tau)
    rel = np.abs(velocity - finite_velocity).max() / np.abs(velocity).max()
    assert rel < 1e-4
    finite_acceleration = (skill.velocity_map(tau + h) - skill.velocity_map(tau - h)) / (2 * dt)
    acceleration = skill.acceleration_map(tau)
    rel = np.abs(acceleration - finite_acceleration).max() / np.abs(acceleration).max()
    assert rel < 1e-4


def independent_kernel(via_times, length_scale):
    """K, the SE kernel's correlation matrix exp(-(a - b)^2 / (2 l^2)) (unit signal
    variance) at the via-point times, built element by element."""
    return np.array(
        [[np.exp(-((a - b) ** 2) / (2 * length_scale**2)) for b in via_times] for a in via_times]
    )


def independent_correlation_operator(via_times, length_scale, correlation_lambda):
    """S = K (K + lambda I)^-1 from scratch, without symmetrisation."""
    k = independent_kernel(via_times, length_scale)
    return k @ np.linalg.inv(k + correlation_lambda * np.eye(len(via_times)))


@pytest.mark.parametrize("correlation_lambda", [1e-1, 1e-2, 1e-3])
def test_correlation_operator_equals_k_times_inverse_of_k_plus_lambda(correlation_lambda):
    """`correlation_operator` equals K (K + lambda I)^-1 computed independently from the
    kernel; that product (never symmetrised) is symmetric, since K and (K + lambda I)^-1
    commute, with eigenvalues mu / (mu + lambda) in (0, 1) for the eigenvalues mu of K."""
    skill = make_skill()
    reference = independent_correlation_operator(skill.via_times, 0.12, correlation_lambda)
    np.testing.assert_allclose(
        skill.correlation_operator(correlation_lambda), reference, atol=1e-10
    )
    np.testing.assert_allclose(reference, reference.T, atol=1e-10)
    eigenvalues = np.sort(np.linalg.eigvals(reference).real)
    mu = np.linalg.eigvalsh(independent_kernel(skill.via_times, 0.12))
    np.testing.assert_allclose(eigenvalues, np.sort(mu / (mu + correlation_lambda)), atol=1e-8)
    assert eigenvalues.min() > 0.0 and eigenvalues.max() < 1.0


def test_window_operator_is_the_principal_block_of_the_independent_global_operator():
    """S_W of a window is the principal sub-block, at the window's via-point indices, of
    the global S = K (K + lambda I)^-1 computed independently (Eq. transformed_action,
    DESIGN §2); it is not the window's own K_W (K_W + lambda I)^-1, and it is contractive
    (eigenvalues in (0, 1))."""
    skill = make_skill()
    full = independent_correlation_operator(skill.via_times, 0.12, 1e-2)
    for window in ([0, 1, 2, 3, 4], [4, 5, 6, 7, 8], [10, 11, 12, 13, 14]):
        s_w = skill.window_operator(window)
        np.testing.assert_allclose(s_w, full[np.ix_(window, window)], atol=1e-10)
        local = independent_correlation_operator(skill.via_times[window], 0.12, 1e-2)
        assert np.abs(s_w - local).max() > 1e-3
        eigenvalues = np.linalg.eigvals(full[np.ix_(window, window)]).real
        assert eigenvalues.min() > 0.0 and eigenvalues.max() < 1.0


def test_correlation_operator_tends_to_identity_as_lambda_vanishes():
    skill = make_skill()
    distances = [
        np.abs(skill.correlation_operator(lam) - np.eye(15)).max()
        for lam in (1e-1, 1e-3, 1e-6, 1e-9)
    ]
    assert all(a > b for a, b in zip(distances, distances[1:], strict=False))
    assert distances[-1] < 1e-4


def test_larger_lambda_smooths_a_spike_more():
    skill = make_skill()
    spike = np.zeros(15)
    spike[7] = 1.0
    roughness = []
    for lam in (1e-3, 1e-2, 1e-1):
        response = skill.correlation_operator(lam) @ spike
        roughness.append(np.abs(np.diff(response, 2)).sum() / np.abs(response).sum())
    assert roughness[0] > roughness[1] > roughness[2]


def test_fit_recovers_smooth_demonstration_below_one_millimetre(smooth_demo):
    skill = fit_skill(smooth_demo)
    rmse = reconstruction_error(skill, smooth_demo)
    assert max(rmse["position"]) < 1e-3
    assert skill.n_via_points == 15
    np.testing.assert_allclose(skill.via_points[0], smooth_demo.poses[0])
    np.testing.assert_allclose(skill.via_points[-1], smooth_demo.poses[-1])


def test_fit_length_scale_respects_via_point_spacing(smooth_demo):
    config = FitConfig(n_via_points=9)
    skill = fit_skill(smooth_demo, config)
    assert skill.kernel.length_scale >= 0.5 / 8 - 1e-12
    assert skill.via_points.shape == (9, 6)


def test_fit_rejects_fewer_samples_than_via_points(smooth_demo):
    from distgprl.skill.demos import Demonstration

    short = Demonstration(smooth_demo.times[:10], smooth_demo.poses[:10])
    with pytest.raises(ValueError, match="fewer than 15"):
        fit_skill(short)


def test_condition_on_offset_shifts_only_interaction_and_successors():
    skill = make_skill()
    offset = np.array([0.1, -0.05, 0.0])
    gamma = skill.condition_on_offset(offset, first_index=6, last_index=12)
    np.testing.assert_array_equal(gamma[:6], skill.via_points[:6])
    np.testing.assert_array_equal(gamma[13:], skill.via_points[13:])
    np.testing.assert_allclose(
        gamma[6:13, :3] - skill.via_points[6:13, :3], np.tile(offset, (7, 1))
    )
    np.testing.assert_array_equal(gamma[6:13, 3:], skill.via_points[6:13, 3:])
    with pytest.raises(ValueError):
        skill.condition_on_offset(offset, first_index=10, last_index=3)


def test_serialisation_round_trip_preserves_trajectory():
    """to_dict -> JSON -> from_dict keeps every field (via-points, duration, kernel, times,
    prior mean, name), and the copy's own trajectory and velocity / acceleration maps
    equal the original's."""
    skill = dataclasses.replace(make_skill(duration=3.7), name="pick")
    copy = GPSkill.from_dict(json.loads(json.dumps(skill.to_dict())))
    np.testing.assert_array_equal(copy.via_points, skill.via_points)
    np.testing.assert_array_equal(copy.via_times, skill.via_times)
    np.testing.assert_array_equal(copy.prior_mean, skill.prior_mean)
    assert copy.duration == skill.duration == 3.7
    assert copy.kernel == skill.kernel
    assert copy.name == "pick"
    tau = np.linspace(0, 1, 50)
    np.testing.assert_allclose(
        copy.position(copy.via_points, tau), skill.position(skill.via_points, tau)
    )
    np.testing.assert_allclose(copy.velocity_map(tau), skill.velocity_map(tau))
    np.testing.assert_allclose(copy.acceleration_map(tau), skill.acceleration_map(tau))
    np.testing.assert_allclose(
        copy.velocity(copy.via_points, tau), skill.velocity(skill.via_points, tau)
    )


def test_precomputed_maps_equal_direct_evaluation():
    skill = make_skill()
    tau = np.linspace(0, 1, 200)
    maps = skill.maps(tau)
    np.testing.assert_allclose(
        maps.positions(skill.via_points), skill.position(skill.via_points, tau)
    )
