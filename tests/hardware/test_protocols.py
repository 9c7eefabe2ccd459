"""Table II as the paper ran it (`distgprl.trial_protocol`): under the paper's protocol a
trajectory executes without the safety layer's pre-flight check; only the UR5e's own joint
speed and acceleration limits stop it (a protective stop: a failed trial with its reason,
not a refusal, not a collision); a contact is a collision."""

from __future__ import annotations

import math

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.hardware.backends import TwinBackend
from distgprl.hardware.controller import controller_stop
from distgprl.hardware.trials import run_trials
from distgprl.hardware.twin import TwinConfig
from distgprl.limits import UR5E_CONTROLLER, ControllerLimits, SafetyLimits
from distgprl.safety_layer.plan_check import UnsafePlanError, check_plan
from distgprl.schema import read_csv
from distgprl.sim.tasks.base import TaskConfig
from distgprl.sim.transforms import matrix_to_pose

SMALL = TwinConfig(width=640, height=480)
DT = 0.04  # the skill's control period, s


def test_the_ur5e_limits_are_its_documented_ones_and_looser_than_the_safety_layers():
    """pi rad/s (180 deg/s, every joint) and 40 rad/s^2; the safety layer's own are stricter."""
    assert UR5E_CONTROLLER.max_joint_speed == pytest.approx(math.pi)
    assert UR5E_CONTROLLER.max_joint_acceleration == 40.0
    safety = SafetyLimits()
    assert safety.max_joint_speed < UR5E_CONTROLLER.max_joint_speed
    assert safety.max_joint_acceleration < UR5E_CONTROLLER.max_joint_acceleration


Q0 = np.array([2.08, -1.60, 1.53, -1.49, -1.57, -2.63])  # near the twin's start, rad


def _ramp(speeds: list[float], q0: np.ndarray = Q0, joint: int = 5):
    """(q0 (6,), joint targets (n, 6)): ``joint`` (the last wrist) moving at ``speeds``
    (rad/s), one per control period, from ``q0``."""
    targets = np.tile(q0, (len(speeds), 1))
    targets[:, joint] += np.cumsum(np.asarray(speeds) * DT)
    return q0, targets


def test_controller_stop_finds_the_first_instant_beyond_a_limit():
    """Speeds ramped at 20 rad/s^2 up to 2.4 rad/s pass the UR5e; 3.2 rad/s (above pi) stops
    at its instant; a jump from rest to 1.8 rad/s (45 rad/s^2) stops on acceleration."""
    zero = np.zeros(6)
    q0, targets = _ramp([0.8, 1.6, 2.4, 2.4, 2.4])
    assert controller_stop(targets, q0, zero, DT) is None
    q0, targets = _ramp([0.8, 1.6, 2.4, 3.2, 3.2])
    stop = controller_stop(targets, q0, zero, DT)
    assert (stop.index, stop.limit, stop.joint) == (3, "joint_speed", 5)
    assert stop.value == pytest.approx(3.2) and stop.bound == pytest.approx(math.pi)
    assert "UR5e joint speed limit" in stop.reason() and "control step 3" in stop.reason()
    q0, targets = _ramp([1.8])
    stop = controller_stop(targets, q0, zero, DT)
    assert (stop.index, stop.limit) == (0, "joint_acceleration")
    assert stop.value == pytest.approx(45.0)
    # the same jump continues a motion already at 1.0 rad/s: 20 rad/s^2, no stop
    assert controller_stop(targets, q0, np.eye(6)[5] * 1.0, DT) is None


@pytest.fixture(scope="module")
def twin():
    backend = TwinBackend(SMALL)
    yield backend
    backend.close()


def _poses(backend: TwinBackend, targets: np.ndarray) -> np.ndarray:
    return np.array([matrix_to_pose(backend.sim.robot.fk(q)) for q in targets])


def _start(backend: TwinBackend) -> np.ndarray:
    backend.start_trial(TaskConfig((0.0, 0.05), (0.0, -0.05)))
    return backend.joint_positions()


def test_a_trajectory_the_safety_layer_refuses_executes_on_the_ur5e(twin):
    """2.4 rad/s on the wrist: above the safety layer's 2 rad/s (its pre-flight check
    refuses it, naming joint_speed) and below the UR5e's pi: the twin's arm runs all of it."""
    q0, targets = _ramp([0.8, 1.6, 2.4, 2.4, 2.4, 2.4], _start(twin))
    poses = _poses(twin, targets)
    with pytest.raises(UnsafePlanError, match="joint_speed"):
        check_plan(poses, q0, twin.sim.robot, SafetyLimits(), DT)
    result = twin.execute(targets, poses)
    assert not result.stopped and result.steps == len(poses)
    assert twin.moved_steps == len(poses) and not twin.collision


def test_a_command_beyond_the_ur5e_limit_ends_in_a_protective_stop_not_a_collision(twin):
    """3.2 rad/s on the wrist (above pi) at the 4th instant: the arm executes the first
    three targets, then the controller stops it; no contact, so no collision."""
    _, targets = _ramp([0.8, 1.6, 2.4, 3.2, 3.2], _start(twin))
    result = twin.execute(targets, _poses(twin, targets))
    assert result.stopped and result.protective_stop and result.steps == 3
    assert result.limit_stop == "joint_speed" and result.collision is False
    assert "protective stop (UR5e joint speed limit)" in result.stop_reason
    assert np.allclose(twin.velocity, 0.0)  # the arm stands after the stop


def test_a_contact_is_a_collision(twin):
    """Driving the tool slowly into the other bar: a contact stop, counted as a collision,
    not a limit stop."""
    _start(twin)
    start = twin.tcp_pose()
    steps = 50
    bar = np.asarray(twin.sim.other_bar_position_at(twin.now() + steps * DT), dtype=float)
    fraction = (1.0 - np.cos(np.linspace(0.0, np.pi, steps + 1)[1:])) / 2.0
    poses = np.tile(start, (steps, 1))
    poses[:, :3] = start[:3] + fraction[:, None] * (bar - start[:3])
    result = twin.execute(None, poses)
    assert result.stopped and result.collision is True and result.limit_stop == ""
    assert result.steps < steps and "contact" in result.stop_reason


def test_a_paper_protocol_trial_executes_unchecked_and_a_limit_stop_fails_it(tmp_path):
    """`run_trials` under the paper's protocol (the default): its file says so, no decision
    is checked (every entry ``unchecked``), nothing is refused. With a controller stricter
    than the demo's motion (0.6 rad/s; the UR5e's is pi) the trial ends in a protective
    stop: a failure without collision, with its reason, counted apart from refusals."""
    kwargs = dict(trials=1, method="demo", seed=1, root=tmp_path, twin_config=SMALL)
    report = run_trials(echo=lambda _: None, **kwargs)
    meta, rows = read_csv(report.path)
    assert meta["protocol"] == "paper" and meta["repair"] is False
    assert meta["safety_layer"]["check"].startswith("none")
    assert meta["safety_layer"]["controller_limits"]["max_joint_speed"] == pytest.approx(math.pi)
    row = rows[0]
    assert row["status"] in ("ok", "stopped", "protective_stop")
    assert set(row["repair"].split(";")) == {"unchecked"} and row["refused_limits"] == ""
    assert report.summary["refused"] == 0

    strict = ControllerLimits(name="strict UR5e", max_joint_speed=0.6)
    stopped = run_trials(echo=lambda _: None, controller=strict, **kwargs)
    row = stopped.rows[0]
    assert row["status"] == "protective_stop" and row["success"] == 0 and row["collision"] == 0
    assert row["stop_reason"].startswith("protective stop (strict UR5e joint speed limit)")
    assert stopped.summary["protective_stops"] == 1 and stopped.summary["refused"] == 0


def test_force_belongs_to_the_safety_layer_and_an_unknown_protocol_is_a_user_error(tmp_path):
    with pytest.raises(UserInputError, match="safety-layer protocol"):
        run_trials(trials=1, method="demo", root=tmp_path, force=True)
    with pytest.raises(UserInputError, match="protocol must be one of paper, safety-layer"):
        run_trials(trials=1, method="demo", root=tmp_path, protocol="careful")


def test_the_cli_rejects_an_unknown_protocol_with_exit_2(tmp_path):
    from typer.testing import CliRunner

    from distgprl.cli import app

    result = CliRunner().invoke(
        app, ["hardware", "--method", "demo", "--protocol", "careful", "--root", str(tmp_path)]
    )
    assert result.exit_code == 2 and "protocol must be one of" in result.output
