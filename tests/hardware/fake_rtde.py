"""A recording fake of ur_rtde's RTDEControlInterface / RTDEReceiveInterface pair.

Only the methods the UR backend calls exist; each call is logged as (name, args). The arm
tracks servoJ/moveJ targets exactly. Failure injection: ``protective_stop_after`` servoJ
calls switch the safety mode to 3 (protective stop); ``interrupt_after`` servoJ calls raise
KeyboardInterrupt (an operator's Ctrl-C during streaming).
"""

from __future__ import annotations

import numpy as np

from distgprl.sim.transforms import matrix_to_pose


class FakeRTDE:
    """Shared state of the fake controller."""

    def __init__(self, q0, fk, protective_stop_after=None, interrupt_after=None) -> None:
        self.q = np.asarray(q0, dtype=float).copy()
        self.fk = fk
        self.log: list[tuple[str, tuple]] = []
        self.safety_mode = 1
        self.program_running = True
        self.protective_stop_after = protective_stop_after
        self.interrupt_after = interrupt_after
        self.servo_calls = 0
        self.control = FakeControl(self)
        self.receive = FakeReceive(self)

    def names(self) -> list[str]:
        return [name for name, _ in self.log]

    def factory(self, robot_ip):
        self.log.append(("connect", (robot_ip,)))
        return self.control, self.receive


class FakeControl:
    def __init__(self, state: FakeRTDE) -> None:
        self.s = state

    def setTcp(self, offset):  # noqa: N802 - ur_rtde's names
        self.s.log.append(("setTcp", (tuple(offset),)))

    def moveJ(self, q, speed, acceleration):  # noqa: N802
        self.s.log.append(("moveJ", (tuple(q), speed, acceleration)))
        if self.s.safety_mode == 1:
            self.s.q = np.asarray(q, dtype=float)
        return True

    def servoJ(self, q, speed, acceleration, time, lookahead_time, gain):  # noqa: N802
        state = self.s
        state.servo_calls += 1
        if state.interrupt_after is not None and state.servo_calls > state.interrupt_after:
            raise KeyboardInterrupt
        state.log.append(("servoJ", (tuple(q), speed, acceleration, time, lookahead_time, gain)))
        if state.safety_mode == 1:
            state.q = np.asarray(q, dtype=float)
        if (
            state.protective_stop_after is not None
            and state.servo_calls >= state.protective_stop_after
        ):
            state.safety_mode = 3
        return True

    def servoStop(self, a=10.0):  # noqa: N802
        self.s.log.append(("servoStop", (a,)))

    def stopJ(self, a=2.0):  # noqa: N802
        self.s.log.append(("stopJ", (a,)))

    def initPeriod(self):  # noqa: N802
        return 0

    def waitPeriod(self, t_start):  # noqa: N802
        return None

    def isProgramRunning(self):  # noqa: N802
        return self.s.program_running

    def stopScript(self):  # noqa: N802
        self.s.log.append(("stopScript", ()))

    def disconnect(self):
        self.s.log.append(("disconnect_control", ()))


class FakeReceive:
    def __init__(self, state: FakeRTDE) -> None:
        self.s = state

    def getActualQ(self):  # noqa: N802
        return self.s.q.tolist()

    def getActualTCPPose(self):  # noqa: N802
        return matrix_to_pose(self.s.fk(self.s.q)).tolist()

    def getSafetyMode(self):  # noqa: N802
        return self.s.safety_mode

    def isProtectiveStopped(self):  # noqa: N802
        return self.s.safety_mode == 3

    def isEmergencyStopped(self):  # noqa: N802
        return self.s.safety_mode in (6, 7)

    def disconnect(self):
        self.s.log.append(("disconnect_receive", ()))
