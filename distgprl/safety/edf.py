"""Euclidean distance field (EDF) of a scene made of primitive obstacles (paper §III-C, §IV-C).

``DistanceField`` gives the exact Euclidean distance from a batch of query points to the nearest
obstacle, ``d(x) = min_{o in dO} ||x - o||_2`` (paper, EDF equation of §III-C), together with its
analytic gradient, for the primitives of :mod:`distgprl.safety.shapes` (``Plane``, ``Box``,
``Cylinder``).

Sign convention (signed distance):
    * ``d > 0`` in free space: the Euclidean distance to the nearest obstacle surface, m.
    * ``d = 0`` on an obstacle surface.
    * ``d < 0`` inside an obstacle: minus the penetration depth, i.e. minus the distance to the
      nearest surface of the obstacle that contains the point (the most negative value if the
      point is inside several overlapping obstacles). Points below a ``Plane`` are inside its
      half-space.
    * ``grad`` is the unit gradient of ``d``: in free space it points away from the nearest
      obstacle surface, inside an obstacle it points out of it towards its nearest surface.
      Moving a point along ``grad`` always increases its clearance.
    This matches PyBullet's ``getClosestPoints`` distance of a point-sized probe (negative on
    penetration); the tests check the agreement.

On the medial axis (points equidistant to two surfaces, e.g. the centre of a box) ``d`` is not
differentiable; ``grad`` is then the gradient of one of the tied surfaces (or, for exactly tied
faces inside a shape, their normalised sum) and stays a unit vector.
Exactly on a cylinder's axis the radial direction is undefined; where the radial surface is the
nearest one there (deep inside a long cylinder), the gradient is returned as zero.

Implementation: every shape is evaluated as a "folded box" in its local frame. All shapes are
packed at construction into one stacked rotation matrix ``[R_1 | ... | R_S]`` (3, 3S), offsets and
half extents, so the local coordinates of all points in all shapes are one matrix product. A box
uses ``a = |p_local|``; a cylinder uses ``a = (r, 0, |z|)`` with ``r`` the radial distance; a plane
is a box of half extent ``_PLANE_DEPTH`` in every direction whose top face is the plane (exact for
points within ``_PLANE_DEPTH`` = 1 km). The signed distance of a folded box is
``||max(q, 0)|| + min(max_k q_k, 0)`` with ``q = a - h``. :meth:`DistanceField.update` and
:meth:`DistanceField.update_poses` rewrite the packed arrays in place (no re-allocation), so moving
obstacles can be refreshed every control step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numba import njit

from distgprl.safety.shapes import Box, Cylinder, Plane, Shape, with_pose

__all__ = ["DistanceField", "frame_from_normal"]

_TINY = 1e-12
# Half-size of the box that stands for a plane's half-space, m.
_PLANE_DEPTH = 1.0e3


@njit(cache=True, nogil=True, error_model="numpy")
def _nearest_signed_distance(transform, half, first_cylinder, points):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Min over shapes of the folded-box signed distance, per point (n,), m: the operations
    of `DistanceField._excess` and `DistanceField._signed` in one pass, the local
    coordinates as plain sums (no BLAS; issue 66).

    Args:
        transform: the packed (3S, 4) world-to-local rows (`DistanceField._local_transform`).
        half: the half extents (3, S, 1).
        first_cylinder: index of the first cylinder column (S if none).
        points: (n, 3), m.
    """
    n_shapes = half.shape[1]
    out = np.empty(points.shape[0])
    for j in range(points.shape[0]):
        x, y, z = points[j, 0], points[j, 1], points[j, 2]
        best = np.inf
        for i in range(n_shapes):
            l0, l1, l2 = _local(transform, n_shapes, i, x, y, z)
            q0, q1, q2 = _excess3(half, first_cylinder, i, l0, l1, l2)
            p0, p1, p2 = max(q0, 0.0), max(q1, 0.0), max(q2, 0.0)
            outside = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            d = outside + min(max(max(q0, q1), q2), 0.0)
            if d < best or d != d:
                best = d
        out[j] = best
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _local(transform, n_shapes, i, x, y, z):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Local coordinates (3,) of world point (x, y, z) in shape i: R_i^T (p - c_i)."""
    r0, r1, r2 = transform[i], transform[n_shapes + i], transform[2 * n_shapes + i]
    return (
        r0[0] * x + r0[1] * y + r0[2] * z + r0[3],
        r1[0] * x + r1[1] * y + r1[2] * z + r1[3],
        r2[0] * x + r2[1] * y + r2[2] * z + r2[3],
    )


@njit(cache=True, nogil=True, error_model="numpy")
def _shifted_local(transform, rotations, n_shapes, i, point, shift):  # type: ignore[no-untyped-def]  # pragma: no cover
    """`_local` of ``point`` (3,), minus R_i^T ``shift`` (3,) (a dynamic shape seen at
    the point's time, `DistanceField.distance`'s ``dynamic_shift``)."""
    l0, l1, l2 = _local(transform, n_shapes, i, point[0], point[1], point[2])
    if shift.shape[0] == 0:
        return l0, l1, l2
    sx, sy, sz = shift[0], shift[1], shift[2]
    r0, r1, r2 = rotations[i], rotations[n_shapes + i], rotations[2 * n_shapes + i]
    return (
        l0 - (r0[0] * sx + r0[1] * sy + r0[2] * sz),
        l1 - (r1[0] * sx + r1[1] * sy + r1[2] * sz),
        l2 - (r2[0] * sx + r2[1] * sy + r2[2] * sz),
    )


@njit(cache=True, nogil=True, error_model="numpy")
def _excess3(half, first_cylinder, i, l0, l1, l2):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Folded-box excess q (3,) of local coordinates in shape i (a cylinder folds radially)."""
    if i >= first_cylinder:
        a0 = math.sqrt(l0 * l0 + l1 * l1)
        a1 = 0.0
    else:
        a0 = abs(l0)
        a1 = abs(l1)
    return a0 - half[0, i, 0], a1 - half[1, i, 0], abs(l2) - half[2, i, 0]


@njit(cache=True, nogil=True, error_model="numpy")
def _distance_and_gradient(  # type: ignore[no-untyped-def]
    transform, rotations, half, first_cylinder, dynamic, points, shifts
):  # pragma: no cover - compiled
    """`DistanceField.distance` in two compiled passes: d (n,) and the unit gradient (n, 3).

    Pass 1: each point's nearest shape (the first of equals) and d. Pass 2: that shape's
    folded gradient, unfolded and rotated to the world, with the NumPy version's rules
    (inside: the unit vector of the largest excess, tied faces summed, when any point of
    the batch touches; then every gradient normalised).
    """
    n_shapes = half.shape[1]
    count = points.shape[0]
    distance = np.empty(count)
    nearest = np.zeros(count, dtype=np.int64)
    no_shift = np.empty(0)
    for j in range(count):
        best = np.inf
        for i in range(n_shapes):
            shift = shifts[j] if dynamic[i] and shifts.shape[0] else no_shift
            l0, l1, l2 = _shifted_local(transform, rotations, n_shapes, i, points[j], shift)
            q0, q1, q2 = _excess3(half, first_cylinder, i, l0, l1, l2)
            p0, p1, p2 = max(q0, 0.0), max(q1, 0.0), max(q2, 0.0)
            d = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2) + min(max(max(q0, q1), q2), 0.0)
            if d < best or (d != d and best == best):  # NumPy's argmin: NaN first
                best = d
                nearest[j] = i
        distance[j] = best
    touching = count > 0 and distance.min() <= 0.0
    gradient = np.zeros((count, 3))
    for j in range(count):
        i = nearest[j]
        shift = shifts[j] if dynamic[i] and shifts.shape[0] else no_shift
        local = _shifted_local(transform, rotations, n_shapes, i, points[j], shift)
        q = _excess3(half, first_cylinder, i, local[0], local[1], local[2])
        p0, p1, p2 = max(q[0], 0.0), max(q[1], 0.0), max(q[2], 0.0)
        outside = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        largest = max(max(q[0], q[1]), q[2])
        scale = max(outside, _TINY)
        g = [p0 / scale, p1 / scale, p2 / scale]
        if touching and outside == 0.0:
            for k in range(3):
                if q[k] == largest:
                    g[k] += 1.0
        for k in range(3):
            g[k] = math.copysign(g[k], local[k])
        if i >= first_cylinder:
            radial = math.sqrt(local[0] * local[0] + local[1] * local[1])
            weight = abs(g[0]) / max(radial, _TINY)
            g[1] = weight * local[1]
            g[0] = weight * local[0]
        r0, r1, r2 = rotations[i], rotations[n_shapes + i], rotations[2 * n_shapes + i]
        for m in range(3):
            gradient[j, m] = g[0] * r0[m] + g[1] * r1[m] + g[2] * r2[m]
        if touching:
            norm = math.sqrt(gradient[j, 0] ** 2 + gradient[j, 1] ** 2 + gradient[j, 2] ** 2)
            norm = max(norm, _TINY)
            for m in range(3):
                gradient[j, m] /= norm
    return distance, gradient


def frame_from_normal(normal: np.ndarray) -> np.ndarray:
    """A rotation matrix (3, 3) whose third column is the unit vector ``normal`` (3,)."""
    z = np.asarray(normal, dtype=float)
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack((x, y, z), axis=1)


class DistanceField:
    """Exact signed distance and gradient to a set of primitive obstacles.

    Args:
        shapes: the obstacles, each a ``Plane``, ``Box`` or ``Cylinder`` (world frame, m). Names
            must be unique. The set of shapes (names and kinds) is fixed at construction; poses
            and sizes are refreshed with :meth:`update` / :meth:`update_poses`.

    Example:
        >>> field = DistanceField([Plane("table", np.zeros(3), np.array([0, 0, 1.0]))])
        >>> d, grad = field.distance(np.array([[0.0, 0.0, 0.3]]))  # [0.3], [[0, 0, 1]]
    """

    def __init__(self, shapes: Sequence[Shape]) -> None:
        shapes = tuple(shapes)
        names = [s.name for s in shapes]
        if len(set(names)) != len(names):
            raise ValueError(f"shape names must be unique, got {names}")
        for s in shapes:
            if not isinstance(s, Plane | Box | Cylinder):
                raise TypeError(f"unsupported shape type {type(s).__name__}")
        # Column order: planes and boxes first (plain folding), cylinders last (a contiguous
        # slice gets the radial folding).
        ordered: list[Shape] = [s for s in shapes if not isinstance(s, Cylinder)]
        ordered += [s for s in shapes if isinstance(s, Cylinder)]
        self._records = ordered
        self._names = tuple(s.name for s in ordered)
        self._index = {name: i for i, name in enumerate(self._names)}
        self._kinds = tuple(type(s) for s in ordered)
        n_shapes = len(ordered)
        self._first_cylinder = n_shapes - sum(isinstance(s, Cylinder) for s in ordered)
        # Component-major packing: row k * S + s of the (3S, 4) homogeneous transform maps a
        # world point to local axis k of shape s, (R_s^T (x - c_s))_k.
        self._local_transform = np.zeros((3 * n_shapes, 4))
        self._rotations_stack = np.zeros((3 * n_shapes, 3))  # row k * S + s = (R_s[:, k])^T
        self._half_extents = np.zeros((3, n_shapes, 1))
        self._dynamic = np.array([bool(s.dynamic) for s in ordered], dtype=bool)
        # Rows k * S + s of the packed transform that belong to a dynamic shape s (the shifted
        # queries of `distance`).
        self._dynamic_rows = np.flatnonzero(np.tile(self._dynamic, 3))
        for i, s in enumerate(ordered):
            self._write(i, s)

    # ------------------------------------------------------------------ packing / updates
    @property
    def names(self) -> tuple[str, ...]:
        """Shape names in the column order of :meth:`distance_per_shape`."""
        return self._names

    @property
    def shapes(self) -> tuple[Shape, ...]:
        """The current shapes (poses as last updated), in the order of :attr:`names`."""
        return tuple(self._records)

    @property
    def dynamic_mask(self) -> np.ndarray:
        """Boolean mask (n_shapes,) of the shapes flagged ``dynamic``, in :attr:`names` order."""
        return self._dynamic.copy()

    def _write(self, i: int, shape: Shape) -> None:
        if type(shape) is not self._kinds[i]:
            raise TypeError(
                f"{shape.name} was a {self._kinds[i].__name__}, got {type(shape).__name__}"
            )
        half: tuple[float, float, float] | np.ndarray  # half extents along the local axes, m
        if isinstance(shape, Plane):
            rotation = frame_from_normal(shape.normal)
            centre = np.asarray(shape.position, dtype=float) - _PLANE_DEPTH * rotation[:, 2]
            half = (_PLANE_DEPTH, _PLANE_DEPTH, _PLANE_DEPTH)
        elif isinstance(shape, Box):
            rotation = np.asarray(shape.rotation, dtype=float)
            centre = np.asarray(shape.position, dtype=float)
            half = np.asarray(shape.half_extents, dtype=float)
        else:
            rotation = np.asarray(shape.rotation, dtype=float)
            centre = np.asarray(shape.position, dtype=float)
            # The folded y coordinate of a cylinder is 0; a large half extent keeps q_y
            # out of every max.
            half = (shape.radius, _PLANE_DEPTH, shape.half_length)
        stride = len(self._names)
        self._local_transform[i::stride, :3] = rotation.T
        self._local_transform[i::stride, 3] = -(centre @ rotation)
        self._rotations_stack[i::stride] = rotation.T
        self._half_extents[:, i, 0] = half
        self._records[i] = shape

    def update(self, shapes: Sequence[Shape]) -> None:
        """Refresh the field from new versions of (some of) its shapes, matched by name.

        Poses and sizes are copied into the packed arrays in place; a shape's kind must not
        change. Cost: a few microseconds per shape.
        """
        for s in shapes:
            if s.name not in self._index:
                raise KeyError(f"unknown shape {s.name!r}; known: {self._names}")
            self._write(self._index[s.name], s)

    def update_poses(self, poses: Mapping[str, tuple[np.ndarray, np.ndarray | None]]) -> None:
        """Move shapes by name: ``{name: (position (3,) m, rotation (3, 3) or None)}``.

        ``rotation=None`` keeps the current orientation. For a ``Plane`` the position is a point
        on the plane and a rotation (if given) maps the local +z axis to the new normal.
        """
        for name, (position, rotation) in poses.items():
            i = self._index[name]
            self._write(i, with_pose(self._records[i], position, rotation))

    # ------------------------------------------------------------------ queries
    def _excess(
        self, points: np.ndarray, dynamic_shift: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Local coordinates L and folded-box excess q = a - h, both (3, S, n) (component, shape,
        point), and the cylinders' radial distance r, shape (C, n); with ``dynamic_shift``
        (n, 3) the dynamic shapes see point i at x_i - shift_i."""
        n_shapes = len(self._names)
        homogeneous = np.empty((4, len(points)))
        homogeneous[:3] = points.T
        homogeneous[3] = 1.0
        # Eq. of §III-C evaluated per shape in its frame: L = R^T (x - c), all shapes at once.
        flat = self._local_transform @ homogeneous
        if dynamic_shift is not None and self._dynamic_rows.size:
            rows = self._dynamic_rows  # R^T (x - shift - c) = R^T (x - c) - R^T shift
            flat[rows] -= self._rotations_stack[rows] @ np.asarray(dynamic_shift, float).T
        local = flat.reshape(3, n_shapes, -1)
        excess = np.abs(local)
        c = self._first_cylinder
        radial = None
        if c < n_shapes:
            radial_x, radial_y = local[0, c:], local[1, c:]
            radial = np.sqrt(radial_x * radial_x + radial_y * radial_y)
            excess[0, c:] = radial
            excess[1, c:] = 0.0
        excess -= self._half_extents
        return local, excess, radial

    @staticmethod
    def _signed(excess: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Folded-box signed distance (S, n) = ||max(q, 0)|| + min(max_k q_k, 0), its outside
        part ||max(q, 0)|| (S, n), max(q, 0) (3, S, n) and max_k q_k (S, n)."""
        positive = np.maximum(excess, 0.0)
        outside = np.square(positive).sum(axis=0)
        np.sqrt(outside, out=outside)
        largest = excess.max(axis=0)
        return outside + np.minimum(largest, 0.0), outside, positive, largest

    def distance_per_shape(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from every point to every shape, shape (n, n_shapes), m.

        Columns follow :attr:`names`. Use it to exclude a shape (e.g. the manipulated object)
        or to restrict to dynamic obstacles: ``d[:, field.dynamic_mask].min(axis=1)``.
        """
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if not self._names:
            return np.empty((len(points), 0))
        return self._signed(self._excess(points)[1])[0].T

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance to the nearest obstacle without the gradient, shape (n,), m.

        One compiled pass (`_nearest_signed_distance`); e.g. for the tool points of r_sd.
        Bit-identical to :meth:`distance`'s ``d`` (the same compiled operations in the same
        order, `tests/safety/test_edf.py`).
        """
        points = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3))
        if not self._names:
            return np.full(len(points), np.inf)
        distances: np.ndarray = _nearest_signed_distance(
            self._local_transform, self._half_extents, self._first_cylinder, points
        )
        return distances

    def distance(
        self, points: np.ndarray, dynamic_shift: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance to the nearest obstacle and its gradient.

        Args:
            points: query points, shape (n, 3), m (world frame).
            dynamic_shift: optional (n, 3), m: the dynamic shapes are taken as translated by
                ``shift_i`` for point i (point i is measured against the dynamic shapes at
                x_i - shift_i, against the static ones at x_i): one query for points that see
                rigidly moving obstacles at different times (`distgprl.envs.clearance`).

        Returns:
            d: signed distance, shape (n,), m (module docstring: negative inside an obstacle;
                ``+inf`` if the field has no shapes).
            grad: unit gradient of ``d`` (points away from the nearest surface), shape (n, 3).

        Two compiled passes (`_distance_and_gradient`, issue 66); the NumPy evaluation of
        the same rules (kept in ``tests/safety/_reference_edf.py``) agrees within the
        rounding of the local coordinates (plain sums here, a BLAS product there): a few
        ulps of their terms' magnitudes — up to ~1e-13 m next to a plane, whose box
        stand-in puts its local z near 1 km — and that times the direction's condition in
        ``grad`` (`_reference_edf.rounding_bounds`).
        """
        points = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3))
        n = len(points)
        if not self._names:
            return np.full(n, np.inf), np.zeros((n, 3))
        shifts = np.empty((0, 3))
        if dynamic_shift is not None and self._dynamic_rows.size:
            shifts = np.ascontiguousarray(np.broadcast_to(np.asarray(dynamic_shift, float), (n, 3)))
        distance_and_gradient: tuple[np.ndarray, np.ndarray] = _distance_and_gradient(
            self._local_transform,
            self._rotations_stack,
            self._half_extents,
            self._first_cylinder,
            self._dynamic,
            points,
            shifts,
        )
        return distance_and_gradient
