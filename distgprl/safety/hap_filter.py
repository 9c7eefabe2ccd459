"""C_safe under moving obstacles (DESIGN §4): the EDF filter of the current scene and the
per-sample :class:`MovingObstacleFilter` of the actor loss, plus the tool's bounding box.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from distgprl.safety.edf import DistanceField
from distgprl.safety.hap_build import SafeSubspace
from distgprl.safety.hap_kernels import MovingBoxes, boxes_block
from distgprl.safety.shapes import Box, Shape

__all__ = ["MovingObstacleFilter", "filter_with_edf", "safe_mask", "tool_bounds"]


def safe_mask(
    positions: np.ndarray, field: DistanceField, margin: float, *, dynamic_only: bool = True
) -> np.ndarray:
    """Boolean mask (m,) of ``positions`` (m, 3) whose EDF clearance is at least ``margin`` (m).

    With ``dynamic_only`` only shapes flagged ``dynamic`` count: the static scene is already
    baked into the subspace (and e.g. the table plane is close to every low pose by design).
    """
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    per_shape = field.distance_per_shape(positions)
    if dynamic_only:
        per_shape = per_shape[:, field.dynamic_mask]
    if per_shape.shape[1] == 0:
        return np.ones(len(positions), dtype=bool)
    mask: np.ndarray = per_shape.min(axis=1) >= margin
    return mask


def filter_with_edf(
    subspace: SafeSubspace | np.ndarray,
    field: DistanceField,
    margin: float,
    *,
    dynamic_only: bool = True,
) -> np.ndarray:
    """C_safe positions (m', 3), m, that keep ``margin`` (m) clearance from the current obstacles.

    The cheap update of C_safe for moving obstacles (DESIGN §4): one EDF query over the (unique)
    subspace positions instead of a rebuild. The margin should cover the tool around the TCP.
    ``subspace`` may be a :class:`SafeSubspace` (its unique positions are used) or an (m, 3)
    array of positions.
    """
    positions = subspace.unique_positions if isinstance(subspace, SafeSubspace) else subspace
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    kept: np.ndarray = positions[safe_mask(positions, field, margin, dynamic_only=dynamic_only)]
    return kept


class MovingObstacleFilter:
    """Which C_safe points a translating moving obstacle blocks (DESIGN §4, per sample).

    :func:`filter_with_edf` filters C_safe once for the obstacles' current poses; the actor loss
    needs the filter per replay sample, each with the obstacles elsewhere. The moving obstacles
    of both tasks only translate, so they are described once by a *template* (their boxes with
    the anchor, the first box's centre, at the origin) and per sample by the anchor position.

    A C_safe position p (a TCP position) is blocked when the tool held at p would come within
    ``margin`` of a moving box. The tool is bounded by an axis-aligned box around the TCP
    (``tool_offset`` centre, ``tool_half_extents``; e.g. :func:`tool_bounds` over the
    demonstration's orientations), so the test is an EDF query of the template with every box
    grown by the tool's extent (Minkowski sum; for a rotated box the tool box's extent along
    the box axes, which is conservative): clearance(p - anchor - tool_offset) < margin.

    Args:
        shapes: the moving obstacles at some instant; boxes only (the tasks' obstacles).
        tool_offset: centre of the tool's bounding box relative to the TCP, shape (3,), m.
        tool_half_extents: its half extents, shape (3,), m (zeros: the TCP point only).
        margin: required clearance, m (e.g. d_min of Eq. safety_reward).
    """

    def __init__(
        self,
        shapes: Sequence[Shape],
        tool_offset: np.ndarray,
        tool_half_extents: np.ndarray,
        margin: float,
    ) -> None:
        if not shapes:
            raise ValueError("a moving-obstacle filter needs at least one moving shape")
        if margin <= 0:
            raise ValueError(f"margin must be positive, got {margin}")
        offset = np.asarray(tool_offset, dtype=float).reshape(3)
        grow = np.asarray(tool_half_extents, dtype=float).reshape(3)
        if np.any(grow < 0):
            raise ValueError("tool_half_extents must be non-negative")
        anchor = np.asarray(shapes[0].position, dtype=float)
        template = []
        for shape in shapes:
            if not isinstance(shape, Box):
                raise TypeError(f"moving obstacle {shape.name!r}: only boxes are supported")
            rotation = np.asarray(shape.rotation, dtype=float)
            template.append(
                replace(
                    shape,
                    position=np.asarray(shape.position, dtype=float) - anchor - offset,
                    rotation=rotation,
                    half_extents=np.asarray(shape.half_extents, dtype=float)
                    + np.abs(rotation.T) @ grow,
                )
            )
        self.template = tuple(template)
        self.margin = float(margin)
        self._centres = np.stack([b.position for b in template])
        self._rotations = np.stack([b.rotation for b in template])
        self._half_extents = np.stack([b.half_extents for b in template])
        self._axis_aligned = bool(np.allclose(self._rotations, np.eye(3)))
        lower = (self._centres - self._half_extents).min(axis=0) - self.margin
        upper = (self._centres + self._half_extents).max(axis=0) + self.margin
        middle, span = (lower + upper) / 2.0, (upper - lower) / 2.0
        # Points further than this from the anchor cannot be blocked (a cheap first cut).
        self.reach = (
            max(
                float(np.linalg.norm(b.position) + np.linalg.norm(b.half_extents)) for b in template
            )
            + self.margin
        )
        # `boxes_block`'s first cut: the common bounding box (axis-aligned) or the reach
        self._bounds = np.concatenate([[self.reach], middle, span])

    @property
    def boxes(self) -> MovingBoxes:
        """The template boxes as `distgprl.safety.hap_kernels` takes them (its first cut
        included), for `HapPrior`'s fused look-up, box test and soft-min."""
        return MovingBoxes(
            self._centres,
            self._rotations,
            self._half_extents,
            self._axis_aligned,
            self._bounds,
            self.margin,
        )

    @staticmethod
    def anchor(shapes: Sequence[Shape]) -> np.ndarray:
        """The anchor position (3,), m, of moving obstacles given as ``shapes``."""
        return np.asarray(shapes[0].position, dtype=float).copy()

    def blocked(self, points: np.ndarray, anchors: np.ndarray) -> np.ndarray:
        """Boolean mask, shape ``points.shape[:-1]``: the point is blocked.

        Equal to ``DistanceField(template).clearance(points - anchor) < margin``, computed
        directly for boxes: outside a box its distance is |max(|R^T (p - c)| - h, 0)|.

        Args:
            points: C_safe positions, shape (..., c, 3), m.
            anchors: the obstacles' anchor per row, shape (..., 3), m.
        """
        points = np.asarray(points, dtype=float)
        anchors = np.asarray(anchors, dtype=float)
        count = points.shape[-2]
        flat = points.reshape(-1, 3)
        index = np.arange(len(flat)).reshape(-1, count)
        rows = np.broadcast_to(anchors, (*points.shape[:-2], 3)).reshape(-1, 3)
        return self.blocked_candidates(flat, index, rows)[0].reshape(points.shape[:-1])

    def blocked_candidates(
        self, points: np.ndarray, index: np.ndarray, anchors: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """`blocked` for candidates given by index: the mask (n, c) of ``points[index]`` and
        the blocked candidates per row (n,).

        Args:
            points: positions, shape (m, 3), m (e.g. all of C_safe).
            index: each row's candidates, indices into ``points``, shape (n, c).
            anchors: the obstacles' anchor per row, shape (n, 3), m.

        One compiled loop (`distgprl.safety.hap_kernels.boxes_block`): points outside the
        boxes' common bounding box grown by the margin (axis-aligned boxes) or farther than
        ``reach`` from the anchor (rotated ones) are cut first.
        """
        return boxes_block(
            np.ascontiguousarray(points, dtype=float),
            np.ascontiguousarray(index),
            np.ascontiguousarray(anchors, dtype=float),
            *self.boxes,
        )


def tool_bounds(tool_points: np.ndarray, rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box (centre, half extents), each (3,), m, around the TCP containing the tool.

    Args:
        tool_points: tool points in the TCP frame, shape (m, 3), m.
        rotations: world-from-TCP rotations the box must cover, shape (r, 3, 3).
    """
    world = np.einsum("rij,mj->rmi", np.asarray(rotations, dtype=float), tool_points)
    lower = world.reshape(-1, 3).min(axis=0)
    upper = world.reshape(-1, 3).max(axis=0)
    return (lower + upper) / 2.0, (upper - lower) / 2.0
