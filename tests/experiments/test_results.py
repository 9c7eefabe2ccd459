"""Versioned, atomic result IO (distgprl/experiments/results.py)."""

from __future__ import annotations

import json

import pytest

from distgprl.errors import UserInputError
from distgprl.experiments import results


def test_json_round_trip_with_meta(tmp_path):
    path = results.write_json(tmp_path / "a" / "x.json", {"value": [1, 2.5]}, seed=3)
    document = results.read_json(path)
    assert document["value"] == [1, 2.5]
    meta = document["meta"]
    assert meta["schema_version"] == results.SCHEMA_VERSION
    assert meta["seed"] == 3
    for key in ("package_version", "git_commit", "utc_time", "libraries"):
        assert key in meta
    assert "torch" in meta["libraries"]


def test_unknown_schema_version_is_a_clear_error(tmp_path):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"meta": {"schema_version": 999}}))
    with pytest.raises(results.SchemaVersionError, match="schema_version 999 is not supported"):
        results.read_json(path)


def test_csv_round_trip_and_version_check(tmp_path):
    rows = [{"a": 1, "b": 0.5}, {"a": 2, "b": 1.5}]
    path = results.write_csv(tmp_path / "r.csv", rows, ["a", "b"], seed=1)
    meta, back = results.read_csv(path)
    assert meta["seed"] == 1 and back == [{"a": "1", "b": "0.5"}, {"a": "2", "b": "1.5"}]
    path.write_text("a,b\n1,2\n")
    with pytest.raises(results.SchemaVersionError, match="missing '# meta:'"):
        results.read_csv(path)


def test_csv_with_unknown_schema_version_names_the_file_and_version(tmp_path):
    """A CSV whose `# meta:` line has schema_version 999 is refused, not guessed at: the
    SchemaVersionError names the file and the unsupported version."""
    path = results.write_csv(tmp_path / "r.csv", [{"a": 1}], ["a"])
    header, body = path.read_text().split("\n", 1)
    meta = json.loads(header[len("# meta: ") :])
    assert meta["schema_version"] == results.SCHEMA_VERSION  # only the version changes
    path.write_text("# meta: " + json.dumps({**meta, "schema_version": 999}) + "\n" + body)
    with pytest.raises(results.SchemaVersionError) as caught:
        results.read_csv(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: ")
    assert "schema_version 999 is not supported" in message
    assert f"this is schema {results.SCHEMA_VERSION}" in message
    assert isinstance(caught.value, UserInputError)  # the CLI's clean-exit path


@pytest.mark.parametrize("preset", ["ci", "p"])  # a preset of this checkout, and another
def test_tables_command_on_unknown_summary_version_exits_2_with_one_line(tmp_path, preset):
    """`distgprl tables` over a results tree holding a summary.json of schema_version 999
    exits with code 2 and one `error:` line naming the file; no table is written. For a
    preset of this checkout (whose config hashes the report checks) as for any other."""
    from typer.testing import CliRunner

    from distgprl.cli import app

    root, out = tmp_path / "results", tmp_path / "tables"
    if preset == "ci":  # beside a valid run of the current configuration
        from distgprl.experiments.runner import resolve_run

        results.write_json(
            root / "ci" / "dcp" / "demo" / "seed0" / "summary.json",
            {"summary": {"success_rate": 0.5}},
            config_hash=resolve_run("dcp", "demo", 0, "ci").hash,
        )
    summary = root / preset / "dcp" / "dist-gprl" / "seed0" / "summary.json"
    summary.parent.mkdir(parents=True)
    summary.write_text(
        json.dumps({"meta": {"schema_version": 999}, "summary": {"success_rate": 1.0}})
    )
    result = CliRunner().invoke(
        app, ["tables", "--root", str(root), "--preset", preset, "--out-dir", str(out)]
    )
    assert result.exit_code == 2, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert lines[0].startswith(f"error: {summary}: ")
    assert "schema_version 999 is not supported" in lines[0]
    assert result.stdout == ""  # the error goes to stderr only
    assert not out.exists()


def test_git_commit_is_dirty_for_source_changes_only(tmp_path):
    import subprocess

    from distgprl.experiments.results import source_commit

    def git(*args):
        subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True)

    (tmp_path / "distgprl").mkdir()
    (tmp_path / "results").mkdir()
    (tmp_path / "distgprl" / "x.py").write_text("a = 1\n")
    (tmp_path / "results" / "r.csv").write_text("1\n")
    assert source_commit(tmp_path) == "unknown"  # not a git work tree yet
    git("init", "-q")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "init")
    clean = source_commit(tmp_path)
    assert len(clean) == 40
    (tmp_path / "results" / "r.csv").write_text("2\n")  # a re-written result file
    (tmp_path / "results" / "new.csv").write_text("3\n")  # an untracked one
    assert source_commit(tmp_path) == clean
    (tmp_path / "distgprl" / "x.py").write_text("a = 2\n")
    assert source_commit(tmp_path) == clean + "+dirty"


@pytest.mark.parametrize("content", ["[1, 2]", "3.5", '{"summary": {}}', '{"meta": "x"}'])
def test_json_that_is_not_a_result_is_a_clear_error(tmp_path, content):
    """Valid JSON without a ``meta`` object (a list, a number, no meta) is refused with a
    SchemaVersionError naming the file, not an AttributeError."""
    path = tmp_path / "summary.json"
    path.write_text(content)
    with pytest.raises(results.SchemaVersionError, match="no 'meta' object"):
        results.read_json(path)


@pytest.mark.parametrize("meta_line", ["# meta: {not json", "# meta: [1]"])
def test_csv_with_a_garbled_meta_line_is_a_clear_error(tmp_path, meta_line):
    path = tmp_path / "evaluation.csv"
    path.write_text(meta_line + "\na,b\n1,2\n")
    with pytest.raises(results.SchemaVersionError, match=r"'# meta:' line is not"):
        results.read_csv(path)
