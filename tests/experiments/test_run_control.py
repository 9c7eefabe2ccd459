"""`distgprl.experiments.run_control`: what an interrupted training says (where it stopped,
what is kept) and the resume command it prints, which continues exactly the interrupted run
(the same task, method, seed, preset, steps, root and evaluation choice)."""

from __future__ import annotations

import shlex
from pathlib import Path

from distgprl.experiments.run_control import (
    TrainingInterrupted,
    describe_interrupt,
    resume_command,
)


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
