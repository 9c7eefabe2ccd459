"""Benchmark of the safety geometry (issue 4): EDF vs PyBullet, L_hap, HAP build.

Plain script: ``python benchmarks/bench_safety.py [--quick]``. Prints medians and spreads
(interquartile range over repeats) of

1. the EDF (``DistanceField.distance``: distance + gradient) for 5 window via-points + 50 tool
   points, against PyBullet closest-point queries (a point probe moved to each point, one
   ``getClosestPoints`` per obstacle body) on the same points and shapes, with the ratio;
2. L_hap forward + backward for a batch of 256 trajectories x 20 query points;
3. the HAP build (real UR5e analytic IK, a sphere model of the arm checked with the EDF) on the
   test grid and on the default workspace grid.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
import pybullet
import torch
import ur_analytic_ik
from pybullet_utils.bullet_client import BulletClient
from scipy.spatial.transform import Rotation

from distgprl.safety.edf import DistanceField
from distgprl.safety.hap_build import HapConfig, build_subspace
from distgprl.safety.hap_loss import HapPrior
from distgprl.safety.shapes import Box, Cylinder, Plane


def timed(function: Callable[[], object], number: int, repeat: int) -> np.ndarray:
    """Seconds per call, one entry per repeat."""
    function()
    samples = []
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            function()
        samples.append((time.perf_counter() - start) / number)
    return np.asarray(samples)


def summary(samples: np.ndarray, unit: float, label: str) -> str:
    q25, q50, q75 = np.percentile(samples / unit, [25, 50, 75])
    name = {1e-6: "us", 1e-3: "ms", 1.0: "s"}[unit]
    return f"median {q50:9.2f} {name}  (IQR {q25:.2f}-{q75:.2f})  {label}"


PROBE_RADIUS = 1e-4  # m, point-sized PyBullet probe; its radius is added back


# ----------------------------------------------------------------------------- scenes
def dcp_like_scene() -> list:
    """Table plane, wall, target cube (manipulated: excluded) and a moving cube: 3 obstacles."""
    return [
        Plane("table", np.zeros(3), np.array([0.0, 0.0, 1.0])),
        Box("wall", np.array([0.55, 0.35, 0.1]), np.eye(3), np.array([0.25, 0.01, 0.1])),
        Box("obstacle_cube", np.array([0.5, 0.05, 0.025]), np.eye(3), np.full(3, 0.025), True),
    ]


def dbm_like_scene() -> list:
    """Table, conveyor rails, 6 rollers and the other bar: 10 obstacles."""
    roller_axis = Rotation.from_euler("x", 90, degrees=True).as_matrix()
    shapes: list = [Plane("table", np.zeros(3), np.array([0.0, 0.0, 1.0]))]
    for side, y in (("left", -0.2), ("right", 0.2)):
        shapes.append(
            Box(f"rail_{side}", np.array([0.5, y, 0.1]), np.eye(3), np.array([0.3, 0.01, 0.02]))
        )
    for i, x in enumerate(np.linspace(0.25, 0.75, 6)):
        shapes.append(Cylinder(f"roller{i}", np.array([x, 0.0, 0.08]), roller_axis, 0.02, 0.19))
    shapes.append(
        Box("other_bar", np.array([0.6, 0.0, 0.12]), np.eye(3), np.array([0.01, 0.15, 0.01]), True)
    )
    return shapes


def bullet_bodies(client: BulletClient, shapes: list) -> list[int]:
    bodies = []
    for shape in shapes:
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
                pybullet.GEOM_PLANE, planeNormal=shape.normal.tolist()
            )
        orientation = (
            [0, 0, 0, 1]
            if isinstance(shape, Plane)
            else Rotation.from_matrix(shape.rotation).as_quat().tolist()
        )
        bodies.append(
            client.createMultiBody(
                0, collision, basePosition=shape.position.tolist(), baseOrientation=orientation
            )
        )
    return bodies


def bench_edf(rng: np.random.Generator, repeat: int) -> None:
    print("1. EDF distance + gradient, 5 via-points + 50 tool points")
    for name, shapes in (("DCP-like", dcp_like_scene()), ("DBM-like", dbm_like_scene())):
        field = DistanceField(shapes)
        # Points in free space (as along a collision-free motion): via-points in the
        # workspace, tool points around the middle one.
        candidates = rng.uniform([0.3, -0.3, 0.05], [0.7, 0.3, 0.4], (400, 3))
        via_points = candidates[field.clearance(candidates) > 0.1][:5]
        candidates = via_points[2] + rng.uniform(-0.08, 0.08, (400, 3))
        tool_points = candidates[field.clearance(candidates) > 0.0][:50]
        points = np.concatenate((via_points, tool_points))
        ours = timed(lambda field=field, points=points: field.distance(points), 200, repeat)
        only_distance = timed(
            lambda field=field, points=points: field.clearance(points), 200, repeat
        )
        moved = [s for s in shapes if s.dynamic]

        def update(field=field, moved=moved) -> None:
            field.update(moved)

        updates = timed(update, 200, repeat)
        client = BulletClient(connection_mode=pybullet.DIRECT)
        radius = PROBE_RADIUS
        try:
            probe = client.createMultiBody(
                0, client.createCollisionShape(pybullet.GEOM_SPHERE, radius=radius)
            )
            bodies = bullet_bodies(client, shapes)
            listed = points.tolist()

            def bullet(client=client, probe=probe, bodies=bodies, listed=listed) -> np.ndarray:
                out = np.empty(len(listed))
                for i, point in enumerate(listed):
                    client.resetBasePositionAndOrientation(probe, point, (0, 0, 0, 1))
                    out[i] = (
                        min(client.getClosestPoints(probe, b, 10.0)[0][8] for b in bodies)
                        + PROBE_RADIUS
                    )
                return out

            theirs = timed(bullet, 5, repeat)
            agreement = np.abs(bullet() - field.distance(points)[0]).max()
        finally:
            client.disconnect()
        print(f"   {name} ({len(shapes)} shapes, {len(points)} points)")
        print("     EDF      " + summary(ours, 1e-6, "distance + gradient"))
        print("     EDF      " + summary(only_distance, 1e-6, "clearance (distance only)"))
        print("     EDF      " + summary(updates, 1e-6, f"update({len(moved)} moved shape)"))
        print("     PyBullet " + summary(theirs, 1e-6, "getClosestPoints, distance only"))
        print(
            f"     ratio PyBullet / EDF (medians): {np.median(theirs) / np.median(ours):.0f}x; "
            f"max |difference| {agreement * 1e3:.3f} mm"
        )


def bench_hap_loss(rng: np.random.Generator, repeat: int) -> None:
    print("2. L_hap forward + backward, 256 trajectories x 20 query points")
    c_safe = HapConfig().grid_positions()
    for mode in ("grid", "kdtree"):
        start = time.perf_counter()
        prior = HapPrior(c_safe, neighbour_search=mode)
        built = time.perf_counter() - start
        x = torch.as_tensor(
            rng.uniform([0.1, -0.6, 0.0], [0.9, 0.6, 0.7], (256, 20, 3)), dtype=torch.float32
        ).requires_grad_(True)

        def step(prior=prior, x=x) -> None:
            x.grad = None
            prior.loss(x).backward()

        default_threads = torch.get_num_threads()
        for threads in sorted({1, default_threads}):
            # Intra-op threads stall when another process holds a core: report both.
            torch.set_num_threads(threads)
            samples = timed(step, 10, repeat)
            print(
                f"   {mode:6s} "
                + summary(
                    samples,
                    1e-3,
                    f"torch threads {threads} (|C_safe| = {len(c_safe)}, "
                    f"construction {built * 1e3:.0f} ms)",
                )
            )
        torch.set_num_threads(default_threads)


# ----------------------------------------------------------------------------- HAP build
UR5E_A = np.array([0.0, -0.425, -0.3922, 0.0, 0.0, 0.0])
UR5E_D = np.array([0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996])
UR5E_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])


def sphere_checker(field: DistanceField, radius: float = 0.05) -> Callable[[np.ndarray], bool]:
    """UR5e as spheres along its DH chain (shoulder to flange) vs the EDF."""

    def in_collision(q: np.ndarray) -> bool:
        frame = np.eye(4)
        origins = []
        for theta, a, d, alpha in zip(q, UR5E_A, UR5E_D, UR5E_ALPHA, strict=True):
            ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
            frame = frame @ np.array(
                [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d]]
                + [[0, 0, 0, 1]]
            )
            origins.append(frame[:3, 3])
        centres = [
            start + t * (end - start)
            for start, end in zip(origins[:-1], origins[1:], strict=True)
            for t in np.linspace(0, 1, max(2, int(np.linalg.norm(end - start) / 0.05) + 1))
        ]
        return bool(np.any(field.clearance(np.asarray(centres)) < radius))

    return in_collision


def ik_all(transform: np.ndarray) -> np.ndarray:
    solutions = ur_analytic_ik.ur5e.inverse_kinematics(np.ascontiguousarray(transform))
    return np.asarray(solutions, dtype=float).reshape(-1, 6)


def bench_hap_build(quick: bool) -> None:
    print("3. HAP build (UR5e analytic IK, sphere arm model vs EDF collision checks)")
    scene = [
        Plane("table", np.array([0.0, 0.0, -0.05]), np.array([0.0, 0.0, 1.0])),
        Box("pillar", np.array([0.5, 0.05, 0.2]), np.eye(3), np.array([0.05, 0.05, 0.25])),
        Cylinder("post", np.array([0.35, -0.35, 0.15]), np.eye(3), 0.04, 0.2),
    ]
    checker = sphere_checker(DistanceField(scene))
    yaw45 = Rotation.from_euler("z", np.pi / 4) * Rotation.from_rotvec([np.pi, 0, 0])
    configs = {
        "test grid (5x7x3 positions x 2 orientations)": HapConfig(
            workspace_lower=(0.3, -0.3, 0.2),
            workspace_upper=(0.7, 0.3, 0.4),
            orientations=((np.pi, 0.0, 0.0), tuple(yaw45.as_rotvec())),
            root_candidates=2,
        ),
    }
    if not quick:
        configs["default grid (7x11x6 positions x 3 orientations)"] = HapConfig()
    for name, config in configs.items():
        subspace = build_subspace(config, ik_all, checker)
        stats = subspace.stats
        print(
            f"   {name}: {stats.build_seconds:.2f} s; {stats.n_mapped} of {stats.n_reachable} "
            f"reachable poses mapped ({len(subspace.unique_positions)} positions of "
            f"{stats.n_poses // len(config.orientations)}), {stats.n_expansions} expansions, "
            f"{stats.collision_checks} collision checks"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, test grid only")
    arguments = parser.parse_args()
    repeat = 5 if arguments.quick else 15
    rng = np.random.default_rng(0)
    print(f"torch threads: {torch.get_num_threads()}")
    bench_edf(rng, repeat)
    bench_hap_loss(rng, repeat)
    bench_hap_build(arguments.quick)


if __name__ == "__main__":
    main()
