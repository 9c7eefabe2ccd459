"""The Slurm guide's batch script (scripts/slurm/distgprl_ray.sbatch): valid bash, and every
`distgprl` command and option it runs exists in the CLI (so the guide cannot drift from it)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from typer.testing import CliRunner

from distgprl.cli import app

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "slurm" / "distgprl_ray.sbatch"


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_the_batch_script_is_valid_bash():
    result = subprocess.run(["bash", "-n", str(SCRIPT)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_every_distgprl_option_the_script_uses_exists():
    text = SCRIPT.read_text().replace("\\\n", " ")
    calls = re.findall(r'"\$VENV/distgprl" (\w+)([^\n]*)', text)
    assert {command for command, _ in calls} == {"sweep", "status"}
    for command, rest in calls:
        help_text = CliRunner().invoke(app, [command, "--help"], terminal_width=200).output
        for option in re.findall(r"(--[a-z-]+)", rest):
            assert option in help_text, f"distgprl {command} has no {option}"
