"""`distgprl.experiments.sweep_record`: the requests of the sweeps into a root are recorded,
so that `distgprl status` without a selection reports the runs they asked for (after
``sweep --seeds 0`` those, not every seed of the preset)."""

from __future__ import annotations

from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.experiments import sweep
from distgprl.experiments.sweep_record import (
    record_request,
    recorded_requests,
    requested_jobs,
    sweeps_file,
)
from distgprl.identity import resolve_run
from distgprl.schema import run_dir, write_json


def test_the_runs_asked_for_are_the_union_of_the_recorded_requests(tmp_path):
    assert requested_jobs(tmp_path, "ci") is None
    record_request(tmp_path, "ci", ["gprl-d"], ["dcp"], [0])
    record_request(tmp_path, "ci", ["gprl-d"], ["dcp"], [0])  # the same request: once
    assert len(recorded_requests(tmp_path, "ci")) == 1
    record_request(tmp_path, "ci", ["gprl-d", "gprl"], None, [1])
    names = [job.name for job in requested_jobs(tmp_path, "ci")]
    assert names == [
        "dcp/gprl-d/seed0",
        "dcp/gprl-d/seed1",
        "dbm/gprl-d/seed1",
        "dcp/gprl/seed1",
        "dbm/gprl/seed1",
    ]
    record_request(tmp_path, "ci", None, None, None)  # the whole preset
    assert len(requested_jobs(tmp_path, "ci")) == len(sweep.plan_jobs("ci", root=tmp_path))


def test_an_unreadable_record_or_a_request_no_longer_valid_is_left_out(tmp_path):
    sweeps_file(tmp_path, "ci").parent.mkdir(parents=True)
    sweeps_file(tmp_path, "ci").write_text("not json")
    assert recorded_requests(tmp_path, "ci") == [] and requested_jobs(tmp_path, "ci") is None
    sweeps_file(tmp_path, "ci").write_text('[{"methods": ["no-such-method"], "tasks": null}]')
    assert requested_jobs(tmp_path, "ci") is None


def test_status_after_a_sweep_of_seed_0_reports_the_seed_0_runs(tmp_path, monkeypatch):
    def fake_job(job):
        run = resolve_run(job.task, job.method, job.seed, job.preset)
        folder = run_dir(job.root, job.preset, job.task, job.method, job.seed)
        done = {"steps": run.config.run.total_steps, "train_wall_time_s": 10.0}
        write_json(folder / "done.json", done, kind="done", config_hash=run.hash)
        return sweep.JobResult(job, "done", 10.0)

    monkeypatch.setattr(sweep, "run_job", fake_job)
    root = ["--root", str(tmp_path)]
    swept = CliRunner().invoke(
        app,
        ["sweep", "--preset", "ci", "--methods", "gprl-d", "--seeds", "0", "--workers", "1"]
        + ["--no-repair-evaluations", *root],
    )
    assert swept.exit_code == 0, swept.output
    result = CliRunner().invoke(app, ["status", "--preset", "ci", *root])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0].startswith(f"the runs the sweeps into {tmp_path} asked for (1 request(s)")
    assert "2/2 done" in lines and "training left: none" in lines
    everything = CliRunner().invoke(app, ["status", "--preset", "ci", "--seeds", "0,1", *root])
    total = len(sweep.plan_jobs("ci", seeds=[0, 1], root=tmp_path))
    assert f"2/{total} done" in everything.output  # asked for: every seed given
