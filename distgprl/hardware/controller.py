"""What the UR5e's controller itself does with a commanded motion: the protective stop at its
documented joint speed and acceleration limits (:data:`distgprl.limits.UR5E_CONTROLLER`),
emulated on the twin over the joint targets it commands (`distgprl.hardware.backends.
TwinBackend`); the real UR5e enforces its own. Under the paper's protocol
(`distgprl.trial_protocol`) these limits are all that applies.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from distgprl.limits import UR5E_CONTROLLER, ControllerLimits

__all__ = ["ControllerStop", "controller_stop", "paper_protocol_meta"]


@dataclass(frozen=True)
class ControllerStop:
    """Where and why the controller stops a commanded joint-target sequence.

    Attributes:
        index: the first control instant (row of the targets) that exceeds a limit; the
            targets before it executed.
        limit: ``joint_speed`` or ``joint_acceleration``.
        value: the commanded value there (rad/s or rad/s^2, absolute).
        bound: the controller's limit.
        joint: which joint (0-based).
        robot: the robot's name.
    """

    index: int
    limit: str
    value: float
    bound: float
    joint: int
    robot: str = "UR5e"

    def reason(self) -> str:
        unit = "rad/s" if self.limit == "joint_speed" else "rad/s^2"
        return (
            f"protective stop ({self.robot} {self.limit.replace('_', ' ')} limit): joint "
            f"{self.joint} commanded {self.value:.3g} {unit} > {self.bound:.3g} {unit} at "
            f"control step {self.index}"
        )


def controller_stop(
    joints: np.ndarray,
    q_start: np.ndarray,
    v_start: np.ndarray,
    dt: float,
    limits: ControllerLimits = UR5E_CONTROLLER,
) -> ControllerStop | None:
    """The first control instant at which joint targets exceed the controller's limits.

    Joint speed at instant k is ``(q_k - q_{k-1}) / dt`` and acceleration ``(v_k - v_{k-1})
    / dt`` (finite differences at the control period, as the safety layer's check computes
    them), from ``q_start`` and ``v_start`` before the first target.

    Args:
        joints: commanded joint targets (n, 6), rad, one per control period.
        q_start: joint target (6,), rad, before the first.
        v_start: joint velocity (6,), rad/s, before the first (zero from rest).
        dt: control period, s.
        limits: the controller's limits.

    Returns:
        The stop (the earliest instant; speed named first where both are exceeded there),
        or None if every target is within the limits.
    """
    joints = np.asarray(joints, dtype=float).reshape(-1, 6)
    if not len(joints):
        return None
    full = np.vstack([np.asarray(q_start, dtype=float), joints])
    velocity = np.diff(full, axis=0) / dt
    acceleration = np.diff(np.vstack([np.asarray(v_start, dtype=float), velocity]), axis=0) / dt
    checks = (
        ("joint_speed", np.abs(velocity), limits.max_joint_speed),
        ("joint_acceleration", np.abs(acceleration), limits.max_joint_acceleration),
    )
    stops = []
    for limit, values, bound in checks:
        over = np.flatnonzero((values > bound).any(axis=1))
        if len(over):
            k = int(over[0])
            j = int(np.argmax(values[k]))
            stops.append(ControllerStop(k, limit, float(values[k, j]), bound, j, limits.name))
    return min(stops, key=lambda s: s.index) if stops else None


def paper_protocol_meta(limits: ControllerLimits = UR5E_CONTROLLER) -> dict[str, object]:
    """What runs before and during a motion under the paper's protocol, for a trial file's
    meta (the safety layer's own description is
    `distgprl.safety_layer.window_check.safety_layer`)."""
    return {
        "check": "none: the policy's poses execute as made (no pre-flight check, retiming "
        "or repair)",
        "controller": (
            f"the {limits.name}'s own limits only: a joint target beyond "
            f"{limits.max_joint_speed:.4g} rad/s or {limits.max_joint_acceleration:.4g} "
            "rad/s^2 ends the trial in a protective stop (a failure, not a refusal); a "
            "contact is a collision"
        ),
        "controller_limits": asdict(limits),
    }
