"""The results schema (distgprl/schema.py): versioned, atomic result IO."""

from __future__ import annotations

import json

import pytest

from distgprl import schema
from distgprl.errors import UserInputError


def test_json_round_trip_with_meta(tmp_path):
    path = schema.write_json(tmp_path / "a" / "x.json", {"value": [1, 2.5]}, seed=3)
    document = schema.read_json(path)
    assert document["value"] == [1, 2.5]
    meta = document["meta"]
    assert meta["schema_version"] == schema.SCHEMA_VERSION
    assert meta["seed"] == 3
    for key in ("package_version", "git_commit", "utc_time", "libraries"):
        assert key in meta
    assert "torch" in meta["libraries"]


def test_unknown_schema_version_is_a_clear_error(tmp_path):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"meta": {"schema_version": 999}}))
    with pytest.raises(schema.SchemaVersionError, match="schema_version 999 is not supported"):
        schema.read_json(path)


def test_csv_round_trip_and_version_check(tmp_path):
    """write_csv -> read_csv returns the rows and the meta; a CSV with no metadata at all
    (no sidecar, no '# meta:' line) is refused."""
    rows = [{"a": 1, "b": 0.5}, {"a": 2, "b": 1.5}]
    path = schema.write_csv(tmp_path / "r.csv", rows, ["a", "b"], seed=1)
    meta, back = schema.read_csv(path)
    assert meta["seed"] == 1 and back == [{"a": "1", "b": "0.5"}, {"a": "2", "b": "1.5"}]
    assert path.read_text() == "a,b\n1,0.5\n2,1.5\n"  # a plain CSV: header, then rows
    sidecar = schema.read_json(tmp_path / "r.csv.meta.json")
    assert sidecar["meta"] == meta and sidecar["columns"] == ["a", "b"]
    (tmp_path / "r.csv.meta.json").unlink()
    with pytest.raises(schema.SchemaVersionError, match="no metadata"):
        schema.read_csv(path)


def test_a_written_csv_reads_with_a_plain_pandas_read_csv(tmp_path):
    """pandas with its defaults sees the fields as the header and one row per record."""
    pandas = pytest.importorskip("pandas")
    rows = [{"episode": i, "success": i % 2, "min_clearance": 0.01 * i} for i in range(4)]
    path = schema.write_csv(tmp_path / "e.csv", rows, ["episode", "success", "min_clearance"])
    frame = pandas.read_csv(path)
    assert list(frame.columns) == ["episode", "success", "min_clearance"]
    assert frame["episode"].tolist() == [0, 1, 2, 3]
    assert frame["min_clearance"].tolist() == pytest.approx([0.0, 0.01, 0.02, 0.03])


def test_a_csv_of_the_earlier_format_with_a_meta_line_still_reads(tmp_path):
    """Committed results keep their first '# meta: {json}' line: read_csv takes the meta
    from it (and ignores any sidecar) and the rows from the rest."""
    meta = schema.result_meta(seed=4)
    path = tmp_path / "old.csv"
    path.write_text("# meta: " + json.dumps(meta, sort_keys=True) + "\na,b\n1,2\n3,4\n")
    read_meta, rows = schema.read_csv(path)
    assert read_meta["seed"] == 4 and rows == [{"a": "1", "b": "2"}, {"a": "3", "b": "4"}]


def test_csv_with_unknown_schema_version_names_the_file_and_version(tmp_path):
    """A CSV whose sidecar (or, earlier format, '# meta:' line) has schema_version 999 is
    refused, not guessed at: the SchemaVersionError names the file and the version."""
    path = schema.write_csv(tmp_path / "r.csv", [{"a": 1}], ["a"])
    sidecar = schema.csv_meta_path(path)
    document = json.loads(sidecar.read_text())
    assert document["meta"]["schema_version"] == schema.SCHEMA_VERSION
    document["meta"]["schema_version"] = 999
    sidecar.write_text(json.dumps(document))
    legacy = tmp_path / "legacy.csv"
    legacy.write_text("# meta: " + json.dumps(document["meta"]) + "\n" + path.read_text())
    for damaged, named in ((path, sidecar), (legacy, legacy)):
        with pytest.raises(schema.SchemaVersionError) as caught:
            schema.read_csv(damaged)
        message = str(caught.value)
        assert message.startswith(f"{named}: ")
        assert "schema_version 999 is not supported" in message
        assert f"this is schema {schema.SCHEMA_VERSION}" in message
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
        from distgprl.identity import resolve_run

        schema.write_json(
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
    assert lines[0].startswith(f"error: damaged run {summary}: ")  # the one RunState verdict
    assert "schema_version 999 is not supported" in lines[0]
    assert result.stdout == ""  # the error goes to stderr only
    assert not out.exists()


def test_git_commit_is_dirty_for_source_changes_only(tmp_path):
    import subprocess

    from distgprl.schema import source_commit

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
    with pytest.raises(schema.SchemaVersionError, match="no 'meta' object"):
        schema.read_json(path)


@pytest.mark.parametrize("meta_line", ["# meta: {not json", "# meta: [1]"])
def test_csv_with_a_garbled_meta_line_is_a_clear_error(tmp_path, meta_line):
    path = tmp_path / "evaluation.csv"
    path.write_text(meta_line + "\na,b\n1,2\n")
    with pytest.raises(schema.SchemaVersionError, match=r"'# meta:' line is not"):
        schema.read_csv(path)


def test_git_commit_is_the_commit_of_this_checkout():
    """`git_commit` looks at the repository that holds the package (one level above it)."""
    import subprocess
    from pathlib import Path

    import distgprl

    root = Path(distgprl.__file__).resolve().parents[1]
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True
    ).stdout.strip()
    assert schema.git_commit() in (head, head + "+dirty")


@pytest.mark.parametrize(
    ("episodes", "policy", "names"),
    [
        (None, "final", ("evaluation.csv", "summary.json")),
        (1000, "final", ("evaluation_n1000.csv", "summary_n1000.json")),
        (None, "best", ("evaluation_best.csv", "summary_best.json")),
        (50, "best", ("evaluation_best_n50.csv", "summary_best_n50.json")),
    ],
)
def test_evaluation_file_names(episodes, policy, names):
    """The preset's evaluation, supplementary ones and the best policy's have distinct names."""
    assert schema.evaluation_file_names(episodes, policy) == names


@pytest.mark.parametrize(
    ("episodes", "policy", "mode", "names"),
    [
        (None, "final", "repair", ("evaluation_repair.csv", "summary_repair.json")),
        (None, "final", "push", ("evaluation_repair_push.csv", "summary_repair_push.json")),
        (None, "final", "check", ("evaluation_check.csv", "summary_check.json")),
        (50, "best", "repair", ("evaluation_best_repair_n50.csv", "summary_best_repair_n50.json")),
    ],
)
def test_repair_evaluation_file_names(episodes, policy, mode, names):
    """The safety-layer evaluations have their own names, none of them a plain evaluation's
    (nor matching the supplementary ``evaluation_n*.csv`` the paired tests collect)."""
    assert schema.repair_evaluation_file_names(episodes, policy, mode) == names
    assert names[0] != schema.evaluation_file_names(episodes, policy)[0]
    assert not names[0].startswith("evaluation_n")
    with pytest.raises(UserInputError, match="unknown repair mode"):
        schema.repair_evaluation_file_names(mode="fix")


def test_unknown_policy_is_a_user_error():
    with pytest.raises(UserInputError, match="unknown policy 'worst'"):
        schema.evaluation_file_names(policy="worst")


def test_evaluation_fields_record_one_adaptation_time_per_schema_window():
    """The evaluation rows carry `adaptation_ms_w1..w<N_WINDOWS>`, and the presets' episodes
    have that many windows."""
    from distgprl.config import load_config

    timed = [f for f in schema.EVALUATION_FIELDS if f.startswith("adaptation_ms_w")]
    assert timed == [f"adaptation_ms_w{k + 1}" for k in range(schema.N_WINDOWS)]
    for preset in ("paper", "ci"):
        assert load_config(preset).env.n_windows == schema.N_WINDOWS


@pytest.mark.parametrize(
    ("trial", "moved"),
    [
        ({"status": "ok", "execution_s": ""}, True),
        ({"status": "refused", "execution_s": "1.5"}, True),
        ({"status": "refused", "execution_s": "0.0"}, False),
        ({"status": "not_perceived", "execution_s": ""}, False),
    ],
)
def test_moved_robot(trial, moved):
    """A trial moved the robot if it finished or spent execution time."""
    assert schema.moved_robot(trial) is moved


def test_safe_success_needs_success_and_no_collision():
    rows = [
        {"success": "1", "collision": "0"},
        {"success": "1", "collision": "1"},
        {"success": "0", "collision": "0"},
        {"success": 1, "collision": 0},
    ]
    assert [schema.is_safe_success(r) for r in rows] == [True, False, False, True]
    assert schema.safe_success_rate(rows) == 0.5


def test_every_committed_csv_of_the_earlier_format_still_reads():
    """Each CSV under results/ (results/archive/ included) with a '# meta:' first line, as
    the results committed before the sidecar were written, reads with `read_csv`: its meta
    with the schema version, and one row per line after the header."""
    from pathlib import Path

    results = Path(__file__).resolve().parents[1] / "results"
    legacy = [
        path for path in sorted(results.rglob("*.csv")) if path.read_text().startswith("# meta: ")
    ]
    assert legacy, f"{results}: the committed results of the earlier format are missing"
    assert any("archive" in path.parts for path in legacy)
    for path in legacy:
        meta, rows = schema.read_csv(path)
        assert meta["schema_version"] == schema.SCHEMA_VERSION, path
        lines = [line for line in path.read_text().splitlines()[2:] if line]
        assert len(rows) == len(lines), path


@pytest.mark.parametrize(
    ("meta", "current", "reason"),
    [
        ({"force": False, "dry_run": False, "policy": {"run_config_hash": "abc"}}, "abc", None),
        ({"force": True, "policy": {"run_config_hash": "abc"}}, "abc", "--force"),
        ({"dry_run": True}, None, "dry run"),
        ({"policy": {"run_config_hash": "old"}}, "abc", "policy config hash old"),
        ({}, "abc", "not recorded"),
        ({"policy": {"run_config_hash": "old"}}, None, None),
        ({"policy": {"run_config_hash": "abc", "policy": "best (shipped)"}}, "abc", "best"),
        ({"policy": {"run_config_hash": "abc", "policy": "final"}}, "abc", None),
        ({"policy": {"run_config_hash": "abc", "policy": "given"}}, "abc", None),
    ],
)
def test_trial_file_exclusion_names_why_table2_leaves_a_file_out(meta, current, reason):
    """A forced or dry-run trial file, one of a named policy other than Table II's (the final
    one), or one of a policy whose hash is not the current one (checked only where a current
    hash is given), is excluded with its reason; else counted."""
    got = schema.trial_file_exclusion(meta, current)
    if reason is None:
        assert got is None
    else:
        assert got is not None and reason in got
