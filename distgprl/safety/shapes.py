"""Obstacle shape descriptions shared by the simulator, the distance field and hardware.

Numerics only: a shape is a primitive with a pose in the world (robot base) frame.
The simulator describes its obstacles with these, the EDF consumes them, and the
hardware pipeline builds them from detected marker poses.

Conventions: lengths in metres; ``rotation`` is a (3, 3) world-from-local rotation
matrix; ``position`` is the primitive's centre, shape (3,).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np


@dataclass(frozen=True)
class Plane:
    """Half-space below a plane: obstacle = {x : n.(x - p) <= 0}.

    Attributes:
        position: a point on the plane, shape (3,), m.
        normal: outward unit normal (pointing into free space), shape (3,).
    """

    name: str
    position: np.ndarray
    normal: np.ndarray
    dynamic: bool = False


@dataclass(frozen=True)
class Box:
    """Oriented box. ``half_extents`` shape (3,), m, along the local axes."""

    name: str
    position: np.ndarray
    rotation: np.ndarray
    half_extents: np.ndarray
    dynamic: bool = False


@dataclass(frozen=True)
class Cylinder:
    """Solid cylinder whose axis is the local z axis.

    Attributes:
        radius: m.
        half_length: half the length along the axis, m.
    """

    name: str
    position: np.ndarray
    rotation: np.ndarray
    radius: float
    half_length: float
    dynamic: bool = False


Shape = Plane | Box | Cylinder


def with_pose(shape: Shape, position: np.ndarray, rotation: np.ndarray | None = None) -> Shape:
    """A copy of ``shape`` moved to a new pose (planes keep their normal unless rotated)."""
    position = np.asarray(position, dtype=float)
    if isinstance(shape, Plane):
        normal = shape.normal if rotation is None else np.asarray(rotation) @ np.array([0, 0, 1.0])
        return replace(shape, position=position, normal=normal)
    rot = shape.rotation if rotation is None else np.asarray(rotation, dtype=float)
    return replace(shape, position=position, rotation=rot)


@dataclass(frozen=True)
class SceneGeometry:
    """All obstacles of a scene at one instant (static and dynamic)."""

    shapes: tuple[Shape, ...] = field(default_factory=tuple)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.shapes)
