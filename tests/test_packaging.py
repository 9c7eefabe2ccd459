"""The built wheel (pyproject.toml): it holds every file the package reads at run time
(demonstrations, presets, the twin's calibration) and nothing generated, and its metadata
declares ranges, not the exact pins of constraints.txt."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> zipfile.ZipFile:
    """The wheel `pip wheel --no-deps .` builds, from a copy of the package sources (so no
    build/ or egg-info folder of the checkout is read or left behind)."""
    source = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(REPO / name, source / name)
    shutil.copytree(
        REPO / "distgprl", source / "distgprl", ignore=shutil.ignore_patterns("__pycache__")
    )
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(out), str(source)],
        check=True, capture_output=True, timeout=300,
    )  # fmt: skip
    (path,) = out.glob("distgprl-*.whl")
    return zipfile.ZipFile(path)


def test_wheel_holds_every_run_time_file_of_the_package(wheel):
    names = set(wheel.namelist())
    data = {
        str(p.relative_to(REPO)).replace("\\", "/")
        for p in (REPO / "distgprl").rglob("*")
        if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts
    }
    assert data, "the package has data files"
    assert data <= names, sorted(data - names)
    for required in (
        "distgprl/presets/paper.yaml",
        "distgprl/presets/ci.yaml",
        "distgprl/presets/operator-unit.yaml",
        "distgprl/data/demos/dcp.csv",
        "distgprl/data/demos/dbm.csv",
        "distgprl/data/demos/dcp_varied/tcs.json",
        "distgprl/data/demos/dbm_varied/demo_19.csv",
        "distgprl/hardware/twin_calibration.yaml",
        "distgprl/__main__.py",
        "distgprl-0.1.0.dist-info/licenses/LICENSE",
    ):
        assert required in names
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]


def test_wheel_ships_the_pep_561_marker(wheel):
    """``distgprl/py.typed`` is in the wheel (pyproject package-data), so type checkers of a
    project that installs distgprl read its annotations (PEP 561); it is the empty marker."""
    assert (REPO / "distgprl" / "py.typed").is_file()
    assert "distgprl/py.typed" in wheel.namelist()
    assert wheel.read("distgprl/py.typed") == b""


def test_wheel_urdf_comes_from_airo_models_which_it_requires(wheel):
    """The package ships no URDF of its own: the UR5e's (and its meshes) are airo-models'
    package data, a declared dependency; the tool is appended at run time (sim/robot.py)."""
    import airo_models

    arm = Path(airo_models.__file__).parent / "arms" / "ur5e"
    assert (arm / "ur5e.urdf").is_file()
    metadata = wheel.read("distgprl-0.1.0.dist-info/METADATA").decode()
    assert "Requires-Dist: airo-models" in metadata


def test_wheel_metadata_declares_ranges_and_no_unused_dependency(wheel):
    metadata = wheel.read("distgprl-0.1.0.dist-info/METADATA").decode()
    requires = [
        line.split(": ", 1)[1]
        for line in metadata.splitlines()
        if line.startswith("Requires-Dist:")
    ]
    base = [r for r in requires if "extra ==" not in r]
    assert not [r for r in base if "==" in r], base
    assert not [r for r in base if r.startswith(("rich", "movement-primitives"))], base
    assert any(r.startswith("movement-primitives") and 'extra == "dev"' in r for r in requires)
    assert any(r.startswith("ur-rtde") and "<" in r for r in requires)
    assert "Requires-Dist: torch<2.14,>=2.13" in metadata
