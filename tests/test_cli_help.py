"""The CLI's help and option parsing (distgprl/cli.py): help that names the valid values, no
``<bool>`` type on flags, bad options refused before anything runs, ``--version``, and
``--preset-file PATH`` for a preset of the user's own."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from distgprl import __version__
from distgprl import config as config_module
from distgprl.cli import app
from distgprl.cli.common import runs_text
from distgprl.methods import METHODS

WIDE = {"COLUMNS": "250", "TERMINAL_WIDTH": "250", "NO_COLOR": "1"}
COMMANDS = sorted(command.name or command.callback.__name__ for command in app.registered_commands)


def invoke(*args: str):
    return CliRunner().invoke(app, list(args), env=WIDE)


@pytest.fixture(autouse=True)
def no_user_presets(monkeypatch):
    monkeypatch.setenv(config_module.USER_PRESETS_ENV, "")


def test_version_prints_the_package_version():
    result = invoke("--version")
    assert result.exit_code == 0
    assert result.output.strip() == f"distgprl {__version__}"


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_no_help_shows_a_bool_type_for_a_flag(command):
    """Flags (--resume, --dry-run, --help, ...) take no value; typer's ``<bool>`` suggested one."""
    result = invoke(*([command] if command else []), "--help")
    assert result.exit_code == 0, result.output
    assert "--help" in result.output
    assert "<bool>" not in result.output


def test_train_help_lists_methods_tasks_and_presets_and_states_the_steps_rule():
    output = invoke("train", "--help").output
    for name in [n for n, spec in METHODS.items() if spec.trainable] + ["dcp", "dbm"]:
        assert name in output
    assert (
        "ci | operator-correlation | operator-signal | operator-signal-uncoupled | operator-unit"
        in output
    )
    assert "x>=3" not in output
    assert "multiple of the episode" in output
    assert "demo" in invoke("evaluate", "--help").output


@pytest.mark.parametrize("steps", ["0", "-3"])
def test_steps_must_be_positive(steps, tmp_path):
    result = invoke(
        "train", "--method", "dist-gprl", "--task", "dcp", "--steps", steps, "--root", str(tmp_path)
    )
    assert result.exit_code == 2
    assert "positive multiple of the episode length" in result.output
    assert not any(tmp_path.iterdir())


def test_a_bad_executor_is_refused_before_the_sweep_banner(tmp_path):
    result = invoke("sweep", "--executor", "bogus", "--root", str(tmp_path))
    assert result.exit_code == 2
    assert "'bogus' is not one of 'local', 'ray'" in result.output
    assert "sweep:" not in result.output


def test_tables_against_an_unknown_preset_says_it_is_not_a_preset(tmp_path):
    result = invoke(
        "tables", "--against", "nope", "--root", str(tmp_path), "--out-dir", str(tmp_path)
    )
    assert result.exit_code == 2
    assert (
        "--against nope: not a preset (valid presets: ci, operator-correlation, "
        "operator-signal, operator-signal-uncoupled, operator-unit, paper)" in result.output
    )
    assert f"no results under {tmp_path / 'nope'}" in " ".join(result.output.split())


def test_run_counts_are_singular_for_one():
    assert (runs_text(1), runs_text(2), runs_text(0)) == ("1 run", "2 runs", "0 runs")


def test_config_of_a_shipped_presets_name_or_with_preset_is_refused(tmp_path):
    """--preset-file paper.yaml would mix the user's runs into the shipped preset's folders."""
    (tmp_path / "paper.yaml").write_text("run:\n  total_steps: 3\n")
    result = invoke(
        "status", "--preset-file", str(tmp_path / "paper.yaml"), "--root", str(tmp_path)
    )
    assert result.exit_code == 2
    assert "is a shipped preset's" in result.output
    (tmp_path / "mine.yaml").write_text("")
    result = invoke(
        "status",
        "--preset",
        "ci",
        "--preset-file",
        str(tmp_path / "mine.yaml"),
        "--root",
        str(tmp_path),
    )
    assert result.exit_code == 2
    assert "give --preset or --preset-file, not both" in result.output


def test_status_of_a_user_preset_plans_its_runs_under_its_stem(tmp_path):
    """`status --preset-file mine.yaml` plans the runs of preset ``mine`` (``<root>/mine/...``)."""
    (tmp_path / "mine.yaml").write_text("run:\n  total_steps: 300\n")
    root = tmp_path / "results"
    result = invoke(
        "status", "--preset-file", str(tmp_path / "mine.yaml"), "--tasks", "dcp", "--methods",
        "dist-gprl", "--seeds", "0", "--root", str(root),
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "missing" in result.output
    assert "mine" in config_module.preset_names()


def test_train_set_trains_the_preset_with_the_override_under_a_hash_of_its_own(
    tmp_path, monkeypatch
):
    """`train --set sac.batch_size=128` passes the preset named with its override down to
    `train_run`: a configuration (batch 128) and a run hash other than the preset's."""
    from distgprl.experiments import training
    from distgprl.identity import resolve_run

    called = {}

    def fake_train_run(task, method, seed, preset, *args, **kwargs):
        called["preset"] = preset
        return tmp_path

    monkeypatch.setattr(training, "train_run", fake_train_run)
    args = ["train", "--method", "dist-gprl", "--task", "dcp", "--root", str(tmp_path)]
    result = invoke(*args, "--set", "sac.batch_size=128")
    assert result.exit_code == 0, result.output
    assert called["preset"] == "paper+sac.batch_size=128"
    changed = resolve_run("dcp", "dist-gprl", 0, called["preset"])
    assert changed.config.sac.batch_size == 128
    assert changed.hash != resolve_run("dcp", "dist-gprl", 0, "paper").hash


def test_sweep_set_plans_the_runs_of_the_preset_with_the_override(tmp_path, monkeypatch):
    from distgprl.experiments import sweep

    planned = []
    monkeypatch.setattr(sweep, "run_sweep", lambda jobs, *a, **k: planned.extend(jobs) or [])
    result = invoke(
        "sweep", "--preset", "ci", "--set", "run.total_steps=300", "--set", "sac.batch_size=32",
        "--tasks", "dcp", "--methods", "dist-gprl", "--seeds", "0", "--root", str(tmp_path),
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert [job.preset for job in planned] == ["ci+run.total_steps=300+sac.batch_size=32"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--set", "sac.batchsize=128"], "unknown key sac.batchsize"),
        (["--set", "sac.batch_size=0"], "sac.batch_size = 0 must be >= 1"),
    ],
)
def test_a_bad_set_exits_2_naming_the_key(tmp_path, args, message):
    base = ["train", "--method", "dist-gprl", "--task", "dcp", "--root", str(tmp_path)]
    result = invoke(*base, *args)
    assert result.exit_code == 2
    assert message in result.output
    assert not any(tmp_path.iterdir())


def test_set_on_a_study_is_refused(tmp_path):
    result = invoke("sweep", "--preset", "operators", "--set", "sac.batch_size=128")
    assert result.exit_code == 2
    assert "is a study of several" in result.output
