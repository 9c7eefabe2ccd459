"""ArUco perception of the DBM cell: camera calibration file, marker detection, bar poses.

Pipeline (one image -> :class:`Percept`):

1. :class:`cv2.aruco.ArucoDetector` (OpenCV >= 4.7 API) finds the markers, corners refined
   to sub-pixel accuracy.
2. The camera-to-base transform comes from the base markers: one ``cv2.solvePnP`` over the
   corners of all visible base markers, whose corner positions in the robot base frame are
   known from the calibration file. The camera is static, so :class:`MarkerPerception`
   keeps the last transform when the arm hides the base markers.
3. Each bar's pose comes from one ``solvePnP`` over the corners of its visible markers
   (their corner positions in the bar frame are known), then is mapped to the robot base
   frame with the transform of step 2.

Calibration file (YAML or JSON, same keys; see ``twin_calibration.yaml`` shipped next to
this module for the digital twin's cell)::

    format: distgprl-cell-calibration/1
    camera:
      width: 640                    # image size the intrinsics belong to, px
      height: 480
      camera_matrix: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]   # px
      distortion: [k1, k2, p1, p2, k3]                      # OpenCV model
    aruco:
      dictionary: DICT_4X4_50       # any cv2.aruco predefined dictionary name
    markers:                        # size = black-border side, m; pose = x y z rx ry rz
      base:                         #   in the robot base frame (m, rad)
        - {id: 0, size: 0.075, pose: [0.22, 0.18, 0.001, 0, 0, 0]}
      target_bar:                   #   in the bar frame (base-box centre, axes as the
        - {id: 10, size: 0.033, pose: [-0.0575, 0, 0.0105, 0, 0, 0]}   # robot base)
      other_bar:
        - {id: 20, size: 0.033, pose: [-0.0575, 0, 0.0105, 0, 0, 0]}
    conveyor_velocity: [0.0, 0.04, 0.0]   # belt velocity in the robot base frame, m/s

Marker frames follow OpenCV (origin at the marker centre, x right, y up in the marker image,
z out of the face). Bar frames: origin at the centre of the bar's base box, x across the
conveyor, y along the belt, z up.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.errors import UserInputError
from distgprl.hardware.markers import (
    BASE_MARKERS,
    DICTIONARY,
    OTHER_BAR_MARKERS,
    TARGET_BAR_MARKERS,
    MarkerSpec,
)
from distgprl.io import atomic_write_text
from distgprl.sim.transforms import invert_transform, matrix_to_rotvec, rotvec_to_matrix

CALIBRATION_FORMAT = "distgprl-cell-calibration/1"
OBJECTS = ("target_bar", "other_bar")
"""The tracked objects, in the order of the calibration's ``markers`` section."""


@dataclass(frozen=True)
class CellCalibration:
    """Camera intrinsics and the cell's marker layout.

    Attributes:
        width, height: image size (px) the intrinsics belong to.
        camera_matrix: (3, 3) pinhole matrix, px.
        distortion: OpenCV distortion coefficients, shape (k,) with k in {4, 5, 8, 12, 14}.
        dictionary: OpenCV predefined ArUco dictionary name.
        base_markers: markers fixed in the robot base frame.
        object_markers: per tracked object (``target_bar``, ``other_bar``), its markers in
            the object's frame.
        conveyor_velocity: belt velocity (3,), m/s, robot base frame (used to predict bar
            motion between an image and its use).
    """

    width: int
    height: int
    camera_matrix: np.ndarray
    distortion: np.ndarray
    dictionary: str = DICTIONARY
    base_markers: tuple[MarkerSpec, ...] = BASE_MARKERS
    object_markers: dict[str, tuple[MarkerSpec, ...]] = field(
        default_factory=lambda: {"target_bar": TARGET_BAR_MARKERS, "other_bar": OTHER_BAR_MARKERS}
    )
    conveyor_velocity: tuple[float, float, float] = (0.0, 0.04, 0.0)

    def to_dict(self) -> dict[str, Any]:
        """The file form (see the module docstring)."""

        def markers(specs):
            return [
                {"id": int(m.marker_id), "size": float(m.size), "pose": [float(v) for v in m.pose]}
                for m in specs
            ]

        return {
            "format": CALIBRATION_FORMAT,
            "camera": {
                "width": int(self.width),
                "height": int(self.height),
                "camera_matrix": np.asarray(self.camera_matrix, dtype=float).tolist(),
                "distortion": np.asarray(self.distortion, dtype=float).tolist(),
            },
            "aruco": {"dictionary": self.dictionary},
            "markers": {
                "base": markers(self.base_markers),
                **{name: markers(self.object_markers[name]) for name in OBJECTS},
            },
            "conveyor_velocity": [float(v) for v in self.conveyor_velocity],
        }

    def scaled_to(self, width: int, height: int) -> CellCalibration:
        """The same camera at another resolution (intrinsics scaled; same aspect ratio)."""
        if (width, height) == (self.width, self.height):
            return self
        sx, sy = width / self.width, height / self.height
        if not math.isclose(sx, sy, rel_tol=1e-3):
            raise UserInputError(
                f"image size {width}x{height} has another aspect ratio than the calibration's "
                f"{self.width}x{self.height}"
            )
        matrix = np.asarray(self.camera_matrix, dtype=float).copy()
        matrix[0, :] *= sx
        matrix[1, :] *= sy
        # OpenCV pixel centres are at integer coordinates: scale about the -0.5 px corner.
        matrix[0, 2] = (self.camera_matrix[0][2] + 0.5) * sx - 0.5
        matrix[1, 2] = (self.camera_matrix[1][2] + 0.5) * sy - 0.5
        return CellCalibration(
            width,
            height,
            matrix,
            np.asarray(self.distortion, dtype=float),
            self.dictionary,
            self.base_markers,
            self.object_markers,
            self.conveyor_velocity,
        )


def _marker_list(entries: Any, where: str) -> tuple[MarkerSpec, ...]:
    if not isinstance(entries, list) or not entries:
        raise UserInputError(f"{where}: must be a non-empty list of markers")
    out = []
    for k, entry in enumerate(entries):
        try:
            marker_id = int(entry["id"])
            size = float(entry["size"])
            pose = tuple(float(v) for v in entry["pose"])
        except (KeyError, TypeError, ValueError):
            raise UserInputError(
                f"{where}[{k}]: each marker needs id (int), size (m) and pose (6 numbers)"
            ) from None
        if len(pose) != 6 or not all(math.isfinite(v) for v in pose):
            raise UserInputError(f"{where}[{k}]: pose must be 6 finite numbers (x y z rx ry rz)")
        if not 0.0 < size < 1.0:
            raise UserInputError(f"{where}[{k}]: size {size} m is not a marker side length")
        out.append(MarkerSpec(marker_id, size, pose))
    return tuple(out)


def calibration_from_dict(data: Any, where: str = "calibration") -> CellCalibration:
    """Validate and convert the file form; raises :class:`UserInputError` naming the key."""
    import cv2

    if not isinstance(data, dict):
        raise UserInputError(f"{where}: not a mapping")
    if data.get("format") != CALIBRATION_FORMAT:
        raise UserInputError(
            f"{where}: format must be {CALIBRATION_FORMAT!r}, got {data.get('format')!r}"
        )
    try:
        camera = data["camera"]
        width, height = int(camera["width"]), int(camera["height"])
        matrix = np.asarray(camera["camera_matrix"], dtype=float)
        distortion = np.asarray(camera.get("distortion", [0.0] * 5), dtype=float).reshape(-1)
        markers = data["markers"]
    except (KeyError, TypeError, ValueError) as exc:
        raise UserInputError(
            f"{where}: missing or malformed camera/markers entry ({exc})"
        ) from None
    if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)) or matrix[0, 0] <= 0:
        raise UserInputError(f"{where}: camera.camera_matrix must be a 3x3 matrix with fx > 0")
    if distortion.size not in (4, 5, 8, 12, 14):
        raise UserInputError(f"{where}: camera.distortion must have 4, 5, 8, 12 or 14 values")
    if width <= 0 or height <= 0:
        raise UserInputError(f"{where}: camera.width and camera.height must be positive")
    dictionary = str((data.get("aruco") or {}).get("dictionary", DICTIONARY))
    if not hasattr(cv2.aruco, dictionary):
        raise UserInputError(
            f"{where}: aruco.dictionary {dictionary!r} is not an OpenCV dictionary"
        )
    if not isinstance(markers, dict):
        raise UserInputError(f"{where}: markers must map base/target_bar/other_bar to lists")
    base = _marker_list(markers.get("base"), f"{where}: markers.base")
    objects = {
        name: _marker_list(markers.get(name), f"{where}: markers.{name}") for name in OBJECTS
    }
    ids = [m.marker_id for m in base] + [m.marker_id for n in OBJECTS for m in objects[n]]
    if len(set(ids)) != len(ids):
        raise UserInputError(f"{where}: marker ids must be unique, got {ids}")
    velocity = tuple(float(v) for v in data.get("conveyor_velocity", (0.0, 0.0, 0.0)))
    if len(velocity) != 3:
        raise UserInputError(f"{where}: conveyor_velocity must be 3 numbers (m/s)")
    return CellCalibration(
        width,
        height,
        matrix,
        distortion,
        dictionary,
        base,
        objects,
        velocity,
    )


def load_calibration(path: str | Path) -> CellCalibration:
    """Read a calibration file (``.yaml``/``.yml`` or ``.json``)."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"{path}: calibration file not found")
    text = path.read_text()
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        raise UserInputError(f"{path}: not valid {path.suffix[1:].upper()} ({exc})") from None
    return calibration_from_dict(data, str(path))


def save_calibration(path: str | Path, calibration: CellCalibration) -> Path:
    """Write a calibration file (YAML unless the suffix is ``.json``), atomically."""
    import yaml

    path = Path(path)
    data = calibration.to_dict()
    if path.suffix.lower() == ".json":
        text = json.dumps(data, indent=2) + "\n"
    else:
        text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
    return atomic_write_text(path, text)


# ----------------------------------------------------------------------------- detection
@dataclass(frozen=True)
class ObjectPose:
    """A perceived object pose.

    Attributes:
        transform: robot-base-from-object transform (4, 4), m.
        markers: ids of the markers the pose was solved from.
        reprojection_px: RMS corner reprojection error, px.
    """

    transform: np.ndarray
    markers: tuple[int, ...]
    reprojection_px: float

    @property
    def position(self) -> np.ndarray:
        """Object origin (3,), m, robot base frame."""
        return self.transform[:3, 3].copy()

    @property
    def rotvec(self) -> np.ndarray:
        """Object orientation as a rotation vector (3,), rad."""
        return matrix_to_rotvec(self.transform[:3, :3])


@dataclass(frozen=True)
class Percept:
    """What one image says about the cell.

    Attributes:
        stamp: capture time of the image on the backend's clock, s.
        camera_from_base: (4, 4) transform used (fresh or remembered), m.
        base_visible: whether the base markers were seen in this image.
        objects: detected objects by name (missing = not seen in this image).
        detected_ids: every marker id found in the image.
        detection_ms: wall time of detection + pose solving, ms.
    """

    stamp: float
    camera_from_base: np.ndarray
    base_visible: bool
    objects: dict[str, ObjectPose]
    detected_ids: tuple[int, ...]
    detection_ms: float


def _to_transform(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3] = rotvec_to_matrix(np.asarray(rvec, dtype=float).reshape(3))
    transform[:3, 3] = np.asarray(tvec, dtype=float).reshape(3)
    return transform


def _solve(
    markers: list[MarkerSpec],
    corners: dict[int, np.ndarray],
    calibration: CellCalibration,
    prior_rotation: np.ndarray | None = None,
) -> tuple[np.ndarray, float] | None:
    """camera-from-parent transform (4, 4) and RMS reprojection error (px) of ``markers``
    (None if no candidate converged in front of the camera).

    Each visible marker gives the two IPPE solutions of its square (solved in the marker
    frame, then moved to the parent frame with the marker's pose); every candidate is
    refined by Levenberg-Marquardt over the corners of *all* visible markers, and the one
    with the smallest reprojection error wins. Several markers spread over an object (or
    the base plate) resolve the planar pose ambiguity of a single small marker. When one
    marker alone leaves two near-equal candidates (reprojection errors within 0.2 px), the
    one closer to ``prior_rotation`` (camera-from-parent, (3, 3); e.g. the last track or a
    bar lying flat) wins.
    """
    import cv2

    from distgprl.sim.transforms import pose_to_matrix

    matrix = np.asarray(calibration.camera_matrix, dtype=float)
    distortion = np.asarray(calibration.distortion, dtype=float)
    object_points = np.concatenate([m.corners() for m in markers])
    image_points = np.concatenate([corners[m.marker_id] for m in markers])
    candidates: list[tuple[np.ndarray, float]] = []
    for marker in markers:
        half = marker.size / 2.0
        square = np.array(
            [[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0], [-half, -half, 0.0]]
        )
        count, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            square, corners[marker.marker_id], matrix, distortion, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        marker_from_parent = invert_transform(pose_to_matrix(np.asarray(marker.pose)))
        for k in range(count):
            camera_from_parent = _to_transform(rvecs[k], tvecs[k]) @ marker_from_parent
            rvec = cv2.Rodrigues(camera_from_parent[:3, :3])[0]
            tvec = camera_from_parent[:3, 3].reshape(3, 1).copy()
            rvec, tvec = cv2.solvePnPRefineLM(
                object_points, image_points, matrix, distortion, rvec, tvec
            )
            candidate = _to_transform(rvec, tvec)
            depth = object_points @ candidate[2, :3] + candidate[2, 3]
            if not np.all(np.isfinite(candidate)) or np.any(depth <= 0.0):
                continue  # diverged, or the points would be behind the camera
            projected, _ = cv2.projectPoints(object_points, rvec, tvec, matrix, distortion)
            residual = projected.reshape(-1, 2) - image_points
            error = float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))
            candidates.append((candidate, error))
    if not candidates:
        return None
    candidates.sort(key=lambda c: c[1])
    if prior_rotation is not None:
        close = [c for c in candidates if c[1] <= candidates[0][1] + 0.2]

        def angle(c):
            return np.arccos(np.clip((np.trace(c[0][:3, :3].T @ prior_rotation) - 1) / 2, -1, 1))

        return min(close, key=angle)
    return candidates[0]


class MarkerPerception:
    """ArUco detection + PnP for the DBM cell (see the module docstring).

    Args:
        calibration: camera intrinsics and marker layout; images of another size than the
            calibration's are handled by scaling the intrinsics (same aspect ratio).
        max_reprojection_px: poses with a larger RMS reprojection error are rejected.
    """

    def __init__(self, calibration: CellCalibration, max_reprojection_px: float = 3.0) -> None:
        import cv2

        self.calibration = calibration
        self.max_reprojection_px = max_reprojection_px
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, calibration.dictionary))
        parameters = cv2.aruco.DetectorParameters()
        parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        parameters.cornerRefinementWinSize = 3
        parameters.cornerRefinementMaxIterations = 50
        parameters.cornerRefinementMinAccuracy = 0.01
        self._detector = cv2.aruco.ArucoDetector(dictionary, parameters)
        self.camera_from_base: np.ndarray | None = None
        self._last_rotation: dict[str, np.ndarray] = {}

    def reset_tracks(self) -> None:
        """Forget the last object orientations (new trial); keeps the camera-to-base transform."""
        self._last_rotation.clear()

    def _calibration_for(self, image: np.ndarray) -> CellCalibration:
        height, width = image.shape[:2]
        return self.calibration.scaled_to(width, height)

    def detect(self, image: np.ndarray) -> dict[int, np.ndarray]:
        """Marker corners by id, each (4, 2) px in OpenCV order, for an RGB/grey uint8 image."""
        import cv2

        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        corners, ids, _ = self._detector.detectMarkers(grey)
        if ids is None:
            return {}
        return {
            int(i): c.reshape(4, 2).astype(np.float64)
            for i, c in zip(ids.ravel(), corners, strict=True)
        }

    def _solve_markers(
        self,
        specs: tuple[MarkerSpec, ...],
        corners: dict[int, np.ndarray],
        calibration,
        prior_rotation: np.ndarray | None = None,
    ) -> tuple[np.ndarray, float, tuple[int, ...]] | None:
        seen = [m for m in specs if m.marker_id in corners]
        if not seen:
            return None
        solved = _solve(seen, corners, calibration, prior_rotation)
        if solved is None or solved[1] > self.max_reprojection_px:
            return None
        transform, error = solved
        return transform, error, tuple(m.marker_id for m in seen)

    def locate_base(self, image: np.ndarray) -> np.ndarray | None:
        """camera-from-base transform (4, 4) from the base markers, or None if not seen."""
        calibration = self._calibration_for(image)
        solved = self._solve_markers(calibration.base_markers, self.detect(image), calibration)
        return None if solved is None else solved[0]

    def perceive(self, image: np.ndarray, stamp: float) -> Percept:
        """Detect markers and return the bar poses in the robot base frame.

        Raises:
            UserInputError: the base markers were never seen (no camera-to-base transform).
        """
        import time

        start = time.perf_counter()
        calibration = self._calibration_for(image)
        corners = self.detect(image)
        base = self._solve_markers(calibration.base_markers, corners, calibration)
        if base is not None:
            self.camera_from_base = base[0]
        if self.camera_from_base is None:
            raise UserInputError(
                "base markers not visible: cannot place the camera relative to the robot "
                f"(looked for ids {[m.marker_id for m in calibration.base_markers]}, "
                f"saw {sorted(corners)}); check the camera view and the calibration file"
            )
        base_from_camera = invert_transform(self.camera_from_base)
        objects = {}
        for name in OBJECTS:
            # prior: the last pose of this object, else lying flat (bar axes = base axes)
            last = self._last_rotation.get(name, np.eye(3))
            prior = self.camera_from_base[:3, :3] @ last
            solved = self._solve_markers(
                calibration.object_markers[name], corners, calibration, prior
            )
            if solved is not None:
                camera_from_object, error, used = solved
                objects[name] = ObjectPose(base_from_camera @ camera_from_object, used, error)
                self._last_rotation[name] = objects[name].transform[:3, :3].copy()
        return Percept(
            stamp=float(stamp),
            camera_from_base=self.camera_from_base.copy(),
            base_visible=base is not None,
            objects=objects,
            detected_ids=tuple(sorted(corners)),
            detection_ms=1000.0 * (time.perf_counter() - start),
        )


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(translation error m, rotation error deg) between two (4, 4) transforms."""
    translation = float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))
    relative = estimate[:3, :3].T @ truth[:3, :3]
    cosine = np.clip((np.trace(relative) - 1.0) / 2.0, -1.0, 1.0)
    return translation, float(np.degrees(np.arccos(cosine)))
