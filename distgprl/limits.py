"""Motion limits as data (no hardware, simulator or torch import): the UR5e's own and the
hardware safety layer's.

Two sets of limits apply to a hardware trial, and they are kept apart:

- :class:`ControllerLimits` (:data:`UR5E_CONTROLLER`): what the UR5e's controller itself
  enforces, from its documentation. A command beyond them ends in a protective stop of the
  arm, whatever this project's code does; the paper's protocol (Table II as the paper ran
  it, `distgprl.trial_protocol`) applies these and nothing else.
- :class:`SafetyLimits`: the project's own, stricter safety layer
  (`distgprl.safety_layer`: pre-flight check, retiming; `distgprl.hardware.watchdog`), run
  beside the paper's protocol. The evaluation also reports the share of simulated episodes
  whose peak joint speed is above its ``max_joint_speed`` (:mod:`distgprl.experiments.rollout`), so
  the limits live below both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "UR5E_CONTROLLER",
    "UR5E_MAX_JOINT_ACCELERATION",
    "UR5E_MAX_JOINT_SPEED",
    "ControllerLimits",
    "SafetyLimits",
]

UR5E_MAX_JOINT_SPEED = math.pi
"""UR5e maximum joint speed, rad/s, every joint (180 deg/s for base, shoulder, elbow and the
three wrists: Universal Robots, UR5e technical specifications / e-Series User Manual UR5e
v5.8, as quoted in UniversalRobots/Universal_Robots_ROS2_Description
``config/ur5e/joint_limits.yaml``). The safety system stops the arm when a joint's speed
exceeds its joint speed limit (UR user manual, safety configuration "Joint limits:
Maximum speed": "the safety system performs a Stop Category 0")."""

UR5E_MAX_JOINT_ACCELERATION = 40.0
"""The largest joint acceleration, rad/s^2, a UR joint-space command may carry (the range
URScript / RTDE accept for a joint motion's acceleration: ur_rtde
``UR_JOINT_ACCELERATION_MAX = 40.0``, checked on every ``moveJ``). Universal Robots
publish no joint acceleration limit in the UR5e's technical specifications ("acceleration
limits are not publicly available", Universal_Robots_ROS2_Description
``config/ur5e/joint_limits.yaml``); a servoJ stream whose targets jump beyond what the
joints can follow is answered by the controller's path sanity check ("C204A1: sudden change
in target position") with a protective stop. This bound is the documented one."""


@dataclass(frozen=True)
class ControllerLimits:
    """What a robot's controller itself enforces on commanded joint targets: a target
    sequence beyond them ends in a protective stop at the first control instant that
    exceeds one (`distgprl.hardware.controller.controller_stop`).

    Attributes:
        name: the robot (in stop reasons).
        max_joint_speed: rad/s, every joint.
        max_joint_acceleration: rad/s^2, every joint.
    """

    name: str = "UR5e"
    max_joint_speed: float = UR5E_MAX_JOINT_SPEED
    max_joint_acceleration: float = UR5E_MAX_JOINT_ACCELERATION


UR5E_CONTROLLER = ControllerLimits()
"""The UR5e's documented joint speed and acceleration limits (`UR5E_MAX_JOINT_SPEED`,
`UR5E_MAX_JOINT_ACCELERATION`)."""


@dataclass(frozen=True)
class SafetyLimits:
    """The hardware safety layer's own limits (this project's, stricter than the UR5e's
    `UR5E_CONTROLLER`): every motion of a safety-layer trial is checked against them before
    it moves (`distgprl.safety_layer.plan_check.check_plan`) and watched while it moves.

    Attributes:
        workspace_lower, workspace_upper: TCP workspace box (3,), m, robot base frame.
        joint_lower, joint_upper: joint position limits (6,), rad (UR5e: +-2 pi, elbow
            +-pi), tightened by ``joint_margin``.
        joint_margin: distance (rad) kept from the joint limits.
        max_joint_speed: rad/s per joint (below the UR5e's `UR5E_MAX_JOINT_SPEED`, pi).
        max_joint_acceleration: rad/s^2 per joint (below `UR5E_MAX_JOINT_ACCELERATION`).
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
