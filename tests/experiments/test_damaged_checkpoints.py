"""Resuming from a damaged checkpoint (issue 52, item 3): a truncated or empty ``model.zip``
or replay buffer, or a buffer that no longer matches its manifest's SHA-256, makes
``--resume`` fall back to the previous good checkpoint, or restart the run from step 0 when
there is none, printing one line that names the damaged file and what was done, never a
traceback, and ending with the same model as a run that was never killed. An interrupt that
lands in or just after a save names the checkpoint on disk (the one a resume continues from).

The runs are a `ci`-like preset cut to the bone (a user preset, `--preset-file`'s code path):
checkpoints every 6 steps, 18 steps in all, a run trains in about a second."""

from __future__ import annotations

import json
import pickle
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.config import USER_PRESETS_ENV, register_preset
from distgprl.experiments import checkpoints, training
from distgprl.experiments.training import train_run
from distgprl.io import file_sha256
from distgprl.schema import read_csv, read_json, run_dir

TINY_PRESET = """\
# The smallest run that keeps two checkpoints: 6-step checkpoints and curve points.
sac:
  learning_starts: 3
  batch_size: 4
  buffer_size: 100
  net_arch: [16, 16]
run:
  total_steps: 18
  eval_every: 6
  curve_episodes: 1
  eval_episodes: 1
  checkpoint_every: 6
"""
METHOD = "dist-gprl"


@pytest.fixture(scope="module")
def preset_file(tmp_path_factory) -> Path:
    """The tiny preset's YAML file."""
    path = tmp_path_factory.mktemp("preset") / "tiny-checkpoints.yaml"
    path.write_text(TINY_PRESET)
    return path


@pytest.fixture(scope="module")
def preset(preset_file) -> str:
    """The tiny preset's name, registered for this module (and unregistered after it)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv(USER_PRESETS_ENV, raising=False)
        patch.delenv("DISTGPRL_CHECKPOINT_ROOT", raising=False)  # checkpoints under tmp
        yield register_preset(preset_file)


def train(root: Path, preset: str, resume: bool = False) -> Path:
    """Train the tiny dcp seed-0 run under ``root`` (no evaluation); its folder."""
    return train_run(
        "dcp",
        METHOD,
        0,
        preset=preset,
        root=root,
        show_progress=False,
        evaluate_after=False,
        resume=resume,
    )


def actor_parameters(folder: Path) -> list[np.ndarray]:
    """The actor's parameters of a run's final ``model.zip``."""
    from distgprl.agents.sac import RegularisedSAC

    model = RegularisedSAC.load_saved(folder / "model.zip")
    return [p.detach().numpy().copy() for p in model.actor.parameters()]


@pytest.fixture(scope="module")
def uninterrupted(preset, tmp_path_factory) -> list[np.ndarray]:
    """The actor of the tiny run trained once, never killed."""
    return actor_parameters(train(tmp_path_factory.mktemp("whole"), preset))


def kill_after_checkpoint(root: Path, preset: str, count: int, monkeypatch) -> Path:
    """Train the tiny run and kill it (as SIGINT would) right after its ``count``-th
    checkpoint is written; the run folder."""
    original, saves = training.save_checkpoint, []

    def save_then_die(folder, model, env, extra):
        original(folder, model, env, extra)
        saves.append(model.num_timesteps)
        if len(saves) == count:
            raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(training, "save_checkpoint", save_then_die)
        with pytest.raises(KeyboardInterrupt):
            train(root, preset)
    return run_dir(root, preset, "dcp", METHOD, 0)


def damage(path: Path, how: str) -> None:
    """Damage a checkpoint file in place: ``truncated`` keeps its first half, ``empty``
    leaves zero bytes."""
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2] if how == "truncated" else b"")


@dataclass(frozen=True)
class Resumed:
    """A resume over a damaged checkpoint (`resume_damaged`).

    Attributes:
        folder: the run folder.
        line: the one line the resume printed on stderr.
        record: the resume's record in done.json.
        spoiled: the damaged file.
        reached: the step the killed run's learning curve had reached.
    """

    folder: Path
    line: str
    record: dict
    spoiled: Path
    reached: int


def resume_damaged(
    tmp_path: Path, preset: str, monkeypatch, capsys, previous: bool, piece: str, spoil
) -> Resumed:
    """Kill the tiny run after its second checkpoint (``previous``: its first checkpoint is
    kept beside it) or its first, spoil the newest checkpoint's ``piece`` with ``spoil``,
    and resume it."""
    folder = kill_after_checkpoint(tmp_path, preset, 2 if previous else 1, monkeypatch)
    paths = checkpoints.checkpoint_paths(folder)
    assert paths["previous"].is_dir() == previous
    spoil(paths[piece])
    return resume(tmp_path, preset, capsys, paths[piece])


def resume(root: Path, preset: str, capsys, spoiled: Path) -> Resumed:
    """Resume the killed tiny run under ``root`` whose checkpoint file ``spoiled`` was
    damaged; it must print exactly one line on stderr."""
    folder = run_dir(root, preset, "dcp", METHOD, 0)
    reached = checkpoints.trained_steps(folder / "progress.csv")
    capsys.readouterr()
    train(root, preset, resume=True)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    [record] = read_json(folder / "done.json")["resumes"]
    return Resumed(folder, lines[0], record, spoiled, reached)


def check_outcome(resumed: Resumed, previous: bool, uninterrupted: list[np.ndarray]) -> None:
    """What a resume from a damaged checkpoint must leave: the line names the file and says
    what was done, done.json records it, the learning curve has each step once, the newest
    checkpoint verifies against its manifest, and the model equals the uninterrupted run's."""
    line, record = resumed.line, resumed.record
    assert line.startswith("warning: ") and "Traceback" not in line
    [damaged] = record["damaged"]
    assert damaged.startswith(f"{resumed.spoiled} ") and damaged in line
    if previous:
        assert record["exact"] and 6 <= record["step"] < 9  # the first checkpoint's step
        assert line.endswith(f"resumed from the previous checkpoint (step {record['step']})")
    else:
        assert record == {
            "step": 0,
            "exact": False,
            "restarted_after_step": resumed.reached,
            "damaged": [damaged],
        }
        assert line.endswith(f"reached step {resumed.reached}) restarts from step 0")
    _, progress = read_csv(resumed.folder / "progress.csv")
    assert [int(row["step"]) for row in progress] == [0, 6, 12, 18]
    paths = checkpoints.checkpoint_paths(resumed.folder)
    manifest = json.loads(paths["manifest"].read_text())
    assert manifest["num_timesteps"] == 18
    for name, entry in manifest["files"].items():
        assert file_sha256(paths["dir"] / name) == entry["sha256"], name
    for ours, reference in zip(actor_parameters(resumed.folder), uninterrupted, strict=True):
        np.testing.assert_array_equal(ours, reference)


@pytest.mark.parametrize("previous", [True, False], ids=["previous-kept", "only-checkpoint"])
@pytest.mark.parametrize("how", ["truncated", "empty"])
def test_a_damaged_model_falls_back_or_restarts(
    tmp_path, preset, uninterrupted, monkeypatch, capsys, how, previous
):
    """A truncated or zero-byte ``model.zip``: the resume uses the previous checkpoint (or
    restarts without one), says so in one line naming model.zip, and ends equal to the run
    that was never killed."""
    resumed = resume_damaged(
        tmp_path, preset, monkeypatch, capsys, previous, "model", lambda p: damage(p, how)
    )
    check_outcome(resumed, previous, uninterrupted)


@pytest.mark.parametrize("previous", [True, False], ids=["previous-kept", "only-checkpoint"])
@pytest.mark.parametrize("how", ["truncated", "empty"])
def test_a_damaged_replay_buffer_falls_back_or_restarts(
    tmp_path, preset, uninterrupted, monkeypatch, capsys, how, previous
):
    """A truncated or zero-byte ``replay_buffer.pkl``: the same, the line naming the
    buffer."""
    resumed = resume_damaged(
        tmp_path, preset, monkeypatch, capsys, previous, "buffer", lambda p: damage(p, how)
    )
    check_outcome(resumed, previous, uninterrupted)


def change_one_reward(path: Path) -> None:
    """Change the first stored reward of a pickled replay buffer in place: the file keeps
    its size and still loads (the change would go unnoticed but for the manifest)."""
    data = bytearray(path.read_bytes())
    rewards = pickle.loads(bytes(data)).rewards
    start = bytes(data).find(rewards.tobytes())
    assert start >= 0, "the rewards array is not stored in-band"
    changed = rewards.copy()
    changed.flat[0] += 1.0
    data[start : start + rewards.nbytes] = changed.tobytes()
    path.write_bytes(bytes(data))
    loaded = pickle.loads(path.read_bytes()).rewards
    assert loaded.flat[0] != rewards.flat[0]  # loadable, and silently different


@pytest.mark.parametrize("previous", [True, False], ids=["previous-kept", "only-checkpoint"])
def test_a_checkpoint_not_matching_its_manifest_falls_back_or_restarts(
    tmp_path, preset, uninterrupted, monkeypatch, capsys, previous
):
    """A replay buffer whose SHA-256 no longer matches the manifest (same size, loads, one
    reward changed): never resumed from; the line names the buffer and the hash mismatch."""
    resumed = resume_damaged(
        tmp_path, preset, monkeypatch, capsys, previous, "buffer", change_one_reward
    )
    assert "has SHA-256" in resumed.line and "its manifest records" in resumed.line
    check_outcome(resumed, previous, uninterrupted)


def test_a_checkpoint_written_before_manifests_that_mixes_steps_restarts(
    tmp_path, preset, uninterrupted, monkeypatch, capsys
):
    """A checkpoint of a version before manifests (none, no previous generation) whose model
    is from an earlier step than its state: the loader's own checks catch it and the run
    restarts, naming model.zip and both steps."""
    first = kill_after_checkpoint(tmp_path / "first", preset, 1, monkeypatch)
    stale = checkpoints.checkpoint_paths(first)["model"].read_bytes()
    folder = kill_after_checkpoint(tmp_path / "run", preset, 2, monkeypatch)
    paths = checkpoints.checkpoint_paths(folder)
    shutil.rmtree(paths["previous"])
    paths["manifest"].unlink()
    paths["model"].write_bytes(stale)
    resumed = resume(tmp_path / "run", preset, capsys, paths["model"])
    assert "pieces of different checkpoints" in resumed.line
    check_outcome(resumed, False, uninterrupted)


def test_the_cli_resumes_a_damaged_checkpoint_with_one_line_and_exit_0(
    tmp_path, preset_file, preset, uninterrupted, monkeypatch
):
    """`distgprl train --preset-file ... --resume` over an empty model.zip whose previous
    checkpoint has an empty buffer: exit 0, one line on stderr naming both files and the
    restart, no traceback, and the model of the run that was never killed."""
    folder = kill_after_checkpoint(tmp_path, preset, 2, monkeypatch)
    paths = checkpoints.checkpoint_paths(folder)
    damage(paths["model"], "empty")
    damage(paths["previous"] / "replay_buffer.pkl", "empty")
    args = ["train", "--method", METHOD, "--task", "dcp", "--preset-file", str(preset_file)]
    args += ["--root", str(tmp_path), "--resume", "--no-evaluate"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    bar = f"dcp/{METHOD}/s0:"  # the progress bar's lines (redrawn after carriage returns)
    [line] = [text for text in result.stderr.split("\n") if text and bar not in text]
    assert f"{paths['model']} is empty (0 bytes)" in line and "restarts from step 0" in line
    assert f"so is the previous one, {paths['previous'] / 'replay_buffer.pkl'} is empty" in line
    assert "Traceback" not in result.output
    for ours, reference in zip(actor_parameters(folder), uninterrupted, strict=True):
        np.testing.assert_array_equal(ours, reference)


@pytest.mark.parametrize("moment", ["saved", "committed", "staged"])
def test_an_interrupt_names_the_checkpoint_on_disk(tmp_path, preset, monkeypatch, moment):
    """A KeyboardInterrupt landing in or just after the second checkpoint's save: the
    interrupt's checkpoint step, and the line `distgprl train` prints, are the step of the
    checkpoint on disk that a resume continues from — the second's once its pieces are
    committed (``saved``: the save had returned; ``committed``: stopped before the pieces
    were moved into place, which the message's settling finishes), the first's when stopped
    before the commit marker (``staged``: the new pieces are dropped)."""
    from distgprl.experiments.run_control import TrainingInterrupted

    saves: list[int] = []
    installs_stopped: list[bool] = []
    save, install, fsync = (
        training.save_checkpoint,
        checkpoints.install_checkpoint,
        checkpoints.fsync_file,
    )

    def save_and_stop(folder, model, env, extra):
        saves.append(int(model.num_timesteps))
        save(folder, model, env, extra)
        if moment == "saved" and len(saves) == 2:
            raise KeyboardInterrupt

    def install_and_stop(paths):
        if moment == "committed" and len(saves) == 2 and not installs_stopped:
            installs_stopped.append(True)
            raise KeyboardInterrupt
        install(paths)

    def fsync_and_stop(path):
        if moment == "staged" and len(saves) == 2:
            raise KeyboardInterrupt
        fsync(path)

    monkeypatch.setattr(training, "save_checkpoint", save_and_stop)
    monkeypatch.setattr(checkpoints, "install_checkpoint", install_and_stop)
    monkeypatch.setattr(checkpoints, "fsync_file", fsync_and_stop)
    with pytest.raises(TrainingInterrupted) as raised:
        train(tmp_path, preset)
    assert len(saves) == 2 and saves[0] < saves[1]
    expected = saves[0] if moment == "staged" else saves[1]
    assert raised.value.checkpoint_step == expected
    paths = checkpoints.checkpoint_paths(run_dir(tmp_path, preset, "dcp", METHOD, 0))
    assert pickle.loads(paths["state"].read_bytes())["num_timesteps"] == expected
    assert json.loads(paths["manifest"].read_text())["num_timesteps"] == expected
    assert not paths["commit"].exists()
    assert f"its checkpoint of step {expected} is kept" in raised.value.describe("distgprl")


def test_checkpoint_step_is_none_without_a_checkpoint(tmp_path):
    """A run folder without a checkpoint: no checkpoint step (a resume starts over)."""
    assert checkpoints.checkpoint_step(tmp_path) is None
