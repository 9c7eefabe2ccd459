"""Expert demonstrations regenerate byte-for-byte; render_episode writes images."""

from __future__ import annotations

import json

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.sim.experts import VARIED_COUNT, generate
from distgprl.sim.render import render_episode
from distgprl.sim.tasks import get_task
from distgprl.sim.tasks.base import TaskConfig
from distgprl.skill.demos import load_demonstration


@pytest.mark.parametrize("name", ["dcp", "dbm"])
def test_regenerating_demos_gives_identical_bytes(name, tmp_path):
    """`python -m distgprl.sim.experts` output equals the shipped files, byte for byte."""
    spec = get_task(name)
    generate(name, tmp_path)
    assert (tmp_path / f"{name}.csv").read_bytes() == spec.demo_path.read_bytes()
    shipped = spec.varied_demo_dir
    files = sorted(p.name for p in shipped.iterdir())
    assert files == sorted(p.name for p in (tmp_path / f"{name}_varied").iterdir())
    for file in files:
        assert (tmp_path / f"{name}_varied" / file).read_bytes() == (shipped / file).read_bytes()
    meta = json.loads((shipped / "tcs.json").read_text())
    assert len(meta["tcs"]) == len(meta["files"]) == VARIED_COUNT
    tcs = [TaskConfig.from_dict(d) for d in meta["tcs"]]
    assert len(set(tcs)) == VARIED_COUNT
    demo = load_demonstration(shipped / meta["files"][0])
    assert demo.poses.shape[1] == 6 and np.all(np.diff(demo.times) > 0)


def test_render_png_and_gif(tmp_path):
    """render_episode writes a non-empty PNG and a multi-frame GIF."""
    import imageio.v3 as iio

    png = render_episode("dcp", None, tmp_path / "dcp.png", width=96, height=72)
    image = iio.imread(tmp_path / "dcp.png")
    assert image.shape[:2] == (72, 96) and image.std() > 5.0
    assert png["success"] and not png["collision"]
    gif = render_episode("dbm", 3, tmp_path / "dbm.gif", width=64, height=48, frame_every=25)
    frames = iio.imread(tmp_path / "dbm.gif", index=None)
    assert frames.shape[0] == gif["frames"] >= 5


def test_render_rejects_bad_input(tmp_path):
    """Unknown task, TC index out of range, bad suffix, missing folder: UserInputError."""
    with pytest.raises(UserInputError):
        render_episode("nope", 0, tmp_path / "x.png")
    with pytest.raises(UserInputError, match="out of range"):
        render_episode("dcp", 100, tmp_path / "x.png")
    with pytest.raises(UserInputError):
        render_episode("dcp", 0, tmp_path / "x.jpg")
    with pytest.raises(UserInputError):
        render_episode("dcp", 0, tmp_path / "missing" / "x.png")
