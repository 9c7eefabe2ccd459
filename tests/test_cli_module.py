"""`python -m distgprl` and `python -m distgprl.cli` are the same CLI as the `distgprl`
console script."""

from __future__ import annotations

import subprocess
import sys

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
