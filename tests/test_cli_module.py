"""`python -m distgprl` and `python -m distgprl.cli` are the same CLI as the `distgprl`
console script."""

from __future__ import annotations

import pickle
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from distgprl.cli import app


@pytest.mark.parametrize("module", ["distgprl", "distgprl.cli"])
def test_module_entry_registers_every_command(module):
    names = sorted(command.name or command.callback.__name__ for command in app.registered_commands)
    assert {"train", "evaluate", "sweep", "tables", "curves"} <= set(names)
    result = subprocess.run(
        [sys.executable, "-m", module, "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        env={"COLUMNS": "200", "PATH": ""},
    )
    assert result.returncode == 0, result.stderr
    listed = {line.split()[1] for line in result.stdout.splitlines() if line.startswith("│ ")}
    assert set(names) <= listed, sorted(set(names) - listed)


def test_a_bad_seed_is_one_line_exit_2_and_writes_nothing(tmp_path):
    """`distgprl train --seed -1` and `distgprl sweep --seeds -1` refuse the input with one
    line on stderr and exit code 2, before any folder is created."""
    for args in (
        ["train", "--method", "dist-gprl", "--task", "dcp", "--seed", "-1"],
        ["sweep", "--preset", "ci", "--seeds", "-1", "--methods", "gprl-d"],
        ["evaluate", "--method", "demo", "--task", "dcp", "--seed", "-1"],
    ):
        result = subprocess.run(
            [sys.executable, "-m", "distgprl.cli", *args, "--root", str(tmp_path / "r")],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=tmp_path,
        )
        assert result.returncode == 2, (args, result.stderr)
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert lines == ["error: seed -1 must be an integer from 0 to 2**32 - 1"], args
        assert list(tmp_path.iterdir()) == [], args


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_train_interrupted_says_where_it_stopped_and_how_to_resume(tmp_path, signum):
    """`distgprl train` stopped by SIGINT or SIGTERM mid-training exits 130 and says, in two
    lines on stderr, the step it stopped at, the step of the checkpoint it keeps (the one on
    disk) and the exact command to resume."""
    root = tmp_path / "r"
    args = ["train", "--method", "gprl-d", "--task", "dcp", "--preset", "ci", "--steps", "900"]
    args += ["--root", str(root), "--no-evaluate"]
    process = subprocess.Popen(
        [sys.executable, "-m", "distgprl.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    state = root / "ci" / "dcp" / "gprl-d" / "seed0" / "checkpoints" / "state.pkl"
    deadline = time.monotonic() + 300
    while not state.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    stopped, resume = stderr.strip().splitlines()[-2:]
    pattern = r"train interrupted at step (\d+) of 900 \((.+)\); its checkpoint of step (\d+)"
    match = re.fullmatch(pattern + r" is kept\.", stopped)
    assert match, stopped
    step, folder, kept = int(match[1]), Path(match[2]), int(match[3])
    assert folder == state.parent.parent
    assert kept == pickle.loads(state.read_bytes())["num_timesteps"] and 120 <= kept <= step < 900
    assert resume.startswith("resume with: distgprl ")
    resumed = ["train", "--method", "gprl-d", "--task", "dcp", "--seed", "0", "--preset", "ci"]
    resumed += ["--steps", "900", "--root", str(root), "--resume", "--no-evaluate"]
    assert shlex.split(resume.removeprefix("resume with: distgprl ")) == resumed
