"""Robot backends for hardware trials: the digital twin and a UR5e over ``ur_rtde``.

Both stream joint-space trajectories (one joint target per control period of the skill,
25 Hz; checked by the safety layer first under its protocol, as the policy made them under
the paper's, `distgprl.trial_protocol`) and report what happened. Either robot enforces
its controller's own limits: the real UR5e itself, the twin by emulating it
(`TwinBackend`). Shared protocol:
:class:`RobotBackend`. Times are on the backend's clock (s); poses are robot base frame
(x, y, z m; rotation vector rad); joints rad.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from distgprl.errors import UserInputError
from distgprl.hardware.controller import controller_stop
from distgprl.hardware.watchdog import StopRequested, Watchdog
from distgprl.limits import UR5E_CONTROLLER, ControllerLimits, SafetyLimits
from distgprl.sim.tasks.base import TaskConfig


@dataclass(frozen=True)
class ExecutionResult:
    """What a backend did with a trajectory.

    Attributes:
        steps: control instants commanded before the end or a stop.
        stopped: the motion ended early (protective stop, watchdog, contact).
        stop_reason: why ("" if not stopped).
        protective_stop: the controller (or the twin's emulation of it) stopped the arm.
        collision: ground-truth contact with an obstacle (twin only; None if unknown).
        limit_stop: the controller's limit the command exceeded (``joint_speed``,
            ``joint_acceleration``; twin only) where the stop was at a limit, not a
            contact; "" otherwise.
        min_clearance: ground-truth min robot-obstacle distance, m (twin only; None if unknown).
        actual_joints: measured joint positions (k, 6), rad, one per commanded instant.
        wall_s: wall time of the execution, s.
    """

    steps: int
    stopped: bool = False
    stop_reason: str = ""
    protective_stop: bool = False
    collision: bool | None = None
    min_clearance: float | None = None
    limit_stop: str = ""
    actual_joints: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    wall_s: float = 0.0


class RobotBackend(Protocol):
    """What :func:`~distgprl.hardware.trials.run_trials` needs from a robot."""

    name: str
    control_dt: float

    def now(self) -> float:
        """Current time on the backend's clock, s."""

    def tcp_pose(self) -> np.ndarray:
        """Actual TCP pose (6,)."""

    def joint_positions(self) -> np.ndarray:
        """Actual joint positions (6,), rad."""

    def capture(self) -> tuple[np.ndarray, float]:
        """(RGB image (h, w, 3) uint8, capture time s)."""

    def move_joints(self, q: np.ndarray) -> ExecutionResult:
        """Slow joint move to ``q`` (6,) (already checked)."""

    def execute(self, joints: np.ndarray, poses: np.ndarray, last: bool = True) -> ExecutionResult:
        """Stream joint targets (n, 6), one per control period (poses (n, 6) for monitoring).

        ``last=False``: another segment follows at once (residual control's next 0.1 s RL
        step), so the stream is not ended (no deceleration to standstill) after this one."""

    def stop(self) -> None:
        """Stop any motion now (idempotent)."""

    def close(self) -> None:
        """Release the robot and the camera."""


# --------------------------------------------------------------------------------- twin
class TwinBackend:
    """Executes in the digital twin (:class:`~distgprl.hardware.twin.TwinSim`).

    The twin's arm is a UR5e and stops as one (emulated protective stops; the rest of the
    trajectory is not executed): on contact with an obstacle (as a real UR would on a
    collision force), and, before any, at the first commanded joint target beyond the
    controller's limits (``controller``: joint speed or acceleration over the twin's own IK
    targets, `distgprl.hardware.controller.controller_stop`; the arm executes the targets
    before it).

    Args:
        twin: camera/sensor settings.
        rng: generator for the pixel noise.
        chunk: control instants executed between contact checks.
        noise_rng: generator for the image effects of ``twin.noise`` (exposure, blur,
            extra sensor noise); default seeded 0.
        controller: the controller's limits (default the UR5e's documented ones).
    """

    name = "twin"

    def __init__(
        self,
        twin=None,
        rng: np.random.Generator | None = None,
        chunk: int = 5,
        noise_rng: np.random.Generator | None = None,
        controller: ControllerLimits = UR5E_CONTROLLER,
    ) -> None:
        from distgprl.hardware.twin import TwinConfig, TwinSim

        self.twin = twin or TwinConfig()
        self.sim = TwinSim(self.twin)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.noise_rng = noise_rng if noise_rng is not None else np.random.default_rng(0)
        self.control_dt = float(self.sim.control_dt)
        self.chunk = int(chunk)
        self.controller = controller
        self.collision = False
        self.min_clearance = float(self.sim.clearance_cutoff)
        self.moved_steps = 0
        self.velocity = np.zeros(6)  # commanded joint velocity, rad/s (the controller's view)

    def start_trial(self, tc: TaskConfig) -> None:
        """Reset the cell to ``tc`` (bars placed, robot at the start pose)."""
        self.sim.reset(tc)
        self.collision = False
        self.min_clearance = float(self.sim.clearance())
        self.moved_steps = 0
        self.velocity = np.zeros(6)

    def now(self) -> float:
        return float(self.sim.time)

    def tcp_pose(self) -> np.ndarray:
        return self.sim.tcp_pose()

    def joint_positions(self) -> np.ndarray:
        return self.sim.joint_positions()

    def ground_truth(self) -> dict[str, np.ndarray]:
        """True bar transforms (4, 4) now."""
        return self.sim.object_transforms()

    def capture(self) -> tuple[np.ndarray, float]:
        """Image of the current state; then ``latency_s`` passes with the robot holding still."""
        stamp = self.now()
        image = self.sim.capture(self.rng, self.noise_rng)
        if self.twin.latency_s > 0:
            self.hold(self.twin.latency_s)
        return image, stamp

    def hold(self, seconds: float) -> None:
        """Let the world run for ``seconds`` while the robot holds its commanded pose."""
        from distgprl.sim.transforms import matrix_to_pose

        steps = int(round(seconds / self.control_dt))
        if steps <= 0:
            return
        pose = matrix_to_pose(self.sim.robot.fk(self.sim.q_command))
        self._run(np.tile(pose, (steps, 1)))
        self.velocity = np.zeros(6)  # holding still

    def _run(self, poses: np.ndarray) -> ExecutionResult:
        start = time.perf_counter()
        done = 0
        actual = []
        for begin in range(0, len(poses), self.chunk):
            result = self.sim.execute(poses[begin : begin + self.chunk])
            done += result.steps
            actual.append(np.tile(self.sim.joint_positions(), (result.steps, 1)))
            self.min_clearance = min(self.min_clearance, result.min_clearance)
            if result.collision:
                self.collision = True
                return ExecutionResult(
                    done,
                    stopped=True,
                    stop_reason="protective stop (contact with an obstacle)",
                    protective_stop=True,
                    collision=True,
                    min_clearance=self.min_clearance,
                    actual_joints=np.concatenate(actual),
                    wall_s=time.perf_counter() - start,
                )
        return ExecutionResult(
            done,
            collision=self.collision,
            min_clearance=self.min_clearance,
            actual_joints=np.concatenate(actual) if actual else np.zeros((0, 6)),
            wall_s=time.perf_counter() - start,
        )

    def move_joints(self, q: np.ndarray) -> ExecutionResult:
        self.sim.robot.reset_joints(np.asarray(q, dtype=float))
        self.sim.q_command = np.asarray(q, dtype=float).copy()
        self.velocity = np.zeros(6)
        return ExecutionResult(0)

    def execute(self, joints: np.ndarray, poses: np.ndarray, last: bool = True) -> ExecutionResult:
        """Run the poses in the twin (it moves only inside this call: ``last`` changes
        nothing), up to a protective stop: a contact, or the first joint target beyond the
        controller's limits (the twin's own IK targets of ``poses``, as its joints are
        commanded; ``joints`` is for a real robot's stream)."""
        poses = np.asarray(poses, dtype=float)
        q_before = np.asarray(self.sim.q_command, dtype=float).copy()
        targets, _ = self.sim.robot.ik_segment(poses, q_before)
        stop = controller_stop(targets, q_before, self.velocity, self.control_dt, self.controller)
        end = len(poses) if stop is None else stop.index
        result = self._run(poses[:end]) if end else ExecutionResult(0)
        self.moved_steps += result.steps
        if result.steps:
            previous = targets[result.steps - 2] if result.steps > 1 else q_before
            self.velocity = (targets[result.steps - 1] - previous) / self.control_dt
        if stop is None or result.stopped:  # done, or a contact came first
            return result
        self.velocity = np.zeros(6)  # the arm is stopped
        return replace(
            result,
            stopped=True,
            stop_reason=stop.reason(),
            protective_stop=True,
            collision=self.collision,
            min_clearance=self.min_clearance,
            limit_stop=stop.limit,
        )

    def stop(self) -> None:
        """The twin only moves inside :meth:`execute`; nothing to stop."""

    def success(self) -> bool:
        return bool(self.sim.success())

    def close(self) -> None:
        self.sim.close()


# ----------------------------------------------------------------------------------- UR
@dataclass(frozen=True)
class URConfig:
    """Streaming settings of the UR backend.

    Attributes:
        servo_rate_hz: servoJ command rate (the e-series controller runs at 500 Hz; joint
            targets are linearly interpolated between the skill's 25 Hz instants).
        lookahead_time: servoJ lookahead, s (0.03..0.2; larger = smoother, more lag).
        gain: servoJ proportional gain (100..2000).
        move_speed, move_acceleration: moveJ to the start configuration, rad/s, rad/s^2.
        stop_deceleration: deceleration of servoStop/stopJ, rad/s^2.
        tcp_offset: the hook's TCP in the flange frame, set on the controller at connect
            (x y z m, rx ry rz rad): the finger face, z pointing back up the tool.
    """

    servo_rate_hz: float = 125.0
    lookahead_time: float = 0.1
    gain: float = 300.0
    move_speed: float = 0.3
    move_acceleration: float = 0.5
    stop_deceleration: float = 2.0
    tcp_offset: tuple[float, float, float, float, float, float] = (
        0.0,
        -0.05,
        0.168,
        np.pi,
        0.0,
        0.0,
    )


def _default_rtde_factory(robot_ip: str):
    try:
        import rtde_control
        import rtde_receive
    except ImportError:
        raise UserInputError(
            "the ur backend needs ur_rtde: pip install 'distgprl[hardware]'"
        ) from None
    try:
        receive = rtde_receive.RTDEReceiveInterface(robot_ip)
        control = rtde_control.RTDEControlInterface(robot_ip)
    except RuntimeError as exc:
        raise UserInputError(
            f"cannot reach the robot at {robot_ip} over RTDE ({exc}); check the network, "
            "that the robot is powered on and in remote control mode"
        ) from None
    return control, receive


class URBackend:
    """A UR5e (e-series) over ``ur_rtde``.

    Args:
        robot_ip: controller address.
        limits: watchdog limits.
        config: streaming settings.
        camera: ``capture() -> (image, stamp)`` provider (e.g. :class:`OpenCVCamera`); its
            stamps must use this backend's clock (:meth:`now`).
        rtde_factory: ``robot_ip -> (RTDEControlInterface, RTDEReceiveInterface)``; the
            default imports ``rtde_control`` / ``rtde_receive`` (extra ``distgprl[hardware]``).
        clock: monotonic clock, s.

    RTDE calls used: control ``setTcp``, ``moveJ``, ``servoJ``, ``servoStop``, ``stopJ``,
    ``initPeriod``, ``waitPeriod``, ``isProgramRunning``, ``stopScript``, ``disconnect``;
    receive ``getActualQ``, ``getActualTCPPose``, ``getSafetyMode``, ``isProtectiveStopped``,
    ``isEmergencyStopped``, ``disconnect``.
    """

    name = "ur"
    control_dt = 0.04

    def __init__(
        self,
        robot_ip: str,
        limits: SafetyLimits,
        config: URConfig = URConfig(),
        camera=None,
        rtde_factory: Callable | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not robot_ip:
            raise UserInputError("the ur backend needs --robot-ip")
        self.robot_ip = robot_ip
        self.limits = limits
        self.config = config
        self.camera = camera
        self._clock = clock
        self._origin = clock()
        factory = rtde_factory or _default_rtde_factory
        self.control, self.receive = factory(robot_ip)
        self.control.setTcp(list(config.tcp_offset))
        self.commands = 0
        self._moving = False
        self._streamed: tuple[np.ndarray, np.ndarray] | None = None  # a stream left open

    def now(self) -> float:
        return float(self._clock() - self._origin)

    def tcp_pose(self) -> np.ndarray:
        return np.asarray(self.receive.getActualTCPPose(), dtype=float)

    def joint_positions(self) -> np.ndarray:
        return np.asarray(self.receive.getActualQ(), dtype=float)

    def capture(self) -> tuple[np.ndarray, float]:
        if self.camera is None:
            raise UserInputError("the ur backend needs a camera (--camera INDEX|URL)")
        return self.camera.capture()

    def safety_mode(self) -> int:
        """Controller safety mode (1 normal, 3 protective stop, 6/7 emergency stop, ...)."""
        mode = int(self.receive.getSafetyMode())
        if self.receive.isEmergencyStopped() and mode in (1, 2):
            mode = 7
        if self.receive.isProtectiveStopped() and mode in (1, 2):
            mode = 3
        return mode

    def _ready(self) -> None:
        mode = self.safety_mode()
        if mode not in (1, 2):
            from distgprl.hardware.watchdog import SAFETY_MODES

            raise StopRequested(f"robot not ready: safety mode {mode} ({SAFETY_MODES.get(mode)})")

    def move_joints(self, q: np.ndarray) -> ExecutionResult:
        start = time.perf_counter()
        try:
            self._ready()
        except StopRequested as stop:
            return ExecutionResult(0, True, stop.reason, protective_stop=True)
        self._moving = True
        try:
            self.control.moveJ(
                [float(v) for v in q], self.config.move_speed, self.config.move_acceleration
            )
        except KeyboardInterrupt:
            self.stop()
            raise
        self._moving = False
        mode = self.safety_mode()
        if mode not in (1, 2):
            return ExecutionResult(
                1, True, f"safety mode {mode} after moveJ", True, wall_s=time.perf_counter() - start
            )
        return ExecutionResult(1, wall_s=time.perf_counter() - start)

    def execute(self, joints: np.ndarray, poses: np.ndarray, last: bool = True) -> ExecutionResult:
        """Stream ``joints`` with servoJ at ``servo_rate_hz`` under the :class:`Watchdog`.

        The stream ends with ``servoStop`` (decelerating to standstill) unless ``last`` is
        False: then the next call continues it (residual control streams its 0.1 s RL steps
        back to back; between them servoJ holds the last target while the next step is
        decided and checked: a few ms, some 30 ms more where the step takes an image). A
        stop condition ends streaming with ``servoStop``;
        Ctrl-C (KeyboardInterrupt) stops the robot and is re-raised.
        """
        joints = np.asarray(joints, dtype=float)
        poses = np.asarray(poses, dtype=float)
        config = self.config
        substeps = max(1, int(round(self.control_dt * config.servo_rate_hz)))
        period = self.control_dt / substeps
        watchdog = Watchdog(self.limits, period)
        start = time.perf_counter()
        actual: list[np.ndarray] = []
        if self._streamed is not None:  # the stream goes on from its last target
            previous, previous_pose = self._streamed
        else:
            previous = self.joint_positions()
            previous_pose = self.tcp_pose()
        self._streamed = None
        self._moving = True
        try:
            self._ready()
            for k in range(len(joints)):
                for s in range(substeps):
                    fraction = (s + 1) / substeps
                    q = previous + fraction * (joints[k] - previous)
                    commanded = previous_pose + fraction * (poses[k] - previous_pose)
                    cycle_start = self._clock()
                    t_start = self.control.initPeriod()
                    watchdog.check(
                        self.safety_mode(),
                        bool(self.control.isProgramRunning()),
                        commanded,
                        self.tcp_pose(),
                        self._clock() - cycle_start,
                    )
                    self.control.servoJ(
                        [float(v) for v in q], 0.0, 0.0, period, config.lookahead_time, config.gain
                    )
                    self.commands += 1
                    self.control.waitPeriod(t_start)
                previous, previous_pose = joints[k], poses[k]
                actual.append(self.joint_positions())
        except StopRequested as stop:
            self.stop()
            protective = "safety mode" in stop.reason
            return ExecutionResult(
                len(actual),
                stopped=True,
                stop_reason=stop.reason,
                protective_stop=protective,
                actual_joints=np.array(actual).reshape(-1, 6),
                wall_s=time.perf_counter() - start,
            )
        except KeyboardInterrupt:
            self.stop()
            raise
        if last:
            self.control.servoStop(config.stop_deceleration)
            self._moving = False
        else:
            self._streamed = (np.asarray(previous).copy(), np.asarray(previous_pose).copy())
        return ExecutionResult(
            len(actual),
            actual_joints=np.array(actual).reshape(-1, 6),
            wall_s=time.perf_counter() - start,
        )

    def stop(self) -> None:
        """Decelerate to standstill (servoStop + stopJ); safe to call at any time."""
        self._streamed = None
        try:
            self.control.servoStop(self.config.stop_deceleration)
            self.control.stopJ(self.config.stop_deceleration)
        finally:
            self._moving = False

    def close(self) -> None:
        try:
            self.stop()
            self.control.stopScript()
        finally:
            self.control.disconnect()
            self.receive.disconnect()
            if self.camera is not None:
                self.camera.close()


class OpenCVCamera:
    """A camera read with ``cv2.VideoCapture`` (device index or stream URL).

    Args:
        source: device index (``"0"`` or ``0``) or URL.
        clock: the robot backend's clock (``URBackend.now``) for the stamps.
        size: requested (width, height), px, or None for the device default.
    """

    def __init__(self, source: str | int, clock: Callable[[], float], size=None) -> None:
        import cv2

        device = int(source) if isinstance(source, int) or str(source).isdigit() else str(source)
        self._capture = cv2.VideoCapture(device)
        if not self._capture.isOpened():
            raise UserInputError(f"cannot open camera {source!r}")
        if size is not None:
            self._capture.set(cv2.CAP_PROP_FRAME_WIDTH, int(size[0]))
            self._capture.set(cv2.CAP_PROP_FRAME_HEIGHT, int(size[1]))
        self._clock = clock

    def capture(self) -> tuple[np.ndarray, float]:
        import cv2

        self._capture.grab()  # drop a buffered frame: keep latency low
        stamp = self._clock()
        ok, frame = self._capture.read()
        if not ok:
            raise UserInputError("camera returned no frame")
        return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB), stamp

    def close(self) -> None:
        self._capture.release()
