"""Digital twin of the DBM cell: the simulation plus a camera that sees ArUco markers.

:class:`TwinSim` is :class:`~distgprl.sim.tasks.dbm.DBMSim` (same physics, robot, conveyor,
bars, success criterion) with printed ArUco markers on the bars and on the robot's mounting
plate (layout in :mod:`distgprl.hardware.markers`) and a static pinhole camera rendered with
PyBullet's TinyRenderer. The markers are visual-only bodies (no collision shape) textured
with images from ``cv2.aruco.generateImageMarker``; the bar markers follow their bar before
every render. Images get configurable Gaussian pixel noise; the latency model lives in
:class:`~distgprl.hardware.backends.TwinBackend` (the world keeps moving while an image is
processed).

Sensor noise (:class:`SensorNoise`, levels :data:`SENSOR_NOISE`) makes the twin see like a
camera: a per-image exposure change (a gain, saturating at 255), Gaussian optical blur and
extra sensor noise on the image; Gaussian noise on the detected marker corners
(:class:`NoisyCornerPerception`); and a calibration error of the base marker plate (the
calibration file places it slightly off, :func:`miscalibrated`). Every effect draws from a
generator passed in; level 0 draws nothing and gives exactly the images of a twin without
sensor noise.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from distgprl.errors import UserInputError
from distgprl.hardware.markers import (
    BAR_PLATE_SIDE,
    BASE_MARKERS,
    BASE_PLATE_SIDE,
    CELLS_WITH_BORDER,
    CELLS_WITH_MARGIN,
    DICTIONARY,
    OTHER_BAR_MARKERS,
    TARGET_BAR_MARKERS,
    MarkerSpec,
)
from distgprl.hardware.perception import CellCalibration, MarkerPerception
from distgprl.io import atomic_write_bytes
from distgprl.sim.tasks.dbm import SCENE, DBMScene, DBMSim
from distgprl.sim.transforms import (
    make_transform,
    matrix_to_pose,
    matrix_to_quaternion,
    pose_to_matrix,
    quaternion_to_matrix,
    rotvec_to_matrix,
)

SHIPPED_CALIBRATION = Path(__file__).with_name("twin_calibration.yaml")
"""The calibration file of the default twin (:func:`twin_calibration` of ``TwinConfig()``)."""


@dataclass(frozen=True)
class SensorNoise:
    """Camera imperfections of the twin beyond its pixel noise (zeros: none).

    Attributes:
        exposure_std: std of the per-image exposure change, stops (gain ``2**N(0, std)``;
            bright pixels saturate at 255).
        blur_sigma_px: std of the Gaussian optical blur, px (0: sharp).
        pixel_noise_std: extra Gaussian sensor noise per pixel and channel (0..255 scale),
            after exposure and blur.
        corner_noise_px: std of Gaussian noise on every detected marker corner, px per axis.
        base_translation_mm: std of the base-plate calibration error per axis, mm (one draw
            per run: the cell is miscalibrated, not the image).
        base_rotation_deg: std of the base-plate calibration error per axis, degrees.
    """

    exposure_std: float = 0.0
    blur_sigma_px: float = 0.0
    pixel_noise_std: float = 0.0
    corner_noise_px: float = 0.0
    base_translation_mm: float = 0.0
    base_rotation_deg: float = 0.0

    @property
    def affects_image(self) -> bool:
        return bool(self.exposure_std or self.blur_sigma_px or self.pixel_noise_std)


_STRONG = SensorNoise(
    exposure_std=0.4,
    blur_sigma_px=1.5,
    pixel_noise_std=8.0,
    corner_noise_px=0.4,
    base_translation_mm=3.0,
    base_rotation_deg=0.5,
)


def _worse_calibration(noise: SensorNoise, factor: float) -> SensorNoise:
    """``noise``'s camera with its corner and base-plate calibration errors ``factor`` times
    larger."""
    return replace(
        noise,
        corner_noise_px=noise.corner_noise_px * factor,
        base_translation_mm=noise.base_translation_mm * factor,
        base_rotation_deg=noise.base_rotation_deg * factor,
    )


SENSOR_NOISE: dict[int, SensorNoise] = {
    0: SensorNoise(),
    1: SensorNoise(
        exposure_std=0.15,
        blur_sigma_px=0.7,
        pixel_noise_std=3.0,
        corner_noise_px=0.15,
        base_translation_mm=1.0,
        base_rotation_deg=0.2,
    ),
    2: _STRONG,
    # Levels 3 and 4 (issue 50 item 5): level 2's image degradation (more would stop the
    # markers being detected at all, a refusal rather than an error), with its calibration
    # and corner errors doubled and quadrupled, so that the median perception error passes the
    # DBM geometry's own scale: the bars are 50 mm wide along the belt (half-width 25 mm) and
    # as little as 10 mm apart, d_min is 30 mm; an error of about twice the half-width aims
    # the hook beside the bar, where no policy can succeed. Chosen from that geometry before
    # any trial at these levels was run.
    3: _worse_calibration(_STRONG, 2.0),
    4: _worse_calibration(_STRONG, 4.0),
}
"""``--sensor-noise`` levels: 0 none (today's twin), 1 mild (a good industrial camera
under changing light), 2 strong (cheap camera, poor light, a rushed calibration), 3 and 4
level 2's camera with a two and four times worse calibration (a cell knocked out of true:
the robustness curve's tail, where the policies break)."""


def sensor_noise_level(level: int) -> SensorNoise:
    """The :class:`SensorNoise` of a level (raises :class:`UserInputError` if unknown)."""
    if level not in SENSOR_NOISE:
        raise UserInputError(f"sensor noise level must be one of {sorted(SENSOR_NOISE)}")
    return SENSOR_NOISE[level]


def degrade_image(rgb: np.ndarray, noise: SensorNoise, rng: np.random.Generator) -> np.ndarray:
    """Exposure change, blur and sensor noise on a float image (h, w, 3), 0..255 scale."""
    import cv2

    out = np.asarray(rgb, dtype=float)
    if noise.exposure_std > 0:
        out = out * 2.0 ** rng.normal(0.0, noise.exposure_std)
    if noise.blur_sigma_px > 0:
        out = cv2.GaussianBlur(out, (0, 0), noise.blur_sigma_px)
    if noise.pixel_noise_std > 0:
        out = out + rng.normal(0.0, noise.pixel_noise_std, size=out.shape)
    return out


def miscalibrated(
    calibration: CellCalibration, noise: SensorNoise, rng: np.random.Generator
) -> CellCalibration:
    """``calibration`` with the base marker plate moved by one random rigid error.

    The error (translation ``N(0, base_translation_mm)`` per axis, rotation vector
    ``N(0, base_rotation_deg)`` per axis, about the plate's centre) is what a real
    calibration of the plate gets wrong; unchanged (and nothing drawn) when both are zero.
    """
    if not (noise.base_translation_mm or noise.base_rotation_deg):
        return calibration
    translation = rng.normal(0.0, noise.base_translation_mm / 1000.0, 3)
    rotation = rotvec_to_matrix(np.radians(rng.normal(0.0, noise.base_rotation_deg, 3)))
    centre = np.mean([np.asarray(m.pose[:3]) for m in calibration.base_markers], axis=0)
    error = make_transform(rotation, centre + translation) @ make_transform(np.eye(3), -centre)
    markers = tuple(
        replace(m, pose=_pose_tuple(matrix_to_pose(error @ pose_to_matrix(m.pose))))
        for m in calibration.base_markers
    )
    return replace(calibration, base_markers=markers)


def _pose_tuple(pose: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """A pose (6,) as a `MarkerSpec` pose: six floats."""
    x, y, z, rx, ry, rz = (float(v) for v in pose)
    return (x, y, z, rx, ry, rz)


class NoisyCornerPerception(MarkerPerception):
    """:class:`MarkerPerception` whose detected corners get Gaussian noise (px).

    Args:
        calibration: as :class:`MarkerPerception`.
        corner_noise_px: std of the noise per corner and axis, px.
        rng: generator for the noise.
    """

    def __init__(
        self, calibration: CellCalibration, corner_noise_px: float, rng: np.random.Generator
    ) -> None:
        super().__init__(calibration)
        self.corner_noise_px = float(corner_noise_px)
        self.rng = rng

    def detect(self, image: np.ndarray) -> dict[int, np.ndarray]:
        corners = super().detect(image)
        return {
            marker: c + self.rng.normal(0.0, self.corner_noise_px, c.shape)
            for marker, c in sorted(corners.items())
        }


@dataclass(frozen=True)
class TwinConfig:
    """Camera and sensor settings of the twin.

    Attributes:
        width, height: image size, px.
        fov_deg: vertical field of view, degrees.
        camera_eye: camera centre (3,), m, robot base frame.
        camera_target: point the optical axis goes through (3,), m.
        pixel_noise_std: std of additive Gaussian noise per pixel and channel (0..255 scale).
        latency_s: time (s) between taking an image and its perception being available;
            the world keeps moving meanwhile (the robot holds still).
        texture_pixels_per_cell: marker texture resolution.
        supersample: the image is rendered this many times larger per side and averaged
            down, which integrates light over each pixel's area like a real sensor
            (TinyRenderer samples one point per pixel: hard, aliased edges bias corners).
        noise: camera imperfections beyond the pixel noise (:class:`SensorNoise`).
    """

    width: int = 1920
    height: int = 1440
    fov_deg: float = 45.0
    camera_eye: tuple[float, float, float] = (0.5, 0.45, 0.85)
    camera_target: tuple[float, float, float] = (0.45, -0.12, 0.05)
    pixel_noise_std: float = 2.0
    latency_s: float = 0.0
    texture_pixels_per_cell: int = 64
    supersample: int = 1
    noise: SensorNoise = field(default_factory=SensorNoise)

    def intrinsics(self) -> np.ndarray:
        """OpenCV camera matrix (3, 3), px (pixel centres at integer coordinates)."""
        fy = 0.5 * self.height / math.tan(math.radians(self.fov_deg) / 2.0)
        return np.array(
            [[fy, 0.0, self.width / 2.0 - 0.5], [0.0, fy, self.height / 2.0 - 0.5], [0, 0, 1.0]]
        )

    def base_from_camera(self) -> np.ndarray:
        """Camera pose (4, 4) in the robot base frame, OpenCV axes (x right, y down, z ahead)."""
        eye = np.asarray(self.camera_eye, dtype=float)
        forward = np.asarray(self.camera_target, dtype=float) - eye
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        return make_transform(np.stack([right, down, forward], axis=1), eye)


def twin_calibration(config: TwinConfig = TwinConfig(), scene: DBMScene = SCENE) -> CellCalibration:
    """The exact calibration of a twin camera (what a perfect real calibration would give)."""
    return CellCalibration(
        width=config.width,
        height=config.height,
        camera_matrix=config.intrinsics(),
        distortion=np.zeros(5),
        dictionary=DICTIONARY,
        base_markers=BASE_MARKERS,
        object_markers={"target_bar": TARGET_BAR_MARKERS, "other_bar": OTHER_BAR_MARKERS},
        conveyor_velocity=(0.0, float(scene.belt_speed), 0.0),
    )


@lru_cache(maxsize=64)
def marker_texture(marker_id: int, pixels_per_cell: int, dictionary: str = DICTIONARY) -> str:
    """PNG path of a marker with a one-cell white margin (written once per process)."""
    import cv2

    aruco = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    side = CELLS_WITH_BORDER * pixels_per_cell
    marker = cv2.aruco.generateImageMarker(aruco, int(marker_id), side)
    margin = (CELLS_WITH_MARGIN - CELLS_WITH_BORDER) // 2 * pixels_per_cell
    plate = np.full((side + 2 * margin, side + 2 * margin), 255, dtype=np.uint8)
    plate[margin : margin + side, margin : margin + side] = marker
    folder = Path(tempfile.gettempdir()) / f"distgprl-aruco-{os.getuid()}"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{dictionary}_{marker_id}_{pixels_per_cell}.png"
    if not path.exists():
        ok, png = cv2.imencode(".png", cv2.cvtColor(plate, cv2.COLOR_GRAY2BGR))
        if not ok:
            raise RuntimeError(f"OpenCV could not encode marker {marker_id} as PNG")
        atomic_write_bytes(path, png.tobytes())
    return str(path)


class TwinSim(DBMSim):
    """DBM simulation with ArUco markers and a camera (see the module docstring).

    Args:
        twin: camera and sensor settings.
        scene: DBM geometry.
        **kwargs: forwarded to :class:`~distgprl.sim.tasks.base.TaskSim`.
    """

    def __init__(self, twin: TwinConfig = TwinConfig(), scene: DBMScene = SCENE, **kwargs) -> None:
        self.twin = twin
        super().__init__(scene=scene, **kwargs)

    # -- scene ---------------------------------------------------------------------------------
    def _plate_body(self, spec: MarkerSpec, plate_side: float, world: np.ndarray) -> int:
        import pybullet  # after distgprl.sim's quiet import (no build banner)

        client = self.client
        # A grid with one vertex per marker cell corner: TinyRenderer interpolates texture
        # coordinates affinely per triangle, so only vertices land exactly where they should;
        # with the grid, every corner of the black border is a vertex.
        cells = CELLS_WITH_MARGIN
        grid = np.linspace(0.0, 1.0, cells + 1)
        u, v = np.meshgrid(grid, grid, indexing="xy")
        vertices = np.stack(
            [(u.ravel() - 0.5) * plate_side, (v.ravel() - 0.5) * plate_side, 0.0 * u.ravel()], 1
        )
        # TinyRenderer samples texture row 0 at v = 1: v grows with marker +y
        uvs = np.stack([u.ravel(), v.ravel()], axis=1)
        indices = []
        for row in range(cells):
            for col in range(cells):
                a = row * (cells + 1) + col
                b, c, d = a + 1, a + cells + 2, a + cells + 1
                indices += [a, b, c, a, c, d]
        visual = client.createVisualShape(
            pybullet.GEOM_MESH,
            vertices=vertices.tolist(),
            indices=indices,
            uvs=uvs.tolist(),
            normals=[[0.0, 0.0, 1.0]] * len(vertices),
            rgbaColor=[1.0, 1.0, 1.0, 1.0],
        )
        body = client.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=-1,
            baseVisualShapeIndex=visual,
            basePosition=world[:3, 3].tolist(),
            baseOrientation=matrix_to_quaternion(world[:3, :3]).tolist(),
        )
        texture = client.loadTexture(
            marker_texture(spec.marker_id, self.twin.texture_pixels_per_cell)
        )
        client.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=[1, 1, 1, 1])
        return body

    def _build_scene(self) -> None:
        super()._build_scene()
        self.marker_bodies: dict[int, int] = {}
        for spec in BASE_MARKERS:
            world = pose_to_matrix(np.asarray(spec.pose))
            self.marker_bodies[spec.marker_id] = self._plate_body(spec, BASE_PLATE_SIDE, world)
        self._bar_markers = (
            (self.object_body, TARGET_BAR_MARKERS),
            (self.other_bar_body, OTHER_BAR_MARKERS),
        )
        for body, specs in self._bar_markers:
            bar = self._body_transform(body)
            for spec in specs:
                world = bar @ pose_to_matrix(np.asarray(spec.pose))
                self.marker_bodies[spec.marker_id] = self._plate_body(spec, BAR_PLATE_SIDE, world)

    def _body_transform(self, body: int) -> np.ndarray:
        position, quaternion = self.client.getBasePositionAndOrientation(body)
        return make_transform(quaternion_to_matrix(quaternion), position)

    def _sync_markers(self) -> None:
        for body, specs in self._bar_markers:
            bar = self._body_transform(body)
            for spec in specs:
                world = bar @ pose_to_matrix(np.asarray(spec.pose))
                self.client.resetBasePositionAndOrientation(
                    self.marker_bodies[spec.marker_id],
                    world[:3, 3].tolist(),
                    matrix_to_quaternion(world[:3, :3]).tolist(),
                )

    # -- ground truth ----------------------------------------------------------------------------
    def object_transforms(self) -> dict[str, np.ndarray]:
        """True robot-base-from-bar transforms (4, 4), m, of ``target_bar`` and ``other_bar``."""
        return {
            "target_bar": self._body_transform(self.object_body),
            "other_bar": self._body_transform(self.other_bar_body),
        }

    def marker_transform(self, marker_id: int) -> np.ndarray:
        """True robot-base-from-marker transform (4, 4) of a marker (after a render sync)."""
        self._sync_markers()
        return self._body_transform(self.marker_bodies[marker_id])

    # -- camera ----------------------------------------------------------------------------------
    def capture(
        self, rng: np.random.Generator | None = None, noise_rng: np.random.Generator | None = None
    ) -> np.ndarray:
        """A camera image (height, width, 3) uint8 of the current state.

        Args:
            rng: generator for the pixel noise (``pixel_noise_std``); None = no noise.
            noise_rng: generator for the image effects of ``twin.noise`` (exposure, blur,
                extra noise), applied before the pixel noise; None = none of them.
        """
        import pybullet  # after distgprl.sim's quiet import (no build banner)

        self._sync_markers()
        twin = self.twin
        client = self.client
        view = client.computeViewMatrix(
            cameraEyePosition=list(twin.camera_eye),
            cameraTargetPosition=list(twin.camera_target),
            cameraUpVector=[0.0, 0.0, 1.0],
        )
        projection = client.computeProjectionMatrixFOV(
            fov=twin.fov_deg, aspect=twin.width / twin.height, nearVal=0.05, farVal=5.0
        )
        factor = max(1, int(twin.supersample))
        width, height = twin.width * factor, twin.height * factor
        image = client.getCameraImage(
            width,
            height,
            view,
            projection,
            renderer=pybullet.ER_TINY_RENDERER,
            shadow=0,
            lightDirection=[0.3, -0.2, 1.0],
        )
        rgba = np.asarray(image[2], dtype=np.uint8).reshape(height, width, 4)[:, :, :3]
        rgb = rgba.reshape(twin.height, factor, twin.width, factor, 3).mean(axis=(1, 3))
        if noise_rng is not None and twin.noise.affects_image:
            rgb = degrade_image(rgb, twin.noise, noise_rng)
        if rng is not None and twin.pixel_noise_std > 0:
            noisy = rgb + rng.normal(0.0, twin.pixel_noise_std, size=rgb.shape)
            rgb = noisy
        return np.ascontiguousarray(np.clip(np.rint(rgb), 0, 255).astype(np.uint8))
