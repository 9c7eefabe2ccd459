"""One PyBullet client per simulation, and helpers that build primitive bodies.

Every PyBullet call in :mod:`distgprl.sim` goes through a
:class:`pybullet_utils.bullet_client.BulletClient` created here in DIRECT (headless)
mode, so several simulations can live in one process. Obstacles are built only from
the primitives of :mod:`distgprl.safety.shapes` (plane, box, cylinder), so the
distance field computed from those shapes agrees with PyBullet's own geometry.
"""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from distgprl.safety.shapes import Box, Cylinder, Plane, Shape
from distgprl.sim.transforms import matrix_to_quaternion

PLANE_SLAB_HALF_SIZE = 1.5
"""Half side (m) of the slab that stands in for a horizontal :class:`Plane` in PyBullet."""

PLANE_SLAB_HALF_THICKNESS = 0.05
"""Half thickness (m) of that slab; its top face is the plane."""


@dataclass(frozen=True)
class PhysicsConfig:
    """Physics settings shared by every task simulation.

    Attributes:
        physics_dt: physics time step, s.
        substeps: physics steps per control period (``control_dt = physics_dt * substeps``).
        solver_iterations: constraint solver iterations per physics step.
        gravity: gravitational acceleration along world -z, m/s^2.
    """

    physics_dt: float = 1.0 / 75.0
    substeps: int = 3
    solver_iterations: int = 20
    gravity: float = 9.81

    @property
    def control_dt(self) -> float:
        """Control period in seconds."""
        return self.physics_dt * self.substeps


# -- PyBullet's C-level stdout -------------------------------------------------------------------
# PyBullet prints ``argv[0]=`` each time a client connects, with C ``printf``: below Python's
# `sys.stdout` (so `contextlib.redirect_stdout` does not catch it) and, when stdout is a pipe,
# flushed by C's buffer at some later point, into output meant for reading or parsing (66
# lines per `ci` sweep). (Its ``pybullet build time`` banner at import goes to stderr.)


def _flush_c_stdout() -> None:
    """Flush C stdio's buffers (``fflush(NULL)``), so buffered text goes where fd 1 points
    now; a no-op where the C library cannot be loaded."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


@contextmanager
def stdout_to_devnull() -> Iterator[None]:
    """Point file descriptor 1 at the null device for the block, then restore it.

    Python's and C's buffers are flushed on entry (what was printed before still reaches
    stdout) and C's again before restoring (what the block printed goes to the null device,
    not later to stdout). Process-wide while it lasts: keep the block short (a connect).
    Where fd 1 cannot be duplicated (no stdout at all), the block runs as is.
    """
    try:
        sys.stdout.flush()
    except (AttributeError, OSError, ValueError):
        pass
    _flush_c_stdout()
    try:
        saved = os.dup(1)
    except OSError:
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        _flush_c_stdout()
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def connect_direct() -> BulletClient:
    """A new headless (DIRECT) PyBullet client, connected without PyBullet's ``argv[0]=``
    line on stdout (`stdout_to_devnull`)."""
    with stdout_to_devnull():
        return BulletClient(connection_mode=pybullet.DIRECT)


def make_client(config: PhysicsConfig) -> BulletClient:
    """A new headless PyBullet client configured with ``config`` (deterministic settings)."""
    client = connect_direct()
    client.setPhysicsEngineParameter(
        fixedTimeStep=config.physics_dt,
        numSolverIterations=config.solver_iterations,
        numSubSteps=0,
        deterministicOverlappingPairs=1,
    )
    client.setGravity(0.0, 0.0, -config.gravity)
    return client


def create_shape_body(
    client: BulletClient,
    shape: Shape,
    rgba: tuple[float, float, float, float],
    mass: float = 0.0,
    lateral_friction: float = 0.5,
) -> int:
    """Create a single-primitive body for ``shape`` at its pose; returns the body id.

    ``mass = 0`` makes a static (or kinematically moved) body. Planes get a large,
    thin visual box; their collision shape is PyBullet's infinite plane.
    """
    quaternion = [0.0, 0.0, 0.0, 1.0]
    position = np.asarray(shape.position, dtype=float)
    if isinstance(shape, Plane):
        # A thick slab whose top face is the plane: PyBullet's box-box contact gives a full
        # contact manifold (an infinite plane gives one point and lets pushed boxes sink).
        # Inside the slab's footprint its distances equal the half-space's.
        normal = np.asarray(shape.normal, dtype=float)
        if not np.allclose(normal, [0.0, 0.0, 1.0]):
            raise ValueError("only horizontal planes (normal +z) are supported")
        half = [PLANE_SLAB_HALF_SIZE, PLANE_SLAB_HALF_SIZE, PLANE_SLAB_HALF_THICKNESS]
        collision = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        visual = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=rgba)
        position = position - np.array([0.0, 0.0, PLANE_SLAB_HALF_THICKNESS])
    elif isinstance(shape, Box):
        half = np.asarray(shape.half_extents, dtype=float).tolist()
        collision = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        visual = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=rgba)
        quaternion = matrix_to_quaternion(shape.rotation).tolist()
    elif isinstance(shape, Cylinder):
        length = 2.0 * float(shape.half_length)
        collision = client.createCollisionShape(
            pybullet.GEOM_CYLINDER, radius=float(shape.radius), height=length
        )
        visual = client.createVisualShape(
            pybullet.GEOM_CYLINDER, radius=float(shape.radius), length=length, rgbaColor=rgba
        )
        quaternion = matrix_to_quaternion(shape.rotation).tolist()
    else:  # pragma: no cover - Shape is a closed union
        raise TypeError(f"unsupported shape {type(shape).__name__}")
    body = client.createMultiBody(
        baseMass=mass,
        baseCollisionShapeIndex=collision,
        baseVisualShapeIndex=visual,
        basePosition=position.tolist(),
        baseOrientation=quaternion,
    )
    client.changeDynamics(
        body,
        -1,
        lateralFriction=lateral_friction,
        linearDamping=0.0,
        angularDamping=0.0,
        restitution=0.0,
    )
    return body


#: PyBullet keeps at most this many children of one ``createCollisionShapeArray`` and
#: silently drops the rest (``MAX_COMPOUND_COLLISION_SHAPES`` in its shared-memory API).
MAX_SHAPES_PER_ARRAY = 16


def _shape_arrays(
    client: BulletClient, shapes: tuple[Box | Cylinder, ...], origin: np.ndarray
) -> tuple[int, int]:
    """(collision, visual) shape-array ids of up to `MAX_SHAPES_PER_ARRAY` shapes, posed
    relative to ``origin``."""
    kwargs: dict[str, list] = {
        "shapeTypes": [],
        "radii": [],
        "halfExtents": [],
        "lengths": [],
        "collisionFramePositions": [],
        "collisionFrameOrientations": [],
    }
    visual_kwargs: dict[str, list] = {
        "shapeTypes": [],
        "radii": [],
        "halfExtents": [],
        "lengths": [],
        "visualFramePositions": [],
        "visualFrameOrientations": [],
    }
    for shape in shapes:
        half: np.ndarray | tuple[float, float, float]
        if isinstance(shape, Box):
            kind, radius, half, length = pybullet.GEOM_BOX, 0.0, shape.half_extents, 0.0
        else:
            kind, radius = pybullet.GEOM_CYLINDER, float(shape.radius)
            half, length = (0.0, 0.0, 0.0), 2.0 * float(shape.half_length)
        position = (np.asarray(shape.position, dtype=float) - origin).tolist()
        quaternion = matrix_to_quaternion(shape.rotation).tolist()
        for target, frame in ((kwargs, "collision"), (visual_kwargs, "visual")):
            target["shapeTypes"].append(kind)
            target["radii"].append(radius)
            target["halfExtents"].append(list(np.asarray(half, dtype=float)))
            target["lengths"].append(length)
            target[f"{frame}FramePositions"].append(position)
            target[f"{frame}FrameOrientations"].append(quaternion)
    return client.createCollisionShapeArray(**kwargs), client.createVisualShapeArray(
        **visual_kwargs
    )


def create_compound_body(
    client: BulletClient,
    shapes: tuple[Box | Cylinder, ...],
    rgba: tuple[float, float, float, float],
    origin: np.ndarray,
    mass: float = 0.0,
    lateral_friction: float = 0.5,
) -> int:
    """One body made of several boxes/cylinders (poses relative to ``origin`` (3,), m).

    The shapes' ``position``/``rotation`` are given in the world frame for the body at
    ``origin`` with identity orientation. Returns the body id. A static body (``mass`` 0)
    of more than `MAX_SHAPES_PER_ARRAY` shapes carries the rest on fixed massless links
    (PyBullet would silently drop them from one shape array); a dynamic one must fit in
    one array.
    """
    origin = np.asarray(origin, dtype=float)
    groups = [
        shapes[start : start + MAX_SHAPES_PER_ARRAY]
        for start in range(0, len(shapes), MAX_SHAPES_PER_ARRAY)
    ]
    if len(groups) > 1 and mass > 0.0:
        raise ValueError(
            f"a dynamic compound body holds at most {MAX_SHAPES_PER_ARRAY} shapes, "
            f"got {len(shapes)}"
        )
    collision, visual = _shape_arrays(client, groups[0], origin)
    links = [_shape_arrays(client, group, origin) for group in groups[1:]]
    link_kwargs: dict[str, list] = {}
    if links:  # only then: bodies of one array are created exactly as before
        n = len(links)
        link_kwargs = {
            "linkMasses": [0.0] * n,
            "linkCollisionShapeIndices": [c for c, _ in links],
            "linkVisualShapeIndices": [v for _, v in links],
            "linkPositions": [[0.0, 0.0, 0.0]] * n,
            "linkOrientations": [[0.0, 0.0, 0.0, 1.0]] * n,
            "linkInertialFramePositions": [[0.0, 0.0, 0.0]] * n,
            "linkInertialFrameOrientations": [[0.0, 0.0, 0.0, 1.0]] * n,
            "linkParentIndices": [0] * n,
            "linkJointTypes": [pybullet.JOINT_FIXED] * n,
            "linkJointAxis": [[0.0, 0.0, 1.0]] * n,
        }
    body = client.createMultiBody(
        baseMass=mass,
        baseCollisionShapeIndex=collision,
        baseVisualShapeIndex=visual,
        basePosition=origin.tolist(),
        **link_kwargs,
    )
    for link in range(-1, len(links)):
        # colour after creation: createVisualShapeArray's rgbaColors crashes PyBullet 3.2.7
        client.changeVisualShape(body, link, rgbaColor=list(rgba))
        client.changeDynamics(
            body,
            link,
            lateralFriction=lateral_friction,
            linearDamping=0.0,
            angularDamping=0.0,
            restitution=0.0,
        )
    return body


def min_distance(
    client: BulletClient,
    body_a: int,
    body_b: int,
    cutoff: float,
    exempt_links_a: frozenset[int] = frozenset(),
) -> float:
    """Minimum signed distance (m) between two bodies, capped at ``cutoff``.

    Negative values are penetration depths. Pairs involving a link of ``body_a`` in
    ``exempt_links_a`` are ignored.
    """
    best = cutoff
    for point in client.getClosestPoints(bodyA=body_a, bodyB=body_b, distance=cutoff):
        if point[3] in exempt_links_a:
            continue
        if point[8] < best:
            best = point[8]
    return best
