"""Which protocol a hardware trial ran under: the names its result files record.

``paper`` (Table II as the paper ran it, the default): every window's (residual control: every
0.1 s RL step's) poses go to the robot as the policy made them, with no pre-flight check,
retiming or repair; only the robot's own controller limits apply
(`distgprl.hardware.controller`). A protective stop is a failed trial (status
``protective_stop``), not a refusal and not a collision unless the arm touched something
first; a contact is a collision.

``safety-layer``: this project's safety layer
(`distgprl.safety_layer.plan_check.check_plan`, the plan repair of
`distgprl.safety_layer.repair`) checks every decision's poses against its own, stricter
:class:`~distgprl.limits.SafetyLimits` before they move, and refuses (or retimes) what fails;
reported beside the paper's protocol, never in its place.

Ground floor (no hardware import), so that the report layer reads trial files by these names.
"""

from __future__ import annotations

from distgprl.errors import UserInputError

__all__ = [
    "PAPER",
    "PROTECTIVE_STOP",
    "PROTOCOLS",
    "SAFETY_LAYER",
    "UNCHECKED",
    "check_protocol",
    "file_protocol",
]

PAPER = "paper"
"""The paper's protocol: the policy's trajectory executes; only the UR5e's own limits apply."""

SAFETY_LAYER = "safety-layer"
"""This project's safety layer before every motion (pre-flight check, retiming, repair)."""

PROTOCOLS = (PAPER, SAFETY_LAYER)
"""The protocols of a hardware trial, the paper's first (the default)."""

PROTECTIVE_STOP = "protective_stop"
"""A trial row's ``status`` when the robot's controller stopped the arm at one of its own
limits (a failed trial, not a refusal; contact stops are ``stopped`` with a collision)."""

UNCHECKED = "unchecked"
"""A trial row's per-decision ``repair`` entry under the paper's protocol: the poses went to
the robot without a pre-flight check (the safety layer's entries are its decisions)."""


def check_protocol(protocol: str) -> str:
    """``protocol`` if it is one of `PROTOCOLS`, else :class:`UserInputError` naming them."""
    if protocol not in PROTOCOLS:
        raise UserInputError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    return protocol


def file_protocol(meta: dict) -> str:
    """The protocol a trial file's trials ran under, from its meta: its ``protocol``, or
    `SAFETY_LAYER` for a file written before the paper's protocol existed (every trial then
    ran behind the safety layer's pre-flight check)."""
    return str(meta.get("protocol") or SAFETY_LAYER)
