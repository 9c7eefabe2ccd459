"""UR backend against the recording fake RTDE pair: streaming, stops, Ctrl-C, limits."""

from __future__ import annotations

import numpy as np
import pytest
from fake_rtde import FakeRTDE  # tests/hardware is on sys.path (rootdir conftest)

from distgprl.hardware.backends import URBackend, URConfig
from distgprl.hardware.watchdog import StopRequested, Watchdog
from distgprl.limits import SafetyLimits
from distgprl.safety_layer.plan_check import UnsafePlanError, check_plan
from distgprl.sim.transforms import matrix_to_pose

DT = 0.04


def straight_plan(model_sim, dx=0.05, steps=25):
    q0 = model_sim.start_joint_positions
    start = matrix_to_pose(model_sim.robot.fk(q0))
    poses = np.tile(start, (steps, 1))
    poses[:, 0] += np.linspace(dx / steps, dx, steps)
    return q0, poses


def backend(model_sim, fake, limits=None):
    return URBackend("10.0.0.2", limits or SafetyLimits(), URConfig(), rtde_factory=fake.factory)


def test_streams_interpolated_servoj_within_limits(model_sim):
    limits = SafetyLimits()
    q0, poses = straight_plan(model_sim)
    check = check_plan(poses, q0, model_sim.robot, limits, DT)
    fake = FakeRTDE(q0, model_sim.robot.fk)
    robot = backend(model_sim, fake, limits)
    result = robot.execute(check.joints, poses)
    assert not result.stopped and result.steps == len(poses)
    servo = [args for name, args in fake.log if name == "servoJ"]
    assert len(servo) == len(poses) * 5  # 125 Hz servo, 25 Hz plan
    targets = np.array([args[0] for args in servo])
    assert np.allclose(targets[-1], check.joints[-1])
    period = servo[0][3]
    assert period == pytest.approx(DT / 5)
    steps = np.abs(np.diff(np.vstack([q0, targets]), axis=0)).max(axis=1) / period
    assert steps.max() <= limits.max_joint_speed
    assert fake.names()[-1] == "servoStop"
    assert fake.log[1][0] == "setTcp"


def test_residual_steps_stream_back_to_back_and_stop_once_at_the_end(model_sim):
    """Residual control's 0.1 s RL steps (`execute(..., last=False)`) continue one stream:
    no servoStop between them, and the next step's servoJ targets go on from the last
    step's last target (not from where the lagging arm is), so the interpolated targets
    stay within the speed limit across the seam; the last step ends the stream once."""
    limits = SafetyLimits()
    q0, poses = straight_plan(model_sim, dx=0.04, steps=6)
    check = check_plan(poses, q0, model_sim.robot, limits, DT)
    fake = FakeRTDE(q0, model_sim.robot.fk)
    robot = backend(model_sim, fake, limits)
    first = robot.execute(check.joints[:3], poses[:3], last=False)
    assert not first.stopped and "servoStop" not in fake.names()
    fake.q = check.joints[1].copy()  # the arm lags one control period behind its target
    second = robot.execute(check.joints[3:], poses[3:], last=True)
    assert not second.stopped and fake.names().count("servoStop") == 1
    assert fake.names()[-1] == "servoStop"
    targets = np.array([args[0] for name, args in fake.log if name == "servoJ"])
    assert len(targets) == len(poses) * 5
    seam = check.joints[2] + (check.joints[3] - check.joints[2]) / 5  # the first after it
    np.testing.assert_allclose(targets[15], seam)
    period = DT / 5
    steps = np.abs(np.diff(np.vstack([q0, targets]), axis=0)).max(axis=1) / period
    assert steps.max() <= limits.max_joint_speed
    np.testing.assert_allclose(targets[-1], check.joints[-1])


def test_protective_stop_mid_trajectory_stops_streaming(model_sim):
    q0, poses = straight_plan(model_sim)
    check = check_plan(poses, q0, model_sim.robot, SafetyLimits(), DT)
    fake = FakeRTDE(q0, model_sim.robot.fk, protective_stop_after=37)
    result = backend(model_sim, fake).execute(check.joints, poses)
    assert result.stopped and result.protective_stop
    assert "protective stop" in result.stop_reason
    assert result.steps < len(poses)
    names = fake.names()
    assert names.count("servoJ") == 37  # nothing streamed after the stop was seen
    assert names[names.index("servoStop") - 1] == "servoJ"
    assert "stopJ" in names


def test_ctrl_c_stops_the_robot(model_sim):
    q0, poses = straight_plan(model_sim)
    check = check_plan(poses, q0, model_sim.robot, SafetyLimits(), DT)
    fake = FakeRTDE(q0, model_sim.robot.fk, interrupt_after=12)
    with pytest.raises(KeyboardInterrupt):
        backend(model_sim, fake).execute(check.joints, poses)
    names = fake.names()
    assert names.count("servoJ") == 12
    assert names[-2:] == ["servoStop", "stopJ"]


def test_not_ready_robot_does_not_move(model_sim):
    q0, poses = straight_plan(model_sim)
    check = check_plan(poses, q0, model_sim.robot, SafetyLimits(), DT)
    fake = FakeRTDE(q0, model_sim.robot.fk)
    fake.safety_mode = 7  # robot emergency stop
    result = backend(model_sim, fake).execute(check.joints, poses)
    assert result.stopped and "emergency" in result.stop_reason
    assert "servoJ" not in fake.names()
    assert backend(model_sim, fake).move_joints(q0).stopped
    assert "moveJ" not in fake.names()


@pytest.mark.parametrize(
    ("limit", "change"),
    [
        ("joint_speed", {"max_joint_speed": 0.05}),
        ("tcp_speed", {"max_tcp_speed": 0.01}),
        ("workspace", {"workspace_upper": (0.3, 0.55, 0.7)}),
    ],
)
def test_unsafe_plans_are_refused_naming_the_limit(model_sim, limit, change):
    q0, poses = straight_plan(model_sim)
    limits = SafetyLimits(**change)
    with pytest.raises(UnsafePlanError, match=limit) as refused:
        check_plan(poses, q0, model_sim.robot, limits, DT)
    assert limit in {v.limit for v in refused.value.violations}
    forced = check_plan(poses, q0, model_sim.robot, limits, DT, force=True)
    assert limit in {v.limit for v in forced.violations}
    assert len(forced.joints) == len(poses)


def test_clearance_refusal_uses_the_field(model_sim):
    from distgprl.safety.edf import DistanceField
    from distgprl.safety.shapes import Box

    q0, poses = straight_plan(model_sim, dx=0.0, steps=5)
    tcp = poses[0, :3]
    wall = Box("wall", tcp + [0.0, 0.0, -0.02], np.eye(3), np.array([0.05, 0.05, 0.005]))
    field = DistanceField([wall])

    def clearance(points, steps):
        return field.clearance(points)

    with pytest.raises(UnsafePlanError, match="clearance"):
        check_plan(poses, q0, model_sim.robot, SafetyLimits(), DT, clearance)
    far = SafetyLimits(min_clearance=-1.0)
    assert check_plan(poses, q0, model_sim.robot, far, DT, clearance).min_clearance < 0.005


def test_watchdog_stops_on_tracking_error_and_overrun():
    limits = SafetyLimits()
    watchdog = Watchdog(limits, 0.008)
    pose = np.array([0.4, 0.0, 0.3, 0.0, 0.0, 0.0])
    watchdog.check(1, True, pose, pose, 0.001)
    with pytest.raises(StopRequested, match="tracking error"):
        watchdog.check(1, True, pose, pose + [0.1, 0, 0, 0, 0, 0], 0.001)
    with pytest.raises(StopRequested, match="program"):
        watchdog.check(1, False, pose, pose, 0.001)
    with pytest.raises(StopRequested, match="overran"):
        for _ in range(limits.max_loop_overrun + 1):
            watchdog.check(1, True, pose, pose, 0.1)
