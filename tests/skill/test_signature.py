"""Truncated path signatures: closed forms, Chen's identity, invariances, torch agreement."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from distgprl.skill.signature import (
    signature,
    signature_dimension,
    signature_distance,
    signature_distance_torch,
    signature_levels,
    signature_similarity,
    signature_similarity_torch,
    signature_torch,
)


def tensor_power(vector: np.ndarray, power: int) -> np.ndarray:
    """vector^{⊗power} as a (d,)*power array."""
    result = vector
    for _ in range(power - 1):
        result = np.multiply.outer(result, vector)
    return result


def chen_product_levels(left: list[np.ndarray], right: list[np.ndarray]) -> list[np.ndarray]:
    """Truncated tensor product of two signatures given as level tensors (level 0 = 1)."""
    depth = len(left)
    product = []
    for level in range(1, depth + 1):
        term = left[level - 1] + right[level - 1]
        for split in range(1, level):
            term = term + np.multiply.outer(left[split - 1], right[level - split - 1])
        product.append(term)
    return product


def reference_signature_levels(path: np.ndarray, depth: int) -> list[np.ndarray]:
    """Independent reference: sequential Chen products of segment exponentials."""
    channels = path.shape[1]
    levels = [np.zeros((channels,) * level) for level in range(1, depth + 1)]
    for increment in np.diff(path, axis=0):
        exponential = [
            tensor_power(increment, level) / math.factorial(level) for level in range(1, depth + 1)
        ]
        levels = chen_product_levels(levels, exponential)
    return levels


def random_path(rng: np.random.Generator, points: int = 9, channels: int = 3) -> np.ndarray:
    return np.cumsum(rng.normal(scale=0.1, size=(points, channels)), axis=0)


def test_signature_dimension_counts_all_levels():
    """Length is d + d^2 + ... + d^depth and matches the flat output."""
    assert signature_dimension(3, 3) == 3 + 9 + 27
    assert signature(np.zeros((4, 2)), 4).shape == (2 + 4 + 8 + 16,)


def test_straight_line_levels_match_closed_form():
    """A straight line (any sampling) has levels Δ, Δ⊗Δ/2, Δ⊗Δ⊗Δ/6; level-2 diagonal = Δ²/2."""
    increment = np.array([0.3, -0.2, 0.5])
    fractions = np.array([0.0, 0.1, 0.15, 0.5, 0.8, 1.0])  # uneven samples along the line
    path = np.array([1.0, 2.0, -0.5]) + fractions[:, None] * increment
    first, second, third = signature_levels(signature(path, 3), 3, 3)
    np.testing.assert_allclose(first, increment, atol=1e-14)
    np.testing.assert_allclose(second, np.outer(increment, increment) / 2, atol=1e-14)
    np.testing.assert_allclose(np.diag(second), increment**2 / 2, atol=1e-14)
    np.testing.assert_allclose(third, tensor_power(increment, 3) / 6, atol=1e-14)


def test_level_two_matches_iterated_sum_formula():
    """For a polyline, S^{ij} = Σ_{a<b} Δa_i Δb_j + Σ_a Δa_i Δa_j / 2 (closed form)."""
    rng = np.random.default_rng(0)
    path = random_path(rng, points=12)
    increments = np.diff(path, axis=0)
    expected = np.zeros((3, 3))
    for later in range(len(increments)):
        expected += np.outer(increments[:later].sum(axis=0), increments[later])
        expected += np.outer(increments[later], increments[later]) / 2
    second = signature_levels(signature(path, 2), 3, 2)[1]
    np.testing.assert_allclose(second, expected, atol=1e-13)


@pytest.mark.parametrize("points", [2, 3, 8, 17])
def test_tree_reduction_matches_sequential_reference(points):
    """The pairwise reduction (odd and even segment counts) equals sequential Chen products."""
    rng = np.random.default_rng(points)
    path = random_path(rng, points=points, channels=2)
    levels = signature_levels(signature(path, 4), 2, 4)
    for computed, expected in zip(levels, reference_signature_levels(path, 4), strict=True):
        np.testing.assert_allclose(computed, expected, atol=1e-13)


def test_chen_identity_for_concatenated_paths():
    """S(a * b) = S(a) ⊗ S(b) when b starts where a ends."""
    rng = np.random.default_rng(1)
    first_part = random_path(rng, points=7)
    second_part = np.vstack([first_part[-1], first_part[-1] + random_path(rng, points=5)])
    whole = np.vstack([first_part, second_part[1:]])
    expected = chen_product_levels(
        signature_levels(signature(first_part, 3), 3, 3),
        signature_levels(signature(second_part, 3), 3, 3),
    )
    for computed, product in zip(
        signature_levels(signature(whole, 3), 3, 3), expected, strict=True
    ):
        np.testing.assert_allclose(computed, product, atol=1e-13)


def test_reparameterisation_and_translation_invariance():
    """Resampling finer along the same polyline, or translating it, leaves S unchanged."""
    rng = np.random.default_rng(2)
    path = random_path(rng, points=6)
    finer = [path[0]]
    for start, end in zip(path[:-1], path[1:], strict=True):
        for fraction in np.sort(rng.uniform(0.0, 1.0, size=3)):
            finer.append(start + fraction * (end - start))
        finer.append(end)
    finer.append(path[-1])  # a repeated point (a pause) changes nothing either
    finer = np.array(finer)
    np.testing.assert_allclose(signature(finer, 3), signature(path, 3), atol=1e-13)
    np.testing.assert_allclose(
        signature(path + [5.0, -1.0, 2.0], 3), signature(path, 3), atol=1e-12
    )


def test_square_loop_antisymmetric_level_two_is_signed_area():
    """A closed unit-side square: level 1 = 0; (S^12 − S^21)/2 = +side² counter-clockwise."""
    side = 0.3
    square = side * np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float)
    first, second = signature_levels(signature(square, 2), 2, 2)
    np.testing.assert_allclose(first, 0.0, atol=1e-15)
    area = (second[0, 1] - second[1, 0]) / 2
    assert area == pytest.approx(side**2, abs=1e-14)
    clockwise_second = signature_levels(signature(square[::-1], 2), 2, 2)[1]
    assert (clockwise_second[0, 1] - clockwise_second[1, 0]) / 2 == pytest.approx(-(side**2))
    # The symmetric part of level 2 is ½ Δ⊗Δ = 0 for a closed loop.
    np.testing.assert_allclose(second + second.T, 0.0, atol=1e-14)


def test_single_point_has_zero_signature():
    """A path with no extent has the identity signature (all levels 0)."""
    np.testing.assert_array_equal(signature(np.array([[1.0, 2.0]]), 3), np.zeros(14))


def test_time_augmentation_and_basepoint():
    """Time channel has level-1 increment 1; a basepoint makes level 1 the end point."""
    rng = np.random.default_rng(3)
    path = random_path(rng, points=5, channels=2) + 1.0
    augmented = signature_levels(signature(path, 2, time_augment=True), 3, 2)
    assert augmented[0][2] == pytest.approx(1.0)
    np.testing.assert_allclose(augmented[0][:2], path[-1] - path[0])
    with_base = signature_levels(signature(path, 2, basepoint=True), 2, 2)
    np.testing.assert_allclose(with_base[0], path[-1], atol=1e-14)
    assert not np.allclose(
        signature(path + 1, 2, basepoint=True), signature(path, 2, basepoint=True)
    )
    # Speed matters only with time augmentation: a pause in the middle changes S(τ-augmented).
    paused = np.vstack([path[:3], path[2], path[2], path[3:]])
    np.testing.assert_allclose(signature(paused, 3), signature(path, 3), atol=1e-13)
    assert not np.allclose(
        signature(paused, 3, time_augment=True), signature(path, 3, time_augment=True)
    )


@pytest.mark.parametrize("options", [{}, {"time_augment": True}, {"basepoint": True}])
def test_torch_batched_matches_numpy(options):
    """signature_torch on a (B, n, d) batch equals numpy per path."""
    rng = np.random.default_rng(4)
    batch = np.stack([random_path(rng, points=11) for _ in range(4)])
    computed = signature_torch(torch.tensor(batch), 3, **options).numpy()
    expected = np.stack([signature(path, 3, **options) for path in batch])
    np.testing.assert_allclose(computed, expected, atol=1e-13)
    single = signature_torch(torch.tensor(batch[0], dtype=torch.float32), 3, **options)
    channels = 3 + int(options.get("time_augment", False))
    assert single.dtype == torch.float32
    assert single.shape == (signature_dimension(channels, 3),)
    np.testing.assert_allclose(single.numpy(), expected[0], rtol=1e-4, atol=1e-6)


def test_torch_gradient_matches_finite_differences():
    """Autograd of the signature (and of the similarity) agrees with finite differences."""
    rng = np.random.default_rng(5)
    paths = torch.tensor(np.stack([random_path(rng, points=6) for _ in range(2)]))
    paths.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: signature_torch(x, 3), (paths,))
    reference = torch.tensor(random_path(rng, points=8))
    assert torch.autograd.gradcheck(
        lambda x: signature_similarity_torch(x, reference, 3, 0.2), (paths,)
    )


def test_similarity_is_one_for_same_shape_and_in_unit_interval():
    """Identical, translated and resampled paths score 1; a deformed path scores in (0, 1)."""
    rng = np.random.default_rng(6)
    path = random_path(rng, points=10)
    midpoints = (path[:-1] + path[1:]) / 2
    resampled = np.empty((2 * len(path) - 1, 3))
    resampled[0::2] = path
    resampled[1::2] = midpoints
    assert signature_similarity(path, path) == 1.0
    assert signature_similarity(path, path + [1.0, 2.0, 3.0]) == pytest.approx(1.0, abs=1e-9)
    assert signature_similarity(path, resampled) == pytest.approx(1.0, abs=1e-12)
    deformed = path + rng.normal(scale=0.02, size=path.shape)
    score = signature_similarity(path, deformed)
    assert 0.0 < score < 1.0


def test_similarity_level_one_is_displacement_difference_in_scale_units():
    """At depth 1 the distance is ‖Δa − Δb‖ / scale exactly (score exp(−that))."""
    line_a = np.array([[0.0, 0.0, 0.0], [0.4, 0.0, 0.0]])
    line_b = np.array([[0.0, 0.0, 0.0], [0.4, 0.05, 0.0]])
    assert signature_distance(line_a, line_b, 1, 0.1) == pytest.approx(0.5)
    assert signature_similarity(line_a, line_b, 1, 0.1) == pytest.approx(math.exp(-0.5))


def test_similarity_decreases_with_deformation_and_is_homogeneous():
    """Larger bumps score lower; scaling paths and scale together leaves the score unchanged."""
    phase = np.linspace(0.0, 1.0, 50)
    base = np.stack([0.5 * phase, np.zeros_like(phase), 0.2 * np.ones_like(phase)], axis=1)
    bump = np.stack([np.zeros_like(phase), np.sin(np.pi * phase), np.zeros_like(phase)], axis=1)
    scores = [
        signature_similarity(base, base + height * bump, 3, 0.05)
        for height in (0.0, 0.01, 0.03, 0.1)
    ]
    assert scores[0] == 1.0 and scores[1] > scores[2] > scores[3] > 0.0
    # Deviations of 1 cm on a 0.5 m motion stay on the order of 1 cm / scale at every level.
    assert signature_distance(base, base + 0.01 * bump, 3, 0.05) < 3 * 0.01 / 0.05
    assert signature_distance(base, base + 0.03 * bump, 3, 0.05) == pytest.approx(
        signature_distance(10 * base, 10 * (base + 0.03 * bump), 3, 0.5), rel=1e-9
    )


def test_per_channel_scale_weights_rotation_channels():
    """A per-channel scale of (m, m, m, rad, rad, rad) divides each channel separately."""
    rng = np.random.default_rng(7)
    poses = np.hstack([random_path(rng, 8), random_path(rng, 8)])
    rotated = poses.copy()
    rotated[:, 3:] *= 1.1
    scale = np.array([0.1, 0.1, 0.1, 1e6, 1e6, 1e6])  # rotations practically ignored
    assert signature_similarity(poses, rotated, 3, scale) == pytest.approx(1.0, abs=1e-4)
    assert signature_similarity(poses, rotated, 3, 0.1) < 0.99


def test_torch_similarity_matches_numpy_with_broadcast():
    """Batched torch distance equals numpy; a single reference broadcasts over the batch."""
    rng = np.random.default_rng(8)
    batch = np.stack([random_path(rng, points=9) for _ in range(3)])
    reference = random_path(rng, points=14)
    computed = signature_distance_torch(torch.tensor(batch), torch.tensor(reference), 3, 0.1)
    expected = [signature_distance(path, reference, 3, 0.1) for path in batch]
    np.testing.assert_allclose(computed.numpy(), expected, rtol=1e-12)
    augmented = signature_distance_torch(
        torch.tensor(batch), torch.tensor(reference), 2, 0.1, time_augment=True
    )
    np.testing.assert_allclose(
        augmented.numpy(),
        [signature_distance(path, reference, 2, 0.1, time_augment=True) for path in batch],
        rtol=1e-12,
    )


def test_similarity_gradient_is_finite_at_equality_and_for_pauses():
    """No NaN gradients when signatures coincide or a path repeats a point."""
    rng = np.random.default_rng(9)
    path = random_path(rng, points=6)
    paused = torch.tensor(np.vstack([path[:3], path[2:]]), requires_grad=True)
    score = signature_similarity_torch(paused, torch.tensor(path), 3, 0.1)
    score.backward()
    assert score.item() == pytest.approx(1.0, abs=1e-12)
    assert torch.all(torch.isfinite(paused.grad))


def test_invalid_arguments_are_rejected():
    """Depth, shapes and scale are validated with clear errors."""
    with pytest.raises(ValueError, match="depth"):
        signature(np.zeros((3, 2)), 0)
    with pytest.raises(ValueError, match="shape"):
        signature(np.zeros(3), 2)
    with pytest.raises(ValueError, match="scale"):
        signature_similarity(np.zeros((3, 2)), np.zeros((3, 2)), 2, -1.0)
    with pytest.raises(ValueError, match="scale"):
        signature_similarity(np.zeros((3, 2)), np.zeros((3, 2)), 2, [0.1, 0.1, 0.1])
    with pytest.raises(ValueError):
        signature_levels(np.zeros(5), 2, 2)
