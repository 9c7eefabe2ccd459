"""`python -m distgprl.cli` is the same CLI as the `distgprl` console script."""

from __future__ import annotations

import subprocess
import sys

from distgprl.cli import app


def test_module_entry_registers_every_command():
    names = sorted(command.name or command.callback.__name__ for command in app.registered_commands)
    assert {"train", "evaluate", "sweep", "tables", "curves"} <= set(names)
    result = subprocess.run(
        [sys.executable, "-m", "distgprl.cli", "--help"],
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
