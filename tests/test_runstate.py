"""One verdict per run folder: each kind of damaged file (malformed summary.json, malformed
done.json, an unknown schema_version, malformed progress.csv, evaluation.csv gone from a
finished run) is `damaged`, naming the file, in `status`, `sweep`, `tables` and `curves`
alike; the sweep retrains a damaged run only when told to; the verdict module imports
neither torch nor pybullet."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.experiments import sweep
from distgprl.experiments.status import run_status
from distgprl.identity import resolve_run
from distgprl.report.curves import write_curves
from distgprl.report.tables import write_tables
from distgprl.runstate import DamagedRunError, job_state, run_state
from distgprl.schema import EVALUATION_FIELDS, PROGRESS_FIELDS, run_dir, write_csv, write_json

TASK, METHOD, SEED, PRESET = "dcp", "gprl-d", 0, "ci"


def finished_run(root):
    """A finished, evaluated `ci` dcp/gprl-d/seed0 run of the current configuration."""
    folder = run_dir(root, PRESET, TASK, METHOD, SEED)
    run = resolve_run(TASK, METHOD, SEED, PRESET)
    meta = {"config_hash": run.hash, "seed": SEED}
    write_json(folder / "config.json", {"run": run.to_dict(), "config_hash": run.hash}, **meta)
    curve = []
    for step in (0, 120, 240):
        row = dict.fromkeys(PROGRESS_FIELDS, 0.0)
        row.update(step=step, episodes=step // 3, success_rate=step / 480, wall_time_s=step / 10)
        row.update(l_sim="", l_hap="")
        curve.append(row)
    write_csv(folder / "progress.csv", curve, PROGRESS_FIELDS, **meta)
    episodes = [{**dict.fromkeys(EVALUATION_FIELDS, 0.0), "episode": k} for k in range(4)]
    for k, row in enumerate(episodes):
        row.update(success=int(k < 2), collision=0, min_clearance=0.02)
    write_csv(folder / "evaluation.csv", episodes, EVALUATION_FIELDS, **meta)
    summary = {
        "episodes": 4,
        "success_rate": 0.5,
        "collision_rate": 0.0,
        "safe_success_rate": 0.5,
        "min_clearance_p5": 0.02,
        "mean_kinematic_retention": 0.9,
    }
    write_json(folder / "summary.json", {"summary": summary}, **meta)
    write_json(folder / "done.json", {"steps": 240, "train_wall_time_s": 24.0}, **meta)
    return folder


def _unknown_schema(folder):
    path = folder / "summary.json"
    document = json.loads(path.read_text())
    document["meta"]["schema_version"] = 999
    path.write_text(json.dumps(document))
    return "summary.json", "schema_version 999 is not supported"


def _malformed(name, text, reason):
    def damage(folder):
        (folder / name).write_text(text)
        return name, reason

    return damage


def _progress_without_meta(folder):
    (folder / "progress.csv").write_text("step,success\n0,1\n")
    (folder / "progress.csv.meta.json").unlink(missing_ok=True)
    return "progress.csv", "no metadata"


def _no_evaluation(folder):
    (folder / "evaluation.csv").unlink()
    return "evaluation.csv", "missing, although done.json and summary.json"


DAMAGES = {
    "malformed summary.json": _malformed("summary.json", '{"summary": {', "not valid JSON"),
    "malformed done.json": _malformed("done.json", '{"steps": 240', "not valid JSON"),
    "unknown schema_version": _unknown_schema,
    "progress.csv without metadata": _progress_without_meta,
    "evaluation.csv missing with a done.json": _no_evaluation,
}


def _job(root):
    return sweep.plan_jobs(PRESET, [METHOD], [TASK], [SEED], root=root)[0]


def _invoke(*args):
    return CliRunner().invoke(app, list(args))


def _report(command, root, out):
    """`distgprl tables` or `curves` of the `ci` preset under ``root`` into ``out``."""
    return _invoke(command, "--preset", PRESET, "--root", str(root), "--out-dir", str(out))


def test_an_undamaged_finished_run_is_done_everywhere(tmp_path):
    """The baseline the damaged cases change: done in status, skipped by the sweep,
    tabulated and plotted (exit 0)."""
    finished_run(tmp_path)
    job = _job(tmp_path)
    assert job_state(tmp_path, PRESET, TASK, METHOD, SEED).verdict == "done"
    assert run_status(job).state == "done"
    assert sweep.run_sweep([job])[0].status == "skipped"
    out = tmp_path / "out"
    for command in ("tables", "curves"):
        result = _invoke(
            command, "--preset", PRESET, "--root", str(tmp_path), "--out-dir", str(out)
        )
        assert result.exit_code == 0, result.output


@pytest.mark.parametrize("case", list(DAMAGES))
def test_a_damaged_file_gets_the_same_verdict_in_status_sweep_tables_and_curves(tmp_path, case):
    folder = finished_run(tmp_path)
    name, reason = DAMAGES[case](folder)
    damaged = folder / name
    job = _job(tmp_path)

    state = job_state(tmp_path, PRESET, TASK, METHOD, SEED)
    assert (state.verdict, state.file) == ("damaged", damaged) and reason in state.reason

    status = run_status(job)  # status: listed as damaged with the file and the reason
    assert status.state == "damaged" and status.error == state.describe()
    printed = _invoke(
        "status", "--preset", PRESET, "--methods", METHOD, "--tasks", TASK, "--seeds", "0",
        "--root", str(tmp_path),
    )  # fmt: skip
    assert printed.exit_code == 0
    assert "damaged" in printed.output and str(damaged) in printed.output

    before = {path.name: path.read_bytes() for path in folder.iterdir()}
    (result,) = sweep.run_sweep([job])  # sweep: reported, left alone
    assert result.status == "damaged" and result.error == state.describe()
    assert {path.name: path.read_bytes() for path in folder.iterdir()} == before
    swept = _invoke(
        "sweep", "--preset", PRESET, "--methods", METHOD, "--tasks", TASK, "--seeds", "0",
        "--root", str(tmp_path), "--workers", "1", "--heartbeat", "0",
    )  # fmt: skip
    assert swept.exit_code == 1 and str(damaged) in swept.output
    assert "1 damaged (--retrain-damaged retrains them)" in swept.output

    for command in ("tables", "curves"):  # reports: exit 2 naming the file
        out = tmp_path / f"out-{command}"
        result = _invoke(
            command, "--preset", PRESET, "--root", str(tmp_path), "--out-dir", str(out)
        )
        assert result.exit_code == 2, (command, result.output)
        assert f"damaged run {damaged}" in result.output and reason in result.output
        assert not out.exists()
    with pytest.raises(DamagedRunError, match=f"damaged run {damaged}"):
        write_curves(tmp_path, PRESET, tmp_path / "out")
    with pytest.raises(DamagedRunError, match=f"damaged run {damaged}"):
        write_tables(tmp_path, PRESET, tmp_path / "out")


def test_the_sweep_retrains_a_damaged_run_only_when_told_to(tmp_path, monkeypatch):
    """With ``retrain_damaged`` the damaged run's folder is removed and the run trained anew
    (from scratch, no resume); without it, nothing is trained."""
    folder = finished_run(tmp_path)
    (folder / "done.json").write_text("{")
    trained = []

    def fake_train(task, method, seed, preset, resume, root, show_progress):
        trained.append((task, method, seed, resume, sorted(p.name for p in folder.glob("*"))))

    monkeypatch.setattr(sweep, "train_run", fake_train)
    assert sweep.run_sweep([_job(tmp_path)])[0].status == "damaged" and not trained
    (result,) = sweep.run_sweep([_job(tmp_path)], retrain_damaged=True)
    assert result.status == "done"
    assert trained == [(TASK, METHOD, SEED, False, [])]


def test_other_verdicts_from_the_folder_alone(tmp_path):
    """missing (no folder, or only a lock file), partial (started), stale (finished with
    another hash), done without a hash to check against (unknown preset)."""
    folder = run_dir(tmp_path, PRESET, TASK, METHOD, SEED)
    assert run_state(folder, True, "h").verdict == "missing"
    folder.mkdir(parents=True)
    (folder / ".lock").write_text("")
    assert run_state(folder, True, "h").verdict == "missing"
    write_json(folder / "config.json", {"config_hash": "h"}, config_hash="h")
    assert run_state(folder, True, "h").verdict == "partial"
    finished_run(tmp_path)
    assert run_state(folder, True, "another").verdict == "stale"
    assert run_state(folder, True, None).verdict == "done"
    (folder / "progress.csv").write_text(
        (folder / "progress.csv").read_text().replace("\n120,", "\ntwelve,")
    )
    state = run_state(folder, True, None)  # a changed file is seen at once (no stale cache)
    assert state.verdict == "damaged" and "row 2 has no integer 'step' ('twelve')" in state.reason


def test_the_verdict_module_imports_neither_torch_nor_pybullet(tmp_path):
    folder = finished_run(tmp_path)
    code = (
        "import sys; from distgprl.runstate import run_state; "
        f"print(run_state({str(folder)!r}, True, None).verdict, "
        "'torch' in sys.modules, 'pybullet' in sys.modules)"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert result.stdout.split() == ["done", "False", "False"]
