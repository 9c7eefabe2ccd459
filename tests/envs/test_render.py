"""Rendering a trained policy's episode (distgprl/envs/render.py): the filmed episode is the
evaluated one, frames pair the adapted and the faded demonstration panels with their window
marked, and ``distgprl render --method M`` writes such a GIF for a run trained in tmp."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.envs.render import (
    WINDOW_COLOURS,
    RecordedEpisode,
    compose_frames,
    evaluation_tc,
    record_episode,
)
from distgprl.errors import UserInputError
from distgprl.experiments.factories import make_env
from distgprl.experiments.rollout import run_episode
from distgprl.experiments.training import train_run
from distgprl.identity import resolve_run


def _seeded_policy(env, seed=5):
    """Fixed non-zero actions (a new generator per episode: the same action sequence)."""
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)


def test_a_filmed_episode_has_the_outcome_its_evaluation_records():
    """Splitting each executed segment into filmed pieces changes nothing: success,
    collision, clearance and return equal `run_episode`'s on the same TC and actions."""
    run = resolve_run("dcp", "dist-gprl", 0, "ci")
    env = make_env(run)
    try:
        tc = evaluation_tc(env, 3)
        evaluated = run_episode(env, tc, _seeded_policy(env))
        filmed = record_episode(env, tc, _seeded_policy(env), width=64, height=48)
        again = run_episode(env, tc, _seeded_policy(env))  # the wrapper is gone
    finally:
        env.close()
    for key in ("success", "collision", "min_clearance", "min_signed_clearance"):
        assert float(filmed.info[key]) == evaluated[key] == again[key], key
    assert filmed.frames[0].shape == (48, 64, 3)
    assert filmed.windows[0] == -1 and filmed.windows[1:] == sorted(filmed.windows[1:])
    assert len(filmed.frames) == len(filmed.windows) > filmed.n_windows


def test_a_tc_index_outside_the_evaluation_tcs_is_refused():
    env = make_env(resolve_run("dcp", "demo", 0, "ci"))
    try:
        with pytest.raises(UserInputError, match="out of range"):
            evaluation_tc(env, 100)
    finally:
        env.close()


def _episode(n_frames, window_of, info, value=100):
    frames = [np.full((120, 200, 3), value, dtype=np.uint8) for _ in range(n_frames)]
    return RecordedEpisode(frames, [window_of(i) for i in range(n_frames)], 3, info)


def test_composed_frames_put_the_faded_demo_beside_and_hold_the_shorter_episode():
    """One frame per frame of the longer episode, each (h, 2w, 3): the left panel framed in
    its window's colour, the right panel the demonstration, lighter (faded to white)."""
    adapted = _episode(5, lambda i: i // 2 - (i == 0), {"success": True})
    demo = _episode(3, lambda i: i - 1, {"collision": True})
    frames = compose_frames(adapted, demo, "dist-gprl seed 0")
    assert len(frames) == 5 and frames[0].shape == (120, 400, 3)
    window = adapted.windows[3]
    assert tuple(frames[3][100, 1]) == WINDOW_COLOURS[window]  # the left panel's border
    inside_left, inside_right = frames[3][80:110, 40:80], frames[3][80:110, 240:280]
    assert inside_right.mean() > inside_left.mean() + 50
    np.testing.assert_array_equal(frames[3][:, 200:], frames[4][:, 200:])  # demo held at its end
    assert not np.array_equal(frames[3][:, :200], frames[4][:, :200])  # the adapted one goes on


@pytest.fixture(scope="module")
def trained_root(tmp_path_factory):
    """A `ci` dcp/dist-gprl seed-0 run of 120 steps (not evaluated)."""
    root = tmp_path_factory.mktemp("runs")
    train_run(
        "dcp",
        "dist-gprl",
        0,
        "ci",
        steps=120,
        root=root,
        show_progress=False,
        evaluate_after=False,
    )
    return root


def test_render_of_a_trained_run_writes_the_side_by_side_gif(trained_root, tmp_path):
    out = tmp_path / "run.gif"
    result = CliRunner().invoke(
        app,
        [
            "render", "--task", "dcp", "--method", "dist-gprl", "--seed", "0", "--tc", "2",
            "--preset", "ci", "--root", str(trained_root), "--out", str(out),
        ],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    line = result.output.strip().splitlines()[-1]
    assert line.startswith(f"wrote {out} (") and ": evaluation TC 2; dist-gprl seed 0: " in line
    assert "; demonstration: " in line and line.count(" mm") == 2
    frames = iio.imread(out)
    assert frames.ndim == 4 and frames.shape[0] > 3 and frames.shape[2] == 2 * 480
    left, right = frames[:, 60:, :480], frames[:, 60:, 480:]
    assert right.mean() > left.mean()  # the demonstration is the faded panel


def test_render_of_a_run_that_was_not_trained_is_a_clear_error(tmp_path):
    result = CliRunner().invoke(
        app,
        [
            "render", "--task", "dcp", "--method", "dist-gprl", "--preset", "ci",
            "--root", str(tmp_path), "--out", str(tmp_path / "x.gif"),
        ],
    )  # fmt: skip
    assert result.exit_code != 0
    assert "Traceback" not in result.output


def test_render_without_out_writes_the_run_named_png_in_the_current_folder(
    trained_root, tmp_path, monkeypatch
):
    """`render --task T --method M --seed S` alone (the README's command) writes one frame to
    ``T_M_seedS.png`` in the current folder and names it."""
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(
        app,
        [
            "render", "--task", "dcp", "--method", "dist-gprl", "--seed", "0",
            "--preset", "ci", "--root", str(trained_root),
        ],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1].startswith("wrote dcp_dist-gprl_seed0.png (1 ")
    assert iio.imread(tmp_path / "dcp_dist-gprl_seed0.png").ndim == 3


def test_render_of_the_demo_refuses_the_options_of_a_trained_run(tmp_path, monkeypatch):
    """``--method demo`` renders the GP skill from no run: ``--seed``, ``--preset``,
    ``--preset-file``, ``--root`` or ``--policy`` with it is a user error (exit 2, one line
    naming them) instead of dropped; ``--task``, ``--tc`` and ``--out`` still render."""
    import distgprl.envs.render as render

    rendered = []

    def fake_render_demo_episode(task, tc, out):
        rendered.append((task, tc, out))
        return {"tc_index": tc, "frames": 1, "success": 1, "collision": 0, "min_clearance": 0.02}

    monkeypatch.setattr(render, "render_demo_episode", fake_render_demo_episode)
    runner = CliRunner()
    out = tmp_path / "demo.png"
    for options in (
        ["--seed", "1"],
        ["--seed", "0"],
        ["--preset", "ci"],
        ["--preset-file", str(tmp_path / "mine.yaml")],
        ["--root", str(tmp_path)],
        ["--policy", "final"],
        ["--method", "demo", "--seed", "2", "--policy", "best"],
    ):
        result = runner.invoke(app, ["render", "--task", "dcp", "--out", str(out), *options])
        assert result.exit_code == 2, (options, result.output)
        assert result.output.strip().splitlines() == [
            f"error: {', '.join(o for o in options if o.startswith('--') and o != '--method')}:"
            " a trained run's (--method demo renders the GP skill alone, from no run): give a "
            "trained --method, or leave them out"
        ]
    assert rendered == []
    result = runner.invoke(app, ["render", "--task", "dcp", "--tc", "3", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert rendered == [("dcp", 3, out)]
