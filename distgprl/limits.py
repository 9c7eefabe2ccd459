"""Hardware safety limits as data (no hardware, simulator or torch import).

:class:`SafetyLimits` is what the hardware safety layer (:mod:`distgprl.hardware.safety`)
checks every trial motion against; the evaluation reports the share of simulated episodes
whose peak joint speed is above ``max_joint_speed`` (:mod:`distgprl.experiments.rollout`), so
the limits live below both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["SafetyLimits"]


@dataclass(frozen=True)
class SafetyLimits:
    """Limits every trial motion must respect.

    Attributes:
        workspace_lower, workspace_upper: TCP workspace box (3,), m, robot base frame.
        joint_lower, joint_upper: joint position limits (6,), rad (UR5e: +-2 pi, elbow
            +-pi), tightened by ``joint_margin``.
        joint_margin: distance (rad) kept from the joint limits.
        max_joint_speed: rad/s per joint (UR5e hardware limit pi rad/s; kept lower).
        max_joint_acceleration: rad/s^2 per joint.
        max_tcp_speed: m/s (ISO/TS 15066-style collaborative speed bound).
        min_clearance: smallest allowed distance (m) from tool/flange to an obstacle.
        max_tracking_error: largest allowed distance (m) between commanded and actual TCP.
        max_loop_overrun: control periods the streaming loop may fall behind before the
            watchdog stops the robot.
    """

    workspace_lower: tuple[float, float, float] = (0.10, -0.75, 0.10)
    workspace_upper: tuple[float, float, float] = (0.85, 0.55, 0.70)
    joint_lower: tuple[float, ...] = (-2 * math.pi, -2 * math.pi, -math.pi) + (-2 * math.pi,) * 3
    joint_upper: tuple[float, ...] = (2 * math.pi, 2 * math.pi, math.pi) + (2 * math.pi,) * 3
    joint_margin: float = 0.05
    max_joint_speed: float = 2.0
    max_joint_acceleration: float = 25.0
    max_tcp_speed: float = 1.0
    min_clearance: float = 0.005
    max_tracking_error: float = 0.05
    max_loop_overrun: int = 5
