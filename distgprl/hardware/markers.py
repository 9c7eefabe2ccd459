"""ArUco marker layout of the DBM cell, shared by the digital twin and the shipped calibration.

Frames (all metres, rotation vectors in radians, UR convention):

- **marker frame** (OpenCV ArUco): origin at the marker centre, x to the right and y up in
  the marker image, z out of the printed face. Corner order as OpenCV's detector returns
  them: top-left, top-right, bottom-right, bottom-left = (-s/2, s/2), (s/2, s/2),
  (s/2, -s/2), (-s/2, -s/2) with s the side of the black border.
- **bar frame**: origin at the centre of the bar's base box (the point the simulation calls
  the bar's position), axes parallel to the robot base frame when the bar lies on the
  conveyor (x across the conveyor, y along the belt, z up).
- **robot base frame**: the UR controller's ``base`` frame (= simulation world frame).

Every bar carries two markers on the top face of its base box, one on each side of the
arch handle (x = +-5.75 cm from the bar centre), printed on a white square plate
(``BAR_PLATE_SIDE``) with a one-cell white margin around the black border. Four larger
markers lie flat on the robot's mounting plate next to the base; their poses in the robot
base frame define the camera-to-base transform.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from distgprl.sim.tasks.dbm import SCENE

DICTIONARY = "DICT_4X4_50"
"""OpenCV predefined dictionary name (4x4 bits: large cells, robust at small image sizes)."""

CELLS_WITH_BORDER = 6
"""Cells across a 4x4 marker including its black border."""

CELLS_WITH_MARGIN = 8
"""Cells across the printed plate: the marker plus a one-cell white margin on every side."""

BAR_PLATE_SIDE = 0.044
"""Side (m) of the white plate that carries a bar marker (the bar top is 5 cm deep)."""

BASE_PLATE_SIDE = 0.10
"""Side (m) of the white plate that carries a base marker."""

TARGET_BAR_IDS = (10, 11)
OTHER_BAR_IDS = (20, 21)
BASE_IDS = (0, 1, 2, 3)


def marker_side(plate_side: float) -> float:
    """Black-border side (m) of a marker printed on a plate of ``plate_side`` m."""
    return plate_side * CELLS_WITH_BORDER / CELLS_WITH_MARGIN


@dataclass(frozen=True)
class MarkerSpec:
    """One physical marker.

    Attributes:
        marker_id: ArUco id in :data:`DICTIONARY` (or the calibration's dictionary).
        size: side of the black border, m.
        pose: marker frame in its parent frame (bar frame for bar markers, robot base
            frame for base markers), shape (6,): x, y, z (m), rx, ry, rz (rad).
    """

    marker_id: int
    size: float
    pose: tuple[float, float, float, float, float, float]

    def corners(self) -> np.ndarray:
        """Corner positions (4, 3), m, in the parent frame, in OpenCV's detection order."""
        from distgprl.sim.transforms import pose_to_matrix

        half = self.size / 2.0
        local = np.array(
            [[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0], [-half, -half, 0.0]]
        )
        transform = pose_to_matrix(np.asarray(self.pose, dtype=float))
        return local @ transform[:3, :3].T + transform[:3, 3]


def _bar_markers(ids: tuple[int, int]) -> tuple[MarkerSpec, ...]:
    top = float(SCENE.bar_half_extents[2]) + 0.0005  # printed plate 0.5 mm above the top face
    x = 0.0575
    size = marker_side(BAR_PLATE_SIDE)
    return (
        MarkerSpec(ids[0], size, (-x, 0.0, top, 0.0, 0.0, 0.0)),
        MarkerSpec(ids[1], size, (x, 0.0, top, 0.0, 0.0, 0.0)),
    )


TARGET_BAR_MARKERS = _bar_markers(TARGET_BAR_IDS)
"""The target bar's markers (bar frame)."""

OTHER_BAR_MARKERS = _bar_markers(OTHER_BAR_IDS)
"""The other bar's markers (bar frame)."""

BASE_MARKERS = tuple(
    MarkerSpec(marker_id, marker_side(BASE_PLATE_SIDE), (x, y, 0.001, 0.0, 0.0, 0.0))
    for marker_id, (x, y) in zip(
        BASE_IDS, ((0.13, 0.14), (0.27, 0.14), (0.13, 0.30), (0.27, 0.30)), strict=True
    )
)
"""The base markers on the mounting plate (robot base frame, z = 1 mm above the base plane)."""
