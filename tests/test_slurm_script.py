"""The Slurm batch script of docs/guides/slurm.md (`scripts/slurm/distgprl_ray.sbatch`),
checked as far as a machine without Slurm allows: its syntax (``bash -n``), and a run of it
with stand-ins for ``srun``, ``scontrol``, ``ray`` and ``distgprl`` that record what they
were asked, each ``ray start`` and ``distgprl`` command then parsed by the real command-line
parsers (`ray start`'s and `distgprl sweep` / `status`'s): every option it uses exists and
takes the value given."""

from __future__ import annotations

import os
import shlex
import stat
import subprocess
import sys
from pathlib import Path

import pytest
import typer

from distgprl.cli import app

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "slurm" / "distgprl_ray.sbatch"
NODES = ["node0", "node1", "node2"]

SRUN = """#!/usr/bin/env bash
# srun stand-in: -w NODE runs the command "on" NODE (here, with NODE set)
node=""
while [ $# -gt 0 ]; do
    case "$1" in
        -w) node=$2; shift 2 ;;
        --nodes=*|--ntasks=*|--cpus-per-task=*) shift ;;
        *) break ;;
    esac
done
NODE=$node exec "$@"
"""

SCONTROL = """#!/usr/bin/env bash
[ "$1 $2" = "show hostnames" ] || exit 9
printf '%s\\n' node0 node1 node2
"""

RECORDER = """#!/usr/bin/env bash
# {name} stand-in: record the command, the node and the token file's mode
printf '%s\\t%s\\t%s\\t%s\\n' "${{NODE:-batch}}" "$RAY_AUTH_MODE" \\
    "$(stat -c %a "$RAY_AUTH_TOKEN_PATH")" "{name} $*" >>"$CALLS"
{body}
"""

RAY_BODY = """if [ "$1" = start ]; then exec sleep 60; fi  # --block: until the job ends"""
DISTGPRL_BODY = """if [ "$1" = sweep ]; then
    # as long as a real sweep would: the workers (started in the background) have joined
    for _ in $(seq 200); do
        [ "$(grep -c ' start ' "$CALLS")" -ge 3 ] && break
        sleep 0.05
    done
    exit "${SWEEP_EXIT:-0}"
fi"""


def executable(path: Path, text: str) -> None:
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IEXEC)


def run_script(tmp_path: Path, sweep_exit: int) -> tuple[subprocess.CompletedProcess, list]:
    bin_dir, venv = tmp_path / "bin", tmp_path / "venv" / "bin"
    bin_dir.mkdir()
    venv.mkdir(parents=True)
    executable(bin_dir / "srun", SRUN)
    executable(bin_dir / "scontrol", SCONTROL)
    executable(venv / "ray", RECORDER.format(name="ray", body=RAY_BODY))
    executable(venv / "distgprl", RECORDER.format(name="distgprl", body=DISTGPRL_BODY))
    (venv / "python").symlink_to(sys.executable)
    calls = tmp_path / "calls.tsv"
    env = {
        **os.environ,
        "PATH": f"{bin_dir}:{os.environ['PATH']}",
        "HOME": str(tmp_path / "home"),
        "CALLS": str(calls),
        "SWEEP_EXIT": str(sweep_exit),
        "SLURM_JOB_ID": "4242",
        "SLURM_JOB_NODELIST": "node[0-2]",
        "SLURM_CPUS_PER_TASK": "8",
        "SLURM_SUBMIT_DIR": str(tmp_path / "project"),
        "DISTGPRL_VENV": str(tmp_path / "venv"),
        "DISTGPRL_RUNS": "--methods dist-gprl,gprl-d --tasks dcp --seeds 0,1",
        "DISTGPRL_SWEEP_ARGS": "--twin-trials 2",
    }
    done = subprocess.run(
        ["bash", str(SCRIPT)], env=env, capture_output=True, text=True, timeout=120
    )
    rows = [line.split("\t") for line in calls.read_text().splitlines()]
    return done, rows


def test_the_batch_script_parses():
    done = subprocess.run(["bash", "-n", str(SCRIPT)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def option(words: list[str], name: str) -> str:
    """The value of ``--name=value`` or ``--name value`` in ``words``."""
    for index, word in enumerate(words):
        if word.startswith(f"{name}="):
            return word.split("=", 1)[1]
        if word == name:
            return words[index + 1]
    raise AssertionError(f"{name} not in {words}")


@pytest.mark.parametrize("sweep_exit", [0, 4])
def test_the_batch_script_starts_a_head_and_workers_then_sweeps(tmp_path, sweep_exit):
    """The head on the first node, a worker on each other one joining it, then the sweep
    and the status of its runs on the cluster's address, all with the job's token (mode
    600, removed at the end); the script exits with the sweep's code."""
    from ray.scripts.scripts import start as ray_start

    done, rows = run_script(tmp_path, sweep_exit)
    assert done.returncode == sweep_exit, done.stderr
    assert f"distgprl sweep exited {sweep_exit}" in done.stdout
    assert {(mode, perms) for _, mode, perms, _ in rows} == {("token", "600")}
    starts = [
        (node, shlex.split(command)[2:]) for node, _, _, command in rows if " start " in command
    ]
    head = [(node, words) for node, words in starts if "--head" in words]
    workers = [(node, words) for node, words in starts if "--head" not in words]
    assert [node for node, _ in head] == ["node0"]
    assert sorted(node for node, _ in workers) == NODES[1:]
    head_words = head[0][1]
    address = f"{option(head_words, '--node-ip-address')}:{option(head_words, '--port')}"
    for _, words in starts:
        ray_start.make_context("start", list(words))  # every option exists, values parse
        assert option(words, "--num-cpus") == "8" and "--block" in words
        assert option(words, "--temp-dir") == "/tmp/ray-4242"
    assert all(option(words, "--address") == address for _, words in workers)
    commands = [shlex.split(command)[1:] for node, _, _, command in rows if "distgprl" in command]
    assert [words[0] for words in commands] == ["sweep", "status"]
    cli = typer.main.get_command(app)
    for words in commands:
        context = cli.commands[words[0]].make_context(words[0], list(words[1:]))
        assert context.params["methods"] == "dist-gprl,gprl-d"
        assert context.params["seeds"] == "0,1" and context.params["preset"] == "paper"
        assert context.params["root"] == tmp_path / "project" / "results"
    sweep = cli.commands["sweep"].make_context("sweep", list(commands[0][1:])).params
    assert (sweep["executor"], sweep["address"], sweep["twin_trials"]) == ("ray", address, 2)
    assert not list((tmp_path / "home" / ".ray").iterdir())  # the token is gone
