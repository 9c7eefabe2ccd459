"""The runtime watchdog of a streaming robot backend (`distgprl.hardware.backends`).

During motion, :class:`Watchdog` stops the robot on a protective/emergency stop, a stopped
controller program, a tracking error, a TCP outside the workspace
(`distgprl.limits.SafetyLimits`) or a control loop that falls behind.
"""

from __future__ import annotations

import numpy as np

from distgprl.limits import SafetyLimits

SAFETY_MODES = {
    1: "normal",
    2: "reduced",
    3: "protective stop",
    4: "recovery",
    5: "safeguard stop",
    6: "system emergency stop",
    7: "robot emergency stop",
    8: "violation",
    9: "fault",
    10: "validate joint id",
    11: "undefined safety mode",
}
"""UR controller safety modes (``RTDEReceiveInterface.getSafetyMode``)."""

MOVING_SAFETY_MODES = frozenset({1, 2})
"""Safety modes in which the robot may move (normal, reduced)."""


class StopRequested(Exception):
    """The watchdog (or the controller) stopped the motion; ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class Watchdog:
    """Runtime monitor called once per control cycle by a streaming backend.

    Args:
        limits: workspace, tracking and loop-overrun limits.
        period: control period of the streaming loop, s.
    """

    def __init__(self, limits: SafetyLimits, period: float) -> None:
        self.limits = limits
        self.period = period
        self._behind = 0

    def check(
        self,
        safety_mode: int,
        program_running: bool,
        commanded_tcp: np.ndarray,
        actual_tcp: np.ndarray,
        cycle_seconds: float,
    ) -> None:
        """Raise :class:`StopRequested` if the robot must stop (reason in the message)."""
        if safety_mode not in MOVING_SAFETY_MODES:
            raise StopRequested(
                f"controller safety mode {safety_mode} ({SAFETY_MODES.get(safety_mode, '?')})"
            )
        if not program_running:
            raise StopRequested("controller program stopped (RTDE control script not running)")
        actual = np.asarray(actual_tcp, dtype=float)[:3]
        lower = np.asarray(self.limits.workspace_lower)
        upper = np.asarray(self.limits.workspace_upper)
        if np.any(actual < lower) or np.any(actual > upper):
            raise StopRequested(f"TCP {np.round(actual, 3).tolist()} m left the workspace box")
        error = float(np.linalg.norm(np.asarray(commanded_tcp, dtype=float)[:3] - actual))
        if error > self.limits.max_tracking_error:
            raise StopRequested(
                f"tracking error {error:.3f} m > {self.limits.max_tracking_error} m"
            )
        if cycle_seconds > 2.0 * self.period:
            self._behind += 1
            if self._behind > self.limits.max_loop_overrun:
                raise StopRequested(
                    f"control loop overran {self._behind} cycles (last {cycle_seconds * 1e3:.1f} "
                    f"ms > {2e3 * self.period:.1f} ms)"
                )
        else:
            self._behind = 0
