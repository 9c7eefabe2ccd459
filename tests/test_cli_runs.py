"""`distgprl.cli.runs`: `train` ends with its evaluation's table (or, with --no-evaluate,
the command that evaluates it); `evaluate` prints the table, or the JSON with --json."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.experiments import evaluation, training
from distgprl.schema import run_dir, write_json

SUMMARY = {"episodes": 6, "success_rate": 0.5, "collision_rate": 1 / 6, "mean_return": 2.0}


def test_train_ends_with_its_evaluation_summary(tmp_path, monkeypatch):
    def fake_train(task, method, seed, preset, steps, resume, root, evaluate_after):
        folder = run_dir(root, preset, task, method, seed)
        if evaluate_after:
            write_json(folder / "summary.json", {"summary": SUMMARY}, kind="summary")
        return folder

    monkeypatch.setattr(training, "train_run", fake_train)
    arguments = ["train", "--method", "gprl", "--task", "dcp", "--preset", "ci"]
    arguments += ["--root", str(tmp_path)]
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[1].startswith("evaluation (") and lines[1].endswith("summary.json):")
    assert lines[-1].split() == ["mean", "return", "2.00"]
    assert any(line.split()[-2:] == ["50", "%"] for line in lines)
    result = CliRunner().invoke(app, [*arguments, "--no-evaluate"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[-1] == (
        "not evaluated (--no-evaluate); evaluate with: distgprl evaluate --method gprl "
        f"--task dcp --seed 0 --preset ci --root {tmp_path}"
    )


def test_evaluate_prints_a_table_or_with_json_the_whole_summary(tmp_path, monkeypatch):
    monkeypatch.setattr(evaluation, "evaluate_run", lambda *args, **kwargs: dict(SUMMARY))
    arguments = ["evaluate", "--method", "demo", "--task", "dbm", "--preset", "ci"]
    arguments += ["--root", str(tmp_path)]
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0] == "evaluation of dbm/demo/seed0 (ci, final policy):"
    assert len(lines) == 1 + len(SUMMARY) and "{" not in result.output
    result = CliRunner().invoke(app, [*arguments, "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output) == {**SUMMARY, "collision_rate": 0.1667}


def test_evaluate_refuses_a_policy_choice_for_a_reference(tmp_path, monkeypatch):
    """A reference (``demo``, ``promp-nominal``) is not trained: ``--policy final`` or
    ``--policy best`` with it is a user error (exit 2, one line), not dropped; with
    ``--plan-repair`` too. A trained method still takes it; a reference without it passes."""
    from distgprl.experiments import safety_layer_evaluation

    evaluated = []

    def fake_evaluate(*args, **kwargs):
        evaluated.append((args, kwargs))
        return dict(SUMMARY)

    monkeypatch.setattr(evaluation, "evaluate_run", fake_evaluate)
    monkeypatch.setattr(safety_layer_evaluation, "evaluate_with_repair", fake_evaluate)
    base = ["evaluate", "--task", "dbm", "--preset", "ci", "--root", str(tmp_path)]
    for options in (
        ["--method", "demo", "--policy", "final"],
        ["--method", "demo", "--policy", "best"],
        ["--method", "promp-nominal", "--policy", "final"],
        ["--method", "demo", "--policy", "final", "--plan-repair"],
    ):
        result = CliRunner().invoke(app, [*base, *options])
        assert result.exit_code == 2, (options, result.output)
        assert result.output.strip().splitlines() == [
            f"error: --policy: {options[1]} is a reference, not trained: it has no final or "
            "best policy to choose (it is evaluated as it is); leave --policy out"
        ]
    assert evaluated == []
    for options in (["--method", "demo"], ["--method", "gprl", "--policy", "best"]):
        result = CliRunner().invoke(app, [*base, *options])
        assert result.exit_code == 0, (options, result.output)
    assert [kwargs["policy"] for _, kwargs in evaluated] == ["final", "best"]
