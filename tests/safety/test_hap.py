"""Tests of the HAP safe subspace (distgprl.safety.hap_build, hap_cache, hap_filter; real UR5e
IK, sphere collision model)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import ur_analytic_ik
from _sphere_robot import SphereRobotChecker, ur5e_ik_all
from scipy.spatial.transform import Rotation

from distgprl.safety.edf import DistanceField
from distgprl.safety.hap_build import HapConfig, build_subspace
from distgprl.safety.hap_cache import build_or_load, subspace_cache_key
from distgprl.safety.hap_filter import MovingObstacleFilter, filter_with_edf, safe_mask, tool_bounds
from distgprl.safety.hap_plot import plot_subspace
from distgprl.safety.shapes import Box, Cylinder, with_pose


@pytest.fixture(scope="module")
def built(small_config, checker):
    stages = []
    subspace = build_subspace(
        small_config,
        ur5e_ik_all,
        checker,
        progress=lambda stage, done, total: stages.append((stage, done, total)),
    )
    return subspace, stages


def neighbour_pairs(subspace, config: HapConfig) -> np.ndarray:
    """All pairs of mapped poses that are neighbours in the pose graph."""
    positions, rotations = subspace.positions, subspace.rotations
    i, j = np.triu_indices(len(positions), k=1)
    close = np.linalg.norm(positions[i] - positions[j], axis=1) <= config.neighbour_radius + 1e-9
    traces = np.einsum("nab,nab->n", rotations[i], rotations[j])
    angle = np.arccos(np.clip((traces - 1) / 2, -1, 1))
    keep = close & (angle <= config.orientation_radius + 1e-9)
    return np.stack((i[keep], j[keep]), axis=1)


def test_subspace_is_nontrivial_and_progress_is_reported(built, small_config):
    subspace, stages = built
    stats = subspace.stats
    assert stats.n_poses == 5 * 7 * 3 * 2
    # The pillar and post block some poses; the mapped branch still covers most of the grid.
    assert 0 < stats.n_reachable < stats.n_poses
    assert len(subspace) == stats.n_mapped >= 0.5 * stats.n_reachable
    assert {s for s, _, _ in stages} == {"ik", "expand"}
    assert stages[-1][1] == stages[-1][2] == stats.n_expansions
    unmapped = stats.n_reachable - stats.n_mapped
    np.testing.assert_allclose(
        stats.total_cost, subspace.costs.sum() + small_config.c_max * unmapped, rtol=1e-12
    )


def test_every_point_has_a_collision_free_ik_solution_in_the_mapped_branch(built, checker):
    subspace, _ = built
    for position, rotation, q in zip(
        subspace.positions, subspace.rotations, subspace.configurations, strict=True
    ):
        pose = np.asarray(ur_analytic_ik.ur5e.forward_kinematics(*q))
        np.testing.assert_allclose(pose[:3, 3], position, atol=1e-6)
        np.testing.assert_allclose(pose[:3, :3], rotation, atol=1e-6)
        assert not checker(q)
        # It is one of the pose's IK branches (up to 2 pi wraps of single joints).
        wrapped = np.angle(np.exp(1j * (ur5e_ik_all(pose) - q)))
        assert np.min(np.max(np.abs(wrapped), axis=1)) < 1e-6


def test_neighbouring_mapped_poses_differ_by_at_most_epsilon(built, small_config):
    subspace, _ = built
    pairs = neighbour_pairs(subspace, small_config)
    assert len(pairs) > len(subspace)  # a connected lattice, not isolated points
    q = subspace.configurations
    jump = np.max(np.abs(q[pairs[:, 0]] - q[pairs[:, 1]]), axis=1)
    assert jump.max() <= small_config.epsilon + 1e-12


def test_expansion_tree_edges_are_collision_free_and_costs_add_up(built, small_config, checker):
    subspace, _ = built
    q = subspace.configurations
    assert len(subspace.edges) == len(subspace) - 1
    for parent, child in subspace.edges:
        steps = np.arange(1, small_config.edge_checks + 1) / (small_config.edge_checks + 1)
        for t in steps:
            assert not checker(q[parent] + t * (q[child] - q[parent]))
        np.testing.assert_allclose(
            subspace.costs[child],
            subspace.costs[parent] + np.linalg.norm(q[child] - q[parent]),
            rtol=1e-12,
        )
    assert np.sum(subspace.parents < 0) == 1 and subspace.costs.min() == 0.0


def test_more_root_candidates_never_cost_more(small_config, checker, built):
    subspace, _ = built
    single = build_subspace(
        dataclasses.replace(small_config, root_candidates=1), ur5e_ik_all, checker
    )
    assert subspace.stats.total_cost <= single.stats.total_cost + 1e-9


@pytest.fixture(scope="module")
def tiny_config() -> HapConfig:
    return HapConfig(
        workspace_lower=(0.3, -0.1, 0.3),
        workspace_upper=(0.5, 0.1, 0.4),
        orientations=((np.pi, 0.0, 0.0),),
        root_candidates=1,
    )


def test_cache_hit_returns_identical_subspace_and_changed_inputs_miss(
    tmp_path, tiny_config, scene, checker
):
    kwargs = dict(obstacles=scene, robot_id="ur5e-spheres-test", cache_dir=tmp_path)
    first, loaded_first = build_or_load(tiny_config, ur5e_ik_all, checker, **kwargs)
    calls = checker.calls
    second, loaded_second = build_or_load(tiny_config, ur5e_ik_all, checker, **kwargs)
    assert not loaded_first and loaded_second
    assert checker.calls == calls  # nothing was recomputed
    for name in ("positions", "rotations", "configurations", "costs", "parents", "edges"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    assert first.stats == second.stats and first.config == second.config
    assert len(list(tmp_path.glob("hap_*.npz"))) == 1
    # Any changed input gives another key: obstacles, config, robot, joint limits.
    key = subspace_cache_key(tiny_config, scene, "ur5e-spheres-test")
    assert first.stats.cache_key == key
    moved = (*scene[:1], with_pose(scene[1], scene[1].position + [0.01, 0, 0]), *scene[2:])
    assert subspace_cache_key(tiny_config, moved, "ur5e-spheres-test") != key
    eps = dataclasses.replace(tiny_config, epsilon=0.9)
    assert subspace_cache_key(eps, scene, "ur5e-spheres-test") != key
    assert subspace_cache_key(tiny_config, scene, "ur5e-other") != key
    assert subspace_cache_key(tiny_config, scene, "ur5e-spheres-test", joint_lower=[-3] * 6) != key
    third, loaded_third = build_or_load(eps, ur5e_ik_all, checker, **kwargs)
    assert not loaded_third and len(list(tmp_path.glob("hap_*.npz"))) == 2


def test_filter_with_edf_drops_points_near_a_moving_obstacle(built):
    subspace, _ = built
    positions = subspace.unique_positions
    target = positions[len(positions) // 2]
    cube = Box("cube", target, np.eye(3), np.full(3, 0.03), dynamic=True)
    static = with_pose(cube, target)
    static = dataclasses.replace(static, name="static_cube", dynamic=False)
    margin = 0.08
    field = DistanceField([cube, static])
    kept = filter_with_edf(subspace, field, margin)
    # Box distance of the axis-aligned cube, computed independently of the EDF.
    expected = np.linalg.norm(np.maximum(np.abs(positions - target) - 0.03, 0.0), axis=1) >= margin
    assert 0 < len(kept) < len(positions)
    np.testing.assert_array_equal(kept, positions[expected])
    # The static copy of the cube is ignored by default (it is baked into the subspace).
    assert safe_mask(positions, DistanceField([static]), margin).all()
    assert not safe_mask(positions, DistanceField([static]), margin, dynamic_only=False).all()


def test_plot_subspace_writes_a_png(built, scene, tmp_path):
    subspace, _ = built
    cube = Box("cube", np.array([0.4, 0.2, 0.1]), np.eye(3), np.full(3, 0.03), dynamic=True)
    path = plot_subspace(subspace, (*scene, cube), tmp_path / "figs" / "hap.png")
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_unreachable_workspace_gives_an_empty_subspace():
    config = HapConfig(
        workspace_lower=(3.0, 3.0, 3.0),
        workspace_upper=(3.1, 3.0, 3.0),
        orientations=((np.pi, 0, 0),),
    )
    subspace = build_subspace(config, ur5e_ik_all, SphereRobotChecker(DistanceField([])))
    assert len(subspace) == 0 and subspace.stats.n_reachable == 0
    assert subspace.edges.shape == (0, 2)


def _box_box_distance(centre_a, half_a, centre_b, half_b):
    """Euclidean distance between two axis-aligned boxes (0 when they overlap)."""
    gap = np.maximum(np.abs(centre_a - centre_b) - (half_a + half_b), 0.0)
    return np.linalg.norm(gap, axis=-1)


def test_moving_filter_blocks_exactly_where_the_tool_box_comes_within_margin():
    """blocked(p, a) <=> the tool box at p comes within the margin of a moving box anchored at
    a (independent box-to-box distance, two boxes, random anchors and points)."""
    rng = np.random.default_rng(0)
    shapes = (
        Box("base", np.array([0.4, 0.1, 0.05]), np.eye(3), np.array([0.1, 0.02, 0.02]), True),
        Box("post", np.array([0.45, 0.1, 0.12]), np.eye(3), np.array([0.01, 0.02, 0.05]), True),
    )
    offset, half = np.array([0.0, 0.01, 0.06]), np.array([0.03, 0.02, 0.07])
    moving = MovingObstacleFilter(shapes, offset, half, margin=0.03)
    anchors = rng.uniform([0.3, -0.1, 0.0], [0.5, 0.2, 0.1], (200, 3))
    points = anchors[:, None, :] + rng.uniform(-0.2, 0.2, (200, 16, 3))
    blocked = moving.blocked(points, anchors)
    expected = np.zeros(blocked.shape, dtype=bool)
    for shape in shapes:
        centre = anchors[:, None, :] + (shape.position - shapes[0].position)
        expected |= _box_box_distance(points + offset, half, centre, shape.half_extents) < 0.03
    np.testing.assert_array_equal(blocked, expected)
    assert 0.05 < blocked.mean() < 0.95  # both outcomes occur


def test_moving_filter_axis_aligned_path_equals_the_general_one_exactly():
    """The per-coordinate test for axis-aligned boxes gives exactly the general (rotated-box)
    path's mask — two boxes, points on a fine lattice around them so that many sit at or near
    the margin, and several leading shapes of ``points``."""
    shapes = (
        Box("base", np.array([0.4, 0.1, 0.05]), np.eye(3), np.array([0.1, 0.02, 0.02]), True),
        Box("post", np.array([0.45, 0.1, 0.12]), np.eye(3), np.array([0.01, 0.02, 0.05]), True),
    )
    moving = MovingObstacleFilter(shapes, np.array([0.0, 0.01, 0.06]), np.full(3, 0.02), 0.03)
    general = MovingObstacleFilter(shapes, np.array([0.0, 0.01, 0.06]), np.full(3, 0.02), 0.03)
    general._axis_aligned = False
    rng = np.random.default_rng(3)
    anchors = rng.uniform([0.3, -0.1, 0.0], [0.5, 0.2, 0.1], (64, 3))
    lattice = np.stack(np.meshgrid(*[np.linspace(-0.3, 0.3, 25)] * 3, indexing="ij"), -1)
    points = anchors[:, None, :] + lattice.reshape(1, -1, 3)[:, rng.permutation(25**3)[:500]]
    fast = moving.blocked(points, anchors)
    np.testing.assert_array_equal(fast, general.blocked(points, anchors))
    assert 0.02 < fast.mean() < 0.98
    np.testing.assert_array_equal(moving.blocked(points[0], anchors[0]), fast[0])
    np.testing.assert_array_equal(moving.blocked(points[None], anchors[None]), fast[None])


def test_moving_filter_matches_the_distance_field_of_its_template_for_rotated_boxes():
    """blocked == clearance of the grown template (DistanceField) below the margin, also for a
    rotated box (whose growth by the tool box is conservative)."""
    rng = np.random.default_rng(1)
    rotation = Rotation.from_rotvec([0.2, -0.4, 0.7]).as_matrix()
    shapes = (Box("bar", np.array([0.5, 0.0, 0.1]), rotation, np.array([0.15, 0.02, 0.03]), True),)
    moving = MovingObstacleFilter(shapes, np.zeros(3), np.array([0.02, 0.02, 0.05]), 0.02)
    anchors = rng.uniform(-0.1, 0.1, (50, 3)) + shapes[0].position
    points = anchors[:, None, :] + rng.uniform(-0.3, 0.3, (50, 40, 3))
    field = DistanceField(moving.template)
    expected = field.clearance((points - anchors[:, None, :]).reshape(-1, 3)) < 0.02
    np.testing.assert_array_equal(moving.blocked(points, anchors).ravel(), expected)
    # Conservative: every point the plain (ungrown) box is within the margin of is blocked.
    plain = DistanceField(shapes)
    for anchor, rows in zip(anchors[:5], points[:5], strict=True):
        moved = DistanceField([with_pose(shapes[0], anchor)])
        near = moved.clearance(rows) < 0.02
        assert np.all(moving.blocked(rows[None], anchor[None])[0][near])
    assert plain.clearance(shapes[0].position[None])[0] < 0  # sanity: the centre is inside


def test_moving_filter_rejects_what_it_cannot_represent():
    box = Box("b", np.zeros(3), np.eye(3), np.full(3, 0.1), True)
    cylinder = Cylinder("c", np.zeros(3), np.eye(3), 0.05, 0.1, True)
    with pytest.raises(TypeError, match="only boxes"):
        MovingObstacleFilter((cylinder,), np.zeros(3), np.zeros(3), 0.03)
    with pytest.raises(ValueError, match="at least one"):
        MovingObstacleFilter((), np.zeros(3), np.zeros(3), 0.03)
    with pytest.raises(ValueError, match="positive"):
        MovingObstacleFilter((box,), np.zeros(3), np.zeros(3), 0.0)


def test_tool_bounds_contain_the_tool_at_every_given_rotation():
    rng = np.random.default_rng(2)
    tool = rng.uniform(-0.05, 0.2, (50, 3))
    rotations = Rotation.from_rotvec(rng.normal(0, 0.5, (6, 3))).as_matrix()
    centre, half = tool_bounds(tool, rotations)
    for rotation in rotations:
        world = tool @ rotation.T
        assert np.all(np.abs(world - centre) <= half + 1e-12)
    # Tight: each face touches some rotated tool point.
    every = np.concatenate([tool @ r.T for r in rotations])
    np.testing.assert_allclose(every.max(axis=0), centre + half)
    np.testing.assert_allclose(every.min(axis=0), centre - half)
