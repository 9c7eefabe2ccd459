"""End-to-end hardware trials on the digital twin and, in dry-run, on the fake UR."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.experiments.trial_policy import load_trial_policy
from distgprl.hardware.trials import run_trials
from distgprl.hardware.twin import TwinConfig, TwinSim, twin_calibration
from distgprl.methods import TABLE_ORDER
from distgprl.schema import TRIAL_FIELDS, read_csv

SMALL = TwinConfig(width=640, height=480)


# via-points; residual ProMP weights (v5's ProMP-RRL); residual RL (Table I's ProMP-RRL)
@pytest.mark.parametrize("method", ["dist-gprl", "promp-rrl-windowed", "promp-rrl"])
def test_twin_trials_end_to_end(tmp_path, untrained_dbm_policy, method):
    from distgprl.report.table2 import hardware_table

    policy_zip = untrained_dbm_policy(method)
    report = run_trials(
        trials=2,
        method=method,
        seed=0,
        root=tmp_path,
        preset="ci",
        model_path=policy_zip,
        twin_config=SMALL,
        echo=lambda _: None,
        protocol="safety-layer",
        load_policy=load_trial_policy,
    )
    assert report.path.parent == tmp_path / "hardware" / method
    meta, rows = read_csv(report.path)
    assert meta["backend"] == "twin" and meta["method"] == method
    assert meta["protocol"] == "safety-layer"
    from distgprl.io import file_sha256

    assert meta["policy"]["model_sha256"] == file_sha256(policy_zip)
    assert list(rows[0]) == list(TRIAL_FIELDS) and len(rows) == 2
    for row in rows:
        assert row["status"] in ("ok", "refused", "stopped")
        assert row["success"] in ("0", "1") and row["collision"] in ("0", "1")
        assert np.isfinite(float(row["min_clearance"]))
        assert row["clearance_source"] == "sim"
        assert float(row["perception_error_mm"]) < 100.0  # small images: coarse, but known
        assert int(row["images"]) >= 1 and float(row["trial_s"]) > 0
        # the perceived TC agrees with the true one to within the perception error
        assert abs(float(row["object_offset_y"]) - float(row["true_object_offset_y"])) < 0.03
    assert report.summary["judged"] == 2
    assert meta["checked_unit"] == ("RL step" if method == "promp-rrl" else "window")
    layer = meta["safety_layer"]  # which safety layer ran, nothing skipped silently
    assert layer["checked_unit"] == meta["checked_unit"] and layer["unsafe"] == "refused"
    assert (layer["retime"], layer["push"]) == ("on", "off")
    if method == "promp-rrl":  # a decision and a check per 0.1 s step, an image per window
        for row in rows:
            reached = len(row["repair"].split(";"))
            assert reached > 3 and int(row["images"]) == sum(s < reached for s in (0, 17, 34))
    if method not in TABLE_ORDER:  # an exploration method is no Table II row
        assert all(row["method"] != method for row in hardware_table(tmp_path, "ci"))
        return
    table = hardware_table(tmp_path, "ci")
    assert table[0]["method"] == method and table[0]["trials"] == 2
    assert table[0]["refused"] == sum(row["status"] == "refused" for row in rows)


def test_operator_judge_and_forced_plans(tmp_path):
    answers = iter(["maybe", "y", "n", "n", "y"])
    report = run_trials(
        trials=2,
        method="demo",
        seed=4,
        root=tmp_path,
        judge="operator",
        force=True,
        protocol="safety-layer",
        twin_config=SMALL,
        ask=lambda _: next(answers),
        echo=lambda _: None,
    )
    assert [r["success"] for r in report.rows] == [1, 0]
    assert [r["collision"] for r in report.rows] == [0, 1]
    assert all(r["status"] != "refused" for r in report.rows)  # force executes anyway


def test_dry_run_twin_never_moves(tmp_path):
    report = run_trials(
        trials=1,
        method="demo",
        seed=1,
        root=tmp_path,
        dry_run=True,
        twin_config=SMALL,
        echo=lambda _: None,
        protocol="safety-layer",  # the paper's protocol predicts no clearance
    )
    row = report.rows[0]
    assert report.path.parent == tmp_path / "hardware" / "dry-run" / "demo"
    assert row["status"] in ("planned", "refused") and row["success"] == ""
    assert row["execution_s"] == 0.0 and np.isfinite(row["planned_min_clearance"])
    assert not (tmp_path / "hardware" / "demo").exists()  # Table II never sees plans


class TwinCamera:
    """Feeds the fake UR backend images of a twin cell (the UR clock is not the sim's)."""

    def __init__(self, config: TwinConfig) -> None:
        from distgprl.sim.tasks.base import TaskConfig

        self.sim = TwinSim(config)
        self.sim.reset(TaskConfig((0.0, 0.05), (0.0, -0.05)))
        self.closed = False

    def capture(self):
        return self.sim.capture(None), 0.0

    def close(self):
        self.closed = True
        self.sim.close()


def test_dry_run_on_the_ur_sends_no_motion(tmp_path, model_sim):
    from fake_rtde import FakeRTDE  # tests/hardware is on sys.path (rootdir conftest)

    from distgprl.hardware.perception import save_calibration

    calibration = save_calibration(tmp_path / "cell.yaml", twin_calibration(SMALL))
    fake = FakeRTDE(model_sim.start_joint_positions, model_sim.robot.fk)
    camera = TwinCamera(SMALL)
    lines: list[str] = []
    report = run_trials(
        trials=1,
        method="demo",
        backend="ur",
        robot_ip="10.0.0.2",
        camera=camera,
        calibration=calibration,
        dry_run=True,
        root=tmp_path,
        rtde_factory=fake.factory,
        ask=lambda _: pytest.fail("a dry run must not prompt"),
        echo=lines.append,
        protocol="safety-layer",
    )
    assert report.rows[0]["status"] in ("planned", "refused")
    # the ur backend goes through the same repair path and prints its per-window decisions
    decisions = report.rows[0]["repair"].split(";")
    assert len([line for line in lines if ", window " in line]) == len(decisions) >= 1
    moving = {"servoJ", "moveJ", "speedJ", "servoL", "moveL"}
    assert not moving & set(fake.names())
    assert "stopScript" in fake.names() and camera.closed


def test_clear_errors(tmp_path):
    with pytest.raises(UserInputError, match="no trained model"):
        run_trials(trials=1, root=tmp_path, twin_config=SMALL, load_policy=load_trial_policy)
    with pytest.raises(UserInputError, match="policy loader"):
        run_trials(trials=1, root=tmp_path, twin_config=SMALL)  # a trained method, no loader
    with pytest.raises(UserInputError, match="calibration"):
        run_trials(trials=1, method="demo", backend="ur", robot_ip="10.0.0.2", root=tmp_path)
    with pytest.raises(UserInputError, match="not found"):
        run_trials(trials=1, method="demo", calibration=tmp_path / "x.yaml", root=tmp_path)
    with pytest.raises(UserInputError, match="unknown method"):
        run_trials(trials=1, method="dmp", root=tmp_path)
    with pytest.raises(UserInputError, match="backend"):
        run_trials(trials=1, method="demo", backend="kuka", root=tmp_path)


def test_unreachable_robot_is_a_user_error(tmp_path):
    def unreachable(ip):
        from distgprl.hardware.backends import _default_rtde_factory

        return _default_rtde_factory(ip)  # ur_rtde is not installed in the test venv

    calibration = tmp_path / "cell.yaml"
    from distgprl.hardware.perception import save_calibration

    save_calibration(calibration, twin_calibration(SMALL))
    with pytest.raises(UserInputError, match="ur_rtde|cannot reach"):
        run_trials(
            trials=1,
            method="demo",
            backend="ur",
            robot_ip="10.0.0.2",
            camera="0",
            calibration=calibration,
            root=tmp_path,
            rtde_factory=unreachable,
        )


def test_trial_summary_min_clearance_is_over_trials_that_moved_the_robot():
    """The CLI's trial summary uses Table II's MinCl: the 5th percentile over trials that
    moved the robot only (a refusal before any motion keeps the start pose's clearance)."""
    from distgprl.hardware.trial_rows import summarise_trials

    def row(status, execution, clearance, success="0", collision="0"):
        return {
            "status": status,
            "execution_s": execution,
            "min_clearance": clearance,
            "success": success,
            "collision": collision,
            "trial_s": "1.0",
        }

    rows = [
        row("ok", "2.0", "0.010", success="1"),
        row("refused", "0.0", "0.060"),  # refused before moving: start-pose clearance
        row("refused", "0.7", "-0.002"),  # refused in a later window, after moving
    ]
    summary = summarise_trials(rows)
    assert summary["judged"] == 3 and summary["moved"] == 2 and summary["refused"] == 2
    assert summary["min_clearance_p5"] == pytest.approx(np.percentile([0.010, -0.002], 5))
    assert summary["success_rate"] == pytest.approx(1 / 3)
    only_refused = summarise_trials([row("refused", "0.0", "0.060")])
    assert only_refused["moved"] == 0 and "min_clearance_p5" not in only_refused
    from distgprl.hardware.trial_rows import describe_summary, describe_trial

    # printed as the sweep and the CLI print it: the protocol's stops, MinCl in mm
    assert describe_summary(summary, "safety-layer") == (
        "success 0.33, collision 0.00, refused 2 of 3, "
        f"MinCl {1000 * summary['min_clearance_p5']:.1f} mm"
    )
    assert describe_summary(only_refused, "paper").startswith(
        "success 0.00, collision 0.00, protective stops 0 of 1"
    )
    assert "MinCl" not in describe_summary(only_refused, "paper")
    assert describe_summary(summarise_trials([]), "paper") == "no trial judged of 0"
    assert describe_trial(rows[0]) == "ok, success 1, collision 0, min clearance 10.0 mm"
    assert describe_trial({**rows[1], "success": "", "min_clearance": ""}) == "refused"


def test_too_fast_plans_are_retimed_not_refused(tmp_path):
    """Under a 0.6 rad/s joint-speed limit the demo's plans are too fast: with repair they
    are re-timed (recorded per window), without it the first window is refused."""
    from distgprl.limits import SafetyLimits
    from distgprl.safety_layer.repair import DECISIONS

    slow = SafetyLimits(max_joint_speed=0.6)
    kwargs = dict(
        trials=1, method="demo", seed=1, root=tmp_path, twin_config=SMALL, protocol="safety-layer"
    )
    repaired = run_trials(limits=slow, echo=lambda _: None, **kwargs).rows[0]
    decisions = repaired["repair"].split(";")
    assert decisions[0] == "retimed" and set(decisions) <= set(DECISIONS)
    added = [float(v) for v in repaired["repair_added_s"].split(";")]
    moved = [float(v) for v in repaired["repair_displacement_m"].split(";")]
    assert len(added) == len(moved) == len(decisions) and added[0] > 0.0
    assert all(m > 0 for m, d in zip(moved, decisions, strict=True) if d == "repaired")
    assert repaired["refused_limits"] not in ("joint_speed", "joint_acceleration")
    assert float(repaired["execution_s"]) > 0.0  # the re-timed window moved the robot

    report = run_trials(limits=slow, repair=False, echo=lambda _: None, **kwargs)
    plain = report.rows[0]
    assert plain["status"] == "refused" and plain["refused_limits"] == "joint_speed"
    assert plain["repair"] == "refused" and plain["repair_added_s"] == "0.000"
    meta, rows = read_csv(report.path)
    assert meta["repair"] is False and rows[0]["repair"] == "refused"


def test_dry_run_prints_the_window_decisions(tmp_path):
    lines: list[str] = []
    report = run_trials(
        trials=1,
        method="demo",
        seed=1,
        root=tmp_path,
        dry_run=True,
        twin_config=SMALL,
        echo=lines.append,
        protocol="safety-layer",
    )
    windows = [line for line in lines if ", window " in line]
    assert len(windows) == len(report.rows[0]["repair"].split(";")) >= 1
    assert all(
        line.split(": ", 1)[1].split()[0] in {"none", "retimed:", "repaired:", "refused"}
        for line in windows
    )


def test_sensor_noise_level_is_recorded_with_the_perception_error(tmp_path):
    report = run_trials(
        trials=1,
        method="demo",
        seed=2,
        root=tmp_path,
        twin_config=SMALL,
        sensor_noise=1,
        echo=lambda _: None,
    )
    meta, rows = read_csv(report.path)
    assert meta["sensor_noise"] == 1
    assert 0.0 < float(rows[0]["perception_error_mm"]) < 100.0
    with pytest.raises(UserInputError, match="sensor noise level"):
        run_trials(trials=1, method="demo", root=tmp_path, twin_config=SMALL, sensor_noise=5)


def test_cli_passes_repair_sensor_noise_and_the_protocol(monkeypatch, tmp_path):
    """`distgprl hardware --no-repair --sensor-noise 2 --protocol safety-layer` reaches
    run_trials; the paper's protocol and the final policy are the defaults; noise 5 and an
    unknown policy are rejected."""
    from pathlib import Path

    from typer.testing import CliRunner

    import distgprl.hardware.trials as trials
    from distgprl.cli import app

    seen = {}

    def fake_run_trials(**kwargs):
        seen.update(kwargs)
        return trials.TrialReport([], Path(tmp_path / "t.csv"), trials.summarise_trials([]))

    monkeypatch.setattr(trials, "run_trials", fake_run_trials)
    runner = CliRunner()
    command = ["hardware", "--no-repair", "--sensor-noise", "2", "--protocol", "safety-layer"]
    result = runner.invoke(app, command)
    assert result.exit_code == 0, result.output
    assert seen["repair"] is False and seen["sensor_noise"] == 2
    assert seen["protocol"] == "safety-layer"
    # the run's final policy, the one Table II counts, by default
    assert seen["load_policy"].func is load_trial_policy
    assert seen["load_policy"].keywords == {"policy": "final"}
    assert runner.invoke(app, ["hardware"]).exit_code == 0
    assert seen["repair"] is True and seen["sensor_noise"] == 0 and seen["protocol"] == "paper"
    assert runner.invoke(app, ["hardware", "--sensor-noise", "5"]).exit_code != 0
    assert runner.invoke(app, ["hardware", "--policy", "latest"]).exit_code == 2


@pytest.fixture
def recorded_trials(monkeypatch, tmp_path):
    """The keyword arguments of each `run_trials` call the CLI makes (none is run)."""
    import distgprl.hardware.trials as trials

    called = []

    def fake_run_trials(**kwargs):
        called.append(kwargs)
        return trials.TrialReport([], tmp_path / "t.csv", trials.summarise_trials([]))

    monkeypatch.setattr(trials, "run_trials", fake_run_trials)
    return called


def test_the_cli_refuses_the_safety_layers_repair_options_under_the_papers_protocol(
    recorded_trials,
):
    """The paper's protocol has no check to repair for: ``--no-repair``, ``--repair`` or
    ``--repair-push`` with it is a user error (exit 2, naming the protocol to use) before any
    trial, not a flag silently dropped; with ``--protocol safety-layer`` they pass."""
    from typer.testing import CliRunner

    from distgprl.cli import app

    called = recorded_trials
    runner = CliRunner()
    for flag in ("--no-repair", "--repair", "--repair-push"):
        result = runner.invoke(app, ["hardware", flag])
        assert result.exit_code == 2, (flag, result.output)
        assert "--protocol safety-layer" in result.output
    assert called == []
    result = runner.invoke(app, ["hardware", "--protocol", "safety-layer", "--repair-push"])
    assert result.exit_code == 0, result.output
    assert called[0]["repair"] is True and called[0]["repair_config"].repair is True


def test_the_cli_refuses_options_the_trials_would_not_read(recorded_trials):
    """An option the trials would not read is a user error (exit 2, naming what to do) before
    any trial, not dropped: ``--robot-ip`` / ``--camera`` with the twin, ``--sensor-noise``
    with the ur backend, ``--model`` or ``--policy`` for a reference (no trained policy),
    ``--model`` with ``--policy best`` (two policies named), ``--judge operator`` with
    ``--dry-run`` (nothing moved to judge). Where they apply they pass."""
    from typer.testing import CliRunner

    from distgprl.cli import app

    called = recorded_trials
    runner = CliRunner()
    refused = {
        ("--backend", "twin", "--robot-ip", "10.0.0.2"): "--backend ur",
        ("--camera", "0"): "--backend ur",
        ("--backend", "twin", "--robot-ip", "10.0.0.2", "--camera", "0"): "--backend ur",
        ("--robot-ip", "10.0.0.2", "--sensor-noise", "0"): "--backend twin",
        ("--backend", "ur", "--sensor-noise", "2"): "--backend twin",
        ("--method", "demo", "--model", "m.zip"): "leave them out",
        ("--method", "promp-nominal", "--model", "m.zip"): "leave them out",
        ("--method", "demo", "--policy", "final"): "leave them out",
        ("--model", "m.zip", "--policy", "best"): "give one of them",
        ("--dry-run", "--judge", "operator"): "drop one of them",
    }
    for options, advice in refused.items():
        result = runner.invoke(app, ["hardware", *options])
        assert result.exit_code == 2, (options, result.output)
        assert len(result.output.strip().splitlines()) == 1 and advice in result.output
    assert called == []
    accepted = [
        ("--robot-ip", "10.0.0.2", "--camera", "0"),  # the ur backend, as --robot-ip implies
        ("--backend", "twin", "--sensor-noise", "2", "--judge", "operator"),
        ("--method", "dist-gprl", "--model", "m.zip"),
        ("--method", "demo", "--dry-run"),
        ("--policy", "best"),
    ]
    for options in accepted:
        result = runner.invoke(app, ["hardware", *options])
        assert result.exit_code == 0, (options, result.output)
    assert [kwargs["backend"] for kwargs in called] == ["ur", "twin", "twin", "twin", "twin"]
    assert called[-1]["load_policy"].keywords == {"policy": "best"}
    assert called[0]["sensor_noise"] == 0 and called[1]["sensor_noise"] == 2


def test_the_promp_nominal_reference_runs_in_the_twin_one_rl_step_at_a_time(tmp_path):
    """Residual control has no window plan: the twin trial of ProMP-RRL's nominal (zero
    residual) decides and checks every 0.1 s RL step before it moves (50 per DBM trial when
    none is refused), with a fresh image at the first step of each window's span as the
    via-point methods get, and records that in the trial file."""
    report = run_trials(
        trials=1,
        method="promp-nominal",
        seed=0,
        root=tmp_path,
        preset="ci",
        twin_config=SMALL,
        echo=lambda _: None,
        protocol="safety-layer",
    )
    meta, rows = read_csv(report.path)
    assert meta["checked_unit"] == "RL step" and meta["policy"] == {}
    decisions = rows[0]["repair"].split(";")
    assert set(decisions) <= {"none", "retimed", "refused"}
    assert int(rows[0]["images"]) == sum(step < len(decisions) for step in (0, 17, 34))
    if rows[0]["status"] == "ok":
        assert len(decisions) == 50
    else:
        assert rows[0]["status"] == "refused" and decisions[-1] == "refused"


def test_an_unsafe_rl_step_is_retimed_or_refused_before_it_moves_and_never_pushed(tmp_path):
    """Residual control's safety layer at the control rate: under a 0.6 rad/s joint-speed
    limit one of the nominal's RL steps is too fast. Without repair it is refused before it
    moves (the trial ends there, naming the limit, its earlier steps executed); with repair
    it is re-timed (time added, recorded per step) and the trial goes on. The via-point push
    does not apply (no via-points): asked for, it is said so once and in the file's meta,
    never run (no step is `repaired`), and the file counts as the retiming setting."""
    from distgprl.limits import SafetyLimits
    from distgprl.safety_layer.retime import RepairConfig
    from distgprl.safety_layer.window_check import NO_VIA_POINTS

    kwargs = dict(
        trials=1,
        method="promp-nominal",
        seed=1,
        root=tmp_path,
        preset="ci",
        twin_config=SMALL,
        # a speed limit only: the clearance margin off (this test is about retiming)
        limits=SafetyLimits(max_joint_speed=0.6, min_clearance=-1.0),
        protocol="safety-layer",
    )
    plain = run_trials(repair=False, echo=lambda _: None, **kwargs)
    meta, rows = read_csv(plain.path)
    row = rows[0]
    decisions = row["repair"].split(";")
    assert row["status"] == "refused" and row["refused_limits"] == "joint_speed"
    assert decisions[-1] == "refused" and set(decisions[:-1]) == {"none"}
    assert "nothing was moved" in row["stop_reason"] and float(row["execution_s"]) > 0.0
    assert meta["safety_layer"] == {
        "checked_unit": "RL step",
        "check": meta["safety_layer"]["check"],
        "unsafe": "refused",
        "retime": "off",
        "push": "off",
    }

    lines: list[str] = []
    pushed = run_trials(repair_config=RepairConfig(repair=True), echo=lines.append, **kwargs)
    meta, rows = read_csv(pushed.path)
    retimed = rows[0]["repair"].split(";")
    assert retimed[: len(decisions)] == decisions[:-1] + ["retimed"]
    assert "repaired" not in retimed and len(retimed) > len(decisions)
    added = [float(v) for v in rows[0]["repair_added_s"].split(";")]
    assert all((a > 0.0) == (d == "retimed") for a, d in zip(added, retimed, strict=True))
    assert meta["repair"] is True and meta["repair_push"] is False
    assert meta["safety_layer"]["retime"] == "on" and meta["safety_layer"]["push"] == NO_VIA_POINTS
    assert lines[0] == f"promp-nominal: --repair-push {NO_VIA_POINTS}; retiming only"
    from distgprl.report.table2 import repair_label

    assert repair_label(meta) == "retime"


def test_a_residual_trial_on_the_ur_streams_its_rl_steps_without_stopping_between(
    tmp_path, model_sim
):
    """On the UR (fake RTDE), a residual-control trial streams its checked 0.1 s RL steps
    back to back: servo mode is ended after the last step (or by the stop after a
    refusal), never between steps (it was: a servoStop, a braking to standstill, after each
    of the 50)."""
    from fake_rtde import FakeRTDE  # tests/hardware is on sys.path (rootdir conftest)

    from distgprl.hardware.perception import save_calibration

    calibration = save_calibration(tmp_path / "cell.yaml", twin_calibration(SMALL))
    fake = FakeRTDE(model_sim.start_joint_positions, model_sim.robot.fk)
    answers = iter(["", "n", "n"])  # place the bars; lifted? touched?
    report = run_trials(
        trials=1,
        method="promp-nominal",
        backend="ur",
        robot_ip="10.0.0.2",
        camera=TwinCamera(SMALL),
        calibration=calibration,
        judge="operator",
        root=tmp_path,
        preset="ci",
        rtde_factory=fake.factory,
        ask=lambda _: next(answers),
        echo=lambda _: None,
        protocol="safety-layer",
    )
    row = report.rows[0]
    steps = len(row["repair"].split(";"))
    assert row["status"] in ("ok", "refused") and steps > 1
    names = fake.names()
    servo = [i for i, name in enumerate(names) if name == "servoJ"]
    assert len(servo) >= 5 * 2 * (steps - 1)  # 125 Hz, 2-3 control periods per step
    assert names.index("servoStop") > servo[-1]  # the stream ended after the last step only
    assert names[-5:] == [  # and closing the connection stops the robot once more
        "servoStop",
        "stopJ",
        "stopScript",
        "disconnect_control",
        "disconnect_receive",
    ]
