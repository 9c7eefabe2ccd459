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
