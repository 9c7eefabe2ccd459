"""`distgprl fit` through typer's runner, including every bad-input case."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.schema import read_json

runner = CliRunner()


def test_fit_demo_writes_json_and_figure(tmp_path, smooth_demo_file):
    out = tmp_path / "skills"
    result = runner.invoke(app, ["fit", "--demo", str(smooth_demo_file), "--out-dir", str(out)])
    assert result.exit_code == 0, result.output
    document = read_json(out / "synthetic.json")
    assert len(document["skill"]["via_points"]) == 15
    assert document["demonstration"]["sha256"]
    assert max(document["rmse"]["position"]) < 1e-3
    assert document["skill"]["kernel"]["length_scale"] > 0
    assert (out / "synthetic.png").stat().st_size > 10_000
    correlation = document["correlation_operator"]
    assert correlation["correlation_lambda"] == 0.01
    assert [w["via_points"][0] for w in correlation["windows"]] == [1, 5, 9]
    assert "Table I operator (lambda 0.01, K 'zero-mean')" in result.output  # v6
    for reading in ("signal", "unit", "correlation"):  # every study operator's spectrum
        assert f"study operator K '{reading}'" in result.output
    assert "action scale per unit raw action (fixed)" in result.output  # no task: no TC range


@pytest.mark.parametrize(
    ("body", "fragment"),
    [
        ("t,x,y,z,rx,ry\n0,1,2,3,4,5\n", "missing column"),
        ("t,x,y,z,rx,ry,rz\n0,1,2,3,4,5,6\n1,1,2,x,4,5,6\n", ":3: column 'z' is not a number"),
        ("t,x,y,z,rx,ry,rz\n0,1,2,3,4,5,6\n1,1,2,nan,4,5,6\n", "not finite"),
        ("t,x,y,z,rx,ry,rz\n1,1,2,3,4,5,6\n0,1,2,3,4,5,6\n", "time must increase"),
        (
            "t,x,y,z,rx,ry,rz\n" + "".join(f"{i},1,2,3,4,5,6\n" for i in range(5)),
            "need at least 15",
        ),
    ],
)
def test_bad_demo_exits_2_with_one_line_and_writes_nothing(tmp_path, body, fragment):
    demo = tmp_path / "bad.csv"
    demo.write_text(body)
    out = tmp_path / "skills"
    result = runner.invoke(app, ["fit", "--demo", str(demo), "--out-dir", str(out)])
    assert result.exit_code == 2
    assert fragment in result.output
    assert str(demo) in result.output
    assert result.output.strip().count("\n") == 0
    assert not out.exists()


def test_unknown_task_lists_valid_names(tmp_path):
    result = runner.invoke(app, ["fit", "--task", "nope", "--out-dir", str(tmp_path)])
    assert result.exit_code == 2
    assert "valid tasks: dcp, dbm" in result.output


def test_task_and_demo_are_exclusive(tmp_path, smooth_demo_file):
    result = runner.invoke(app, ["fit", "--task", "dcp", "--demo", str(smooth_demo_file)])
    assert result.exit_code == 2


def test_fit_task_shows_the_committed_skill_without_fitting(tmp_path, monkeypatch):
    """`distgprl fit --task dcp` prints the committed skill's hyperparameters at full
    precision and its provenance, and writes its report files, without running the fit."""
    import distgprl.skill.committed as committed
    import distgprl.skill.gp as gp
    from distgprl.skill.committed import load_committed_skill

    def refit(*args, **kwargs):
        raise AssertionError("fitted")

    monkeypatch.setattr(gp, "fit_skill", refit)
    monkeypatch.setattr(committed, "fit_skill", refit)
    out = tmp_path / "skills"
    result = runner.invoke(app, ["fit", "--task", "dcp", "--out-dir", str(out)])
    assert result.exit_code == 0, result.output
    skill = load_committed_skill("dcp")
    assert f"length scale {skill.kernel.length_scale!r}" in result.output
    assert "data/skills/dcp.json (fitted at " in result.output
    document = read_json(out / "dcp.json")
    assert document["skill"] == skill.to_dict()
    assert document["committed_skill"]["openblas_coretype"] == "Haswell"
    assert "action scale per unit raw action (reach)" in result.output


def test_fit_write_round_trips_and_compare_reports_the_difference(tmp_path):
    """`fit --task dcp --write --skills-dir D` refits and writes D/dcp.json; the file loads
    back as exactly the fresh fit, `fit --task dcp --skills-dir D --compare` then finds a
    fresh fit identical bit for bit on the same machine, and the package's file is untouched."""
    from distgprl.skill.committed import (
        committed_skill_path,
        fit_task_skill,
        load_committed_skill,
    )

    shipped = committed_skill_path("dcp").read_bytes()
    result = runner.invoke(app, ["fit", "--task", "dcp", "--write", "--skills-dir", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert f"-> {tmp_path / 'dcp.json'}" in result.output
    written = load_committed_skill("dcp", directory=tmp_path)
    assert written.to_dict() == fit_task_skill("dcp").to_dict()
    again = runner.invoke(
        app,
        ["fit", "--task", "dcp", "--compare", "--skills-dir", str(tmp_path)]
        + ["--out-dir", str(tmp_path / "out")],
    )
    assert again.exit_code == 0, again.output
    assert "against the committed skill: identical bit for bit" in again.output
    assert committed_skill_path("dcp").read_bytes() == shipped


def test_fit_write_refuses_a_demo_file(tmp_path, smooth_demo_file):
    result = runner.invoke(app, ["fit", "--demo", str(smooth_demo_file), "--write"])
    assert result.exit_code == 2
    assert "--write refits a task's committed skill" in result.output


def test_fit_task_with_a_missing_skill_file_exits_2_naming_it(tmp_path):
    result = runner.invoke(
        app, ["fit", "--task", "dcp", "--skills-dir", str(tmp_path), "--out-dir", str(tmp_path)]
    )
    assert result.exit_code == 2
    assert f"{tmp_path / 'dcp.json'}: the committed skill file is missing" in result.output
    assert result.output.strip().count("\n") == 0


def test_fit_refuses_options_its_mode_would_not_read(tmp_path, smooth_demo_file, monkeypatch):
    """``--out-dir`` or ``--compare`` with ``--write`` (it writes the committed skill file and
    says how it moved) and ``--compare`` or ``--skills-dir`` with ``--demo`` (no committed
    skill) are user errors (exit 2, one line), nothing fitted or written; ``--write
    --skills-dir`` still refits."""
    import distgprl.cli.skills as cli_skills
    import distgprl.experiments.skills as skills

    called = []

    def never(*args, **kwargs):
        called.append(args)
        raise AssertionError("ran")

    monkeypatch.setattr(skills, "fit_demonstration", never)
    monkeypatch.setattr(skills, "show_committed_skill", never)
    monkeypatch.setattr(cli_skills, "refit_task", lambda *args: called.append(args))
    demo = str(smooth_demo_file)
    refused = {
        ("--write", "--out-dir", str(tmp_path / "out")): "--out-dir: --write writes",
        ("--task", "dcp", "--write", "--compare"): "--compare: --write writes",
        ("--write", "--compare", "--out-dir", "o"): "--out-dir and --compare: --write writes",
        ("--demo", demo, "--compare"): "--compare: a task's committed skill's",
        ("--demo", demo, "--skills-dir", str(tmp_path)): "--skills-dir: a task's committed",
    }
    for options, message in refused.items():
        result = runner.invoke(app, ["fit", *options])
        assert result.exit_code == 2, (options, result.output)
        assert result.output.strip().count("\n") == 0 and message in result.output
    assert called == [] and not (tmp_path / "out").exists()
    result = runner.invoke(app, ["fit", "--task", "dcp", "--write", "--skills-dir", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert called == [("dcp", 15, tmp_path)]
