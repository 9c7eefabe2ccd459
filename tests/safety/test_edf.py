"""Tests of distgprl.safety.edf: exact signed distance and gradient to primitive obstacles."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pybullet
import pytest
from _reference_edf import reference_distance, rounding_bounds
from pybullet_utils.bullet_client import BulletClient
from scipy.spatial.transform import Rotation

from distgprl.safety.edf import DistanceField
from distgprl.safety.shapes import Box, Cylinder, Plane, with_pose

PROBE_RADIUS = 5e-4  # m; PyBullet has no zero-radius sphere, its radius is added back


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return Rotation.random(random_state=int(rng.integers(2**31))).as_matrix()


def random_scene(rng: np.random.Generator, count: int = 9) -> list:
    shapes = []
    for i in range(count):
        position = rng.uniform(-1.0, 1.0, 3)
        rotation = random_rotation(rng)
        if i % 3 == 0:
            shapes.append(Box(f"box{i}", position, rotation, rng.uniform(0.02, 0.3, 3)))
        elif i % 3 == 1:
            radius, half_length = rng.uniform(0.02, 0.2), rng.uniform(0.02, 0.3)
            shapes.append(Cylinder(f"cylinder{i}", position, rotation, radius, half_length))
        else:
            shapes.append(Plane(f"plane{i}", position, rotation[:, 2]))
    return shapes


def add_to_bullet(client: BulletClient, shape) -> int:
    if isinstance(shape, Box):
        collision = client.createCollisionShape(
            pybullet.GEOM_BOX, halfExtents=shape.half_extents.tolist()
        )
    elif isinstance(shape, Cylinder):
        collision = client.createCollisionShape(
            pybullet.GEOM_CYLINDER, radius=shape.radius, height=2 * shape.half_length
        )
    else:
        collision = client.createCollisionShape(
            pybullet.GEOM_PLANE, planeNormal=np.asarray(shape.normal).tolist()
        )
    orientation = (
        [0.0, 0.0, 0.0, 1.0]
        if isinstance(shape, Plane)
        else Rotation.from_matrix(shape.rotation).as_quat().tolist()  # x y z w, as PyBullet
    )
    return client.createMultiBody(
        0, collision, basePosition=np.asarray(shape.position).tolist(), baseOrientation=orientation
    )


def points_near(shape, rng: np.random.Generator, count: int) -> np.ndarray:
    """Points within ~0.3 m of the shape (many inside, many near edges and rims)."""
    if isinstance(shape, Box):
        size = shape.half_extents
    elif isinstance(shape, Cylinder):
        size = np.array([shape.radius, shape.radius, shape.half_length])
    else:
        size = np.array([0.3, 0.3, 0.3])
    local = rng.uniform(-1.0, 1.0, (count, 3)) * (size + 0.3)
    rotation = np.eye(3) if isinstance(shape, Plane) else shape.rotation
    return shape.position + local @ rotation.T


def test_matches_pybullet_closest_points_within_a_millimetre():
    """Every shape column agrees with PyBullet's getClosestPoints (signed) within 1 mm."""
    rng = np.random.default_rng(7)
    shapes = random_scene(rng)
    field = DistanceField(shapes)
    client = BulletClient(connection_mode=pybullet.DIRECT)
    try:
        probe = client.createMultiBody(
            0, client.createCollisionShape(pybullet.GEOM_SPHERE, radius=PROBE_RADIUS)
        )
        bodies = {shape.name: add_to_bullet(client, shape) for shape in shapes}
        compared = inside = 0
        for shape in shapes:
            points = points_near(shape, rng, 400)
            ours = field.distance_per_shape(points)[:, field.names.index(shape.name)]
            for point, expected_ours in zip(points, ours, strict=True):
                client.resetBasePositionAndOrientation(probe, point.tolist(), [0, 0, 0, 1])
                contact = client.getClosestPoints(probe, bodies[shape.name], 10.0)
                theirs = contact[0][8] + PROBE_RADIUS
                assert abs(theirs - expected_ours) < 1e-3, (shape, point, theirs, expected_ours)
                compared += 1
                inside += expected_ours < 0
    finally:
        client.disconnect()
    assert compared == 3600 and inside > 300  # inside points were exercised too


def test_distance_is_min_over_shapes_and_columns_follow_names():
    rng = np.random.default_rng(1)
    shapes = random_scene(rng)
    field = DistanceField(shapes)
    points = rng.uniform(-1.5, 1.5, (500, 3))
    per_shape = field.distance_per_shape(points)
    d, _ = field.distance(points)
    np.testing.assert_allclose(d, per_shape.min(axis=1), atol=1e-12)
    single = DistanceField([shapes[4]])
    column = field.names.index(shapes[4].name)
    np.testing.assert_allclose(per_shape[:, column], single.distance(points)[0], atol=1e-12)


def test_known_values_box_cylinder_plane():
    """Face, edge, corner, inside and cap/rim distances against hand-computed values."""
    box = Box("box", np.array([1.0, 0, 0]), np.eye(3), np.array([0.1, 0.2, 0.3]))
    d, g = DistanceField([box]).distance(
        np.array([[1.3, 0, 0], [1.2, 0.3, 0], [1.2, 0.3, 0.4], [1.05, 0, 0]])
    )
    np.testing.assert_allclose(d, [0.2, np.sqrt(0.02), np.sqrt(0.03), -0.05], atol=1e-12)
    np.testing.assert_allclose(g[0], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(g[2], np.ones(3) / np.sqrt(3), atol=1e-12)
    np.testing.assert_allclose(g[3], [1, 0, 0], atol=1e-12)  # nearest face is +x
    tilt = Rotation.from_euler("x", 90, degrees=True).as_matrix()  # axis along -y
    cylinder = Cylinder("cylinder", np.zeros(3), tilt, 0.1, 0.5)
    d, g = DistanceField([cylinder]).distance(
        np.array([[0, 0, 0.3], [0, -0.8, 0], [0.2, 0.6, 0], [0, 0, 0.05]])
    )
    np.testing.assert_allclose(d, [0.2, 0.3, np.sqrt(0.02), -0.05], atol=1e-12)
    np.testing.assert_allclose(g[:2], [[0, 0, 1], [0, -1, 0]], atol=1e-12)
    np.testing.assert_allclose(g[3], [0, 0, 1], atol=1e-12)
    # Medial axis inside: the centre of a cube ties all faces; the gradient stays unit-length.
    cube = Box("cube", np.zeros(3), np.eye(3), np.full(3, 0.1))
    d, g = DistanceField([cube]).distance(np.zeros((1, 3)))
    np.testing.assert_allclose(d, [-0.1], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)
    plane = Plane("wall", np.array([0, 0.5, 0]), np.array([0, -1.0, 0]))
    d, g = DistanceField([plane]).distance(np.array([[3.0, 0.2, 7.0], [0, 0.7, 0]]))
    np.testing.assert_allclose(d, [0.3, -0.2], atol=1e-12)
    np.testing.assert_allclose(g, [[0, -1, 0], [0, -1, 0]], atol=1e-12)


def test_gradient_matches_central_differences_away_from_medial_axis():
    """Analytic gradient = central differences wherever d is smooth at the step scale."""
    rng = np.random.default_rng(3)
    shapes = random_scene(rng)
    field = DistanceField(shapes)
    points = np.concatenate([points_near(s, rng, 300) for s in shapes])
    d, grad = field.distance(points)
    step = 1e-6
    forward = np.empty_like(points)
    backward = np.empty_like(points)
    for axis in range(3):
        offset = np.zeros(3)
        offset[axis] = step
        forward[:, axis] = (field.distance(points + offset)[0] - d) / step
        backward[:, axis] = (d - field.distance(points - offset)[0]) / step
    # Off the medial axis the one-sided slopes agree (the kink test does not use `grad`).
    smooth = np.all(np.abs(forward - backward) < 1e-4, axis=1)
    assert smooth.mean() > 0.95
    central = 0.5 * (forward + backward)
    np.testing.assert_allclose(grad[smooth], central[smooth], atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(grad, axis=1), 1.0, atol=1e-9)
    assert (d[smooth] < 0).sum() > 100  # the inside branch was checked too


def test_stepping_back_along_gradient_lands_on_the_surface():
    """x - d(x) grad(x) is on the nearest obstacle surface, inside and outside alike."""
    rng = np.random.default_rng(4)
    shapes = random_scene(rng)
    field = DistanceField(shapes)
    points = np.concatenate([points_near(s, rng, 300) for s in shapes])
    d, grad = field.distance(points)
    surface = points - d[:, None] * grad
    d_surface, _ = field.distance(surface)
    # On the surface of the nearest shape (another shape may overlap it: then it is inside).
    assert np.all(d_surface < 1e-9)
    per_shape = field.distance_per_shape(surface)
    nearest = field.distance_per_shape(points).argmin(axis=1)
    np.testing.assert_allclose(per_shape[np.arange(len(points)), nearest], 0.0, atol=1e-9)


def test_update_moves_the_field_like_a_fresh_field():
    rng = np.random.default_rng(5)
    shapes = random_scene(rng)
    field = DistanceField(shapes)
    points = rng.uniform(-1.5, 1.5, (300, 3))
    before, _ = field.distance(points)
    moved = [
        with_pose(s, s.position + rng.uniform(-0.2, 0.2, 3), random_rotation(rng))
        for s in shapes[:5]
    ]
    field.update(moved)
    d, grad = field.distance(points)
    fresh_d, fresh_grad = DistanceField(moved + shapes[5:]).distance(points)
    np.testing.assert_allclose(d, fresh_d, atol=1e-12)
    np.testing.assert_allclose(grad, fresh_grad, atol=1e-12)
    assert np.abs(d - before).max() > 0.05
    # update_poses: same result by name, keeping orientation when rotation is None.
    other = DistanceField(shapes)
    other.update_poses(
        {s.name: (s.position, s.rotation) for s in moved if not isinstance(s, Plane)}
    )
    other.update_poses({s.name: (s.position, None) for s in moved if isinstance(s, Plane)})
    planes_kept = [
        with_pose(s, m.position) if isinstance(s, Plane) else m
        for s, m in zip(shapes[:5], moved, strict=True)
    ]
    expected, _ = DistanceField(planes_kept + shapes[5:]).distance(points)
    np.testing.assert_allclose(other.distance(points)[0], expected, atol=1e-12)
    names = {s.name for s in other.shapes}
    assert names == set(field.names)


def test_update_rejects_unknown_names_and_kind_changes():
    box = Box("box", np.zeros(3), np.eye(3), np.ones(3) * 0.1)
    field = DistanceField([box])
    with pytest.raises(KeyError):
        field.update([Box("other", np.zeros(3), np.eye(3), np.ones(3))])
    with pytest.raises(TypeError):
        field.update([Cylinder("box", np.zeros(3), np.eye(3), 0.1, 0.1)])
    with pytest.raises(ValueError):
        DistanceField([box, box])


def test_clearance_equals_distance_without_gradient():
    """`clearance` (one compiled pass) equals `distance`'s d bit for bit on random boxes,
    cylinders and planes, outside and inside: both are compiled passes of the same
    operations in the same order (`_local`, `_excess3`, the folded-box formula) on the same
    packed arrays, with no BLAS and no FMA contraction, so no rounding can differ."""
    rng = np.random.default_rng(6)
    field = DistanceField(random_scene(rng))
    points = rng.uniform(-1.5, 1.5, (200, 3))
    np.testing.assert_array_equal(field.clearance(points), field.distance(points)[0])
    inside = np.stack([np.asarray(s.position, float) for s in field.shapes])  # d < 0 there
    np.testing.assert_array_equal(field.clearance(inside), field.distance(inside)[0])
    assert np.isnan(field.clearance(np.array([[np.nan, 0.0, 0.0]])))[0]


def test_dynamic_mask_and_empty_field():
    shapes = [
        Plane("table", np.zeros(3), np.array([0, 0, 1.0])),
        Box("cube", np.array([0.5, 0, 0.05]), np.eye(3), np.ones(3) * 0.05, dynamic=True),
    ]
    field = DistanceField(shapes)
    assert field.dynamic_mask.tolist() == [False, True]
    d, grad = DistanceField([]).distance(np.zeros((4, 3)))
    assert np.all(np.isinf(d)) and np.all(grad == 0)
    assert np.all(np.isinf(DistanceField([]).clearance(np.zeros((2, 3)))))


def test_dynamic_shift_measures_each_point_against_the_moved_dynamic_shapes():
    """``distance(points, dynamic_shift)`` equals, point by point, a field whose dynamic shapes
    (boxes, cylinders, rotated) are translated by that point's shift and whose static ones
    stay: distances to 1e-12, gradients to 1e-9 where no two shapes tie (issue 49)."""
    rng = np.random.default_rng(8)
    shapes = [
        replace(s, dynamic=not isinstance(s, Plane) and i % 2 == 0)
        for i, s in enumerate(random_scene(rng))
    ]
    field = DistanceField(shapes)
    assert field.dynamic_mask.any() and not field.dynamic_mask.all()
    points = rng.uniform(-1.5, 1.5, (120, 3))
    shifts = rng.uniform(-0.3, 0.3, (120, 3))
    d, grad = field.distance(points, dynamic_shift=shifts)
    for i in range(len(points)):
        moved = [with_pose(s, s.position + shifts[i]) if s.dynamic else s for s in shapes]
        reference = DistanceField(moved)
        expected_d, expected_grad = reference.distance(points[i : i + 1])
        np.testing.assert_allclose(d[i], expected_d[0], rtol=0, atol=1e-12)
        per_shape = np.sort(reference.distance_per_shape(points[i])[0])
        if per_shape[1] - per_shape[0] > 1e-9:
            np.testing.assert_allclose(grad[i], expected_grad[0], rtol=0, atol=1e-9)
    # No shift: the plain query, bit for bit.
    plain = field.distance(points)
    zero = field.distance(points, dynamic_shift=np.zeros_like(points))
    np.testing.assert_array_equal(zero[0], plain[0])


def assert_within_rounding(actual, expected, bound, what):
    """|actual - expected| <= bound elementwise (bound (n,) per row), naming the worst row."""
    excess = np.abs(actual - expected).reshape(len(bound), -1).max(axis=1) - bound
    worst = int(np.argmax(excess))
    assert excess[worst] <= 0.0, (
        f"{what} at {worst}: {actual[worst]} vs {expected[worst]}, "
        f"{excess[worst] + bound[worst]:.3g} apart, bound {bound[worst]:.3g}"
    )


def test_distance_equals_the_numpy_evaluation_of_its_rules():
    """`distance` (two compiled passes, issue 66) equals v7's NumPy array evaluation of the
    same rules (`_reference_edf.reference_distance`) on random boxes, cylinders and planes
    (and the same scenes without their planes, whose half-spaces would otherwise be the
    nearest shape of most points), outside and inside the shapes, with and without a dynamic
    shift, within the rounding bound `_reference_edf.rounding_bounds` derives per point.
    The two sum the local coordinates in different orders (plain sums against a BLAS
    product, whose kernel is the machine's: an FMA chain under AVX-512), so they may differ
    by a few ulps of the terms' magnitudes — for a plane, folded as a box of half extent
    1 km, ulps of 1 000 m (1.1e-13 m each) — and, in the gradient, by that times the
    condition of the direction at the point (1 / outside distance; 1 / radial distance on a
    cylinder). The d bound, 2 gamma_13 (|M| + |h|) per shape, is 6e-15 to 8e-12 m here, so a
    rule off by 1e-9 fails; every rule (box, cylinder, plane, the shifted dynamic box) is
    the nearest shape's for more than 50 points. Points where rounding could change the
    nearest shape or face are not compared in the gradient (under 5 %)."""
    rng = np.random.default_rng(66)
    nearest_kinds: list[str] = []
    for _ in range(4):
        shapes = random_scene(rng)
        shapes[0] = Box("moving", np.zeros(3), np.eye(3), np.full(3, 0.1), dynamic=True)
        field = DistanceField(shapes)
        # Without the planes (whose half-spaces hold most points, deepest there) the boxes,
        # cylinders and the shifted dynamic box are the nearest shapes of many points.
        solids = DistanceField([s for s in shapes if not isinstance(s, Plane)])
        inside = np.stack([np.asarray(s.position, float) for s in field.shapes])
        points = np.concatenate([rng.uniform(-1.5, 1.5, (300, 3)), inside + 1e-3])
        shift = rng.uniform(-0.3, 0.3, (len(points), 3))
        for scene in (field, solids):
            for dynamic_shift in (None, shift):
                d, grad = scene.distance(points, dynamic_shift)
                d_ref, grad_ref = reference_distance(scene, points, dynamic_shift)
                d_bound, grad_bound = rounding_bounds(scene, points, dynamic_shift)
                assert_within_rounding(d, d_ref, d_bound, "d")
                compared = ~np.isnan(grad_bound)
                assert compared.mean() > 0.95
                assert_within_rounding(
                    grad[compared], grad_ref[compared], grad_bound[compared], "gradient"
                )
                per_shape = scene._signed(scene._excess(points, dynamic_shift)[1])[0]
                shifted = "shifted " if dynamic_shift is not None else ""
                nearest_kinds += [shifted + scene.names[i] for i in per_shape.argmin(axis=0)]
        outside = points[reference_distance(solids, points)[0] > 0.0]  # no point touches
        assert len(outside) > 100
        grad_bound = rounding_bounds(solids, outside)[1]
        compared = ~np.isnan(grad_bound)
        assert compared.mean() > 0.95
        assert_within_rounding(
            solids.distance(outside)[1][compared],
            reference_distance(solids, outside)[1][compared],
            grad_bound[compared],
            "gradient outside",
        )
    # Every rule was the nearest shape's for many points: boxes, cylinders, planes, and the
    # dynamic box under its shift.
    kinds = [name.rstrip("0123456789") for name in nearest_kinds]
    counts = {kind: kinds.count(kind) for kind in set(kinds)}
    for kind in ("box", "cylinder", "plane", "moving", "shifted moving"):
        assert counts.get(kind, 0) > 50, counts
