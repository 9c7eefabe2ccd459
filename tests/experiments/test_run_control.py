"""`distgprl.experiments.run_control`: what an interrupted training says (where it stopped,
what is kept) and the resume command it prints, which continues exactly the interrupted run
(the same task, method, seed, preset, steps, root and evaluation choice); where a resume
continues from (`resume_point`: the checkpoint's step, or a restart without one)."""

from __future__ import annotations

import json
import pickle
import shlex
from pathlib import Path

from distgprl.experiments.checkpoints import (
    MANIFEST_NAME,
    PIECE_FILES,
    checkpoint_paths,
    checkpoint_step,
)
from distgprl.experiments.run_control import (
    ResumePoint,
    TrainingInterrupted,
    describe_interrupt,
    resume_command,
    resume_point,
)
from distgprl.schema import PROGRESS_FIELDS, run_dir, write_csv


def test_resume_command_repeats_every_choice_of_the_run():
    command = resume_command("dcp", "dist-gprl", 3, "ci", 240, Path("my results"), False)
    assert shlex.split(command) == [
        "distgprl",
        "train",
        "--method",
        "dist-gprl",
        "--task",
        "dcp",
        "--seed",
        "3",
        "--preset",
        "ci",
        "--steps",
        "240",
        "--root",
        "my results",
        "--resume",
        "--no-evaluate",
    ]
    default = shlex.split(resume_command("dbm", "gprl", 0, "paper", None, "results"))
    assert "--steps" not in default and "--no-evaluate" not in default


def test_an_interrupt_says_what_a_resume_keeps():
    """With a checkpoint, its step is kept; without one, a resume starts over."""
    kept = TrainingInterrupted(Path("run"), 130, 240, 120).describe("distgprl train ...")
    assert "step 130 of 240" in kept and "checkpoint of step 120 is kept" in kept
    assert kept.endswith("resume with: distgprl train ...")
    lost = TrainingInterrupted(Path("run"), 50, 240, None).describe("cmd")
    assert "no checkpoint was written yet, so a resume starts over" in lost


def test_an_interrupt_outside_the_training_steps_still_gives_the_resume_command():
    text = describe_interrupt(KeyboardInterrupt(), "cmd")
    assert text == "train interrupted outside the training steps; resume with: cmd"
    inside = TrainingInterrupted(Path("run"), 1, 2, None)
    assert describe_interrupt(inside, "cmd") == inside.describe("cmd")


def _checkpoint_generation(directory: Path, step: int, manifest: bool = True) -> None:
    """The three files of a checkpoint generation at ``step`` (their contents do not matter
    to where a resume continues from), with or without a manifest."""
    directory.mkdir(parents=True, exist_ok=True)
    for name in PIECE_FILES.values():
        (directory / name).write_bytes(b"x")
    (directory / PIECE_FILES["state"]).write_bytes(pickle.dumps({"num_timesteps": step}))
    if manifest:
        (directory / MANIFEST_NAME).write_text(json.dumps({"num_timesteps": step, "files": {}}))


def test_a_run_without_a_checkpoint_restarts_whatever_its_curve_reached(tmp_path):
    """A partial progress.csv is no resumable progress: with no checkpoint the resume point
    is step 0 and says so, with the step the curve had reached."""
    assert resume_point(tmp_path) == ResumePoint(0, None)
    assert resume_point(tmp_path).describe() == "restarts: no checkpoint yet"
    row = {**dict.fromkeys(PROGRESS_FIELDS, ""), "step": 120}
    write_csv(tmp_path / "progress.csv", [row], PROGRESS_FIELDS)
    point = resume_point(tmp_path)
    assert (point.reached, point.checkpoint, point.start_step) == (120, None, 0)
    assert point.describe() == "restarts: no checkpoint yet (it had reached step 120)"


def test_the_resume_point_is_the_checkpoint_a_resume_would_load(tmp_path):
    """The newest generation's manifest step; a pending commit marker's (a save a kill
    interrupted after it committed, rolled forward on resume); the previous generation's
    when the newest has no files; a generation from before manifests by its state file.
    Reading it writes nothing."""
    paths = checkpoint_paths(tmp_path)
    _checkpoint_generation(paths["previous"], 120)
    assert checkpoint_step(tmp_path) == 120
    _checkpoint_generation(paths["dir"], 240)
    assert resume_point(tmp_path).describe() == "resumes from its checkpoint of step 240"
    assert resume_point(tmp_path).start_step == 240
    paths["commit"].write_text(json.dumps({"num_timesteps": 360, "files": {}}))
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert checkpoint_step(tmp_path) == 360
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before
    paths["commit"].unlink()
    paths["manifest"].unlink()
    assert checkpoint_step(tmp_path) == 240  # its state file says so


def test_a_run_killed_at_its_first_checkpoint_resumes_from_it(
    tmp_path, kill_at_the_first_checkpoint
):
    kill_at_the_first_checkpoint(tmp_path)
    folder = run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0)
    assert resume_point(folder) == ResumePoint(120, 120)
