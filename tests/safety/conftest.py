"""Fixtures for the safety tests: a UR5e sphere model (`_sphere_robot`) checked against an
EDF scene, and a small HAP grid."""

from __future__ import annotations

import numpy as np
import pytest
from _sphere_robot import DOWN_YAW_45, SphereRobotChecker, scene_shapes

from distgprl.safety.edf import DistanceField
from distgprl.safety.hap_build import HapConfig


@pytest.fixture(scope="session")
def scene() -> tuple:
    return scene_shapes()


@pytest.fixture(scope="session")
def checker(scene) -> SphereRobotChecker:
    return SphereRobotChecker(DistanceField(scene))


@pytest.fixture(scope="session")
def small_config() -> HapConfig:
    """A small grid (5 x 7 x 3 positions x 2 orientations) so the build runs in seconds."""
    return HapConfig(
        workspace_lower=(0.3, -0.3, 0.2),
        workspace_upper=(0.7, 0.3, 0.4),
        grid_step=0.1,
        # Tool down, and tool down turned 45 degrees about the vertical (neighbouring layers).
        orientations=((np.pi, 0.0, 0.0), tuple(DOWN_YAW_45)),
        root_candidates=2,
    )
