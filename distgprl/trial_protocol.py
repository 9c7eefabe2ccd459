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

Which trained policy a trial runs is named here too (`TRIAL_POLICIES`): the run's final
policy (``model.zip``, on disk only where the run was trained) or its shipped best policy
(``policy_best.pt``, Table I's, in every clone). Table II counts `TABLE2_POLICY`'s trials.

Ground floor (no hardware import), so that the report layer reads trial files by these names.
"""

from __future__ import annotations

from pathlib import Path

from distgprl.errors import UserInputError

__all__ = [
    "BEST_POLICY",
    "FINAL_POLICY",
    "GIVEN_POLICY",
    "PAPER",
    "PROTECTIVE_STOP",
    "PROTOCOLS",
    "SAFETY_LAYER",
    "TABLE2_POLICY",
    "TRIAL_POLICIES",
    "UNCHECKED",
    "check_protocol",
    "check_trial_policy",
    "counts_for",
    "file_policy",
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


FINAL_POLICY = "final"
"""A trial runs the run's final policy, its ``model.zip`` (only where the run was trained)."""

BEST_POLICY = "best"
"""A trial runs the run's shipped best policy (``policy_best.pt``: Table I's, in every clone)."""

GIVEN_POLICY = "given"
"""A trial file's policy when ``--model`` named the file (`file_policy`)."""

TRIAL_POLICIES = (FINAL_POLICY, BEST_POLICY)
"""The trained policies a trial can run, by name."""

TABLE2_POLICY = FINAL_POLICY
"""The policy Table II's trials run and count: the final one, the policy Table II v8's
trials ran (docs/findings/environment-v8.md, note of 2026-12-08); the trials of another
named policy are not counted in it but tabulated beside it (`distgprl.report.table2`)."""


def check_trial_policy(policy: str) -> str:
    """``policy`` if it is one of `TRIAL_POLICIES`, else :class:`UserInputError` naming them."""
    if policy not in TRIAL_POLICIES:
        raise UserInputError(f"policy must be one of {', '.join(TRIAL_POLICIES)}, got {policy!r}")
    return policy


def file_policy(meta: dict) -> str | None:
    """Which trained policy a trial file's trials ran, from its provenance (``meta["policy"]``):
    its ``policy`` (`BEST_POLICY`, `FINAL_POLICY` or `GIVEN_POLICY`, a file ``--model`` named),
    or for a file that predates it `FINAL_POLICY` for a ``model.zip`` and `GIVEN_POLICY` for
    another file; None for a reference, which runs no policy."""
    policy = meta.get("policy") or {}
    if not policy:
        return None
    named = str(policy.get("policy", ""))
    if named.startswith(BEST_POLICY):
        return BEST_POLICY
    if named in (FINAL_POLICY, GIVEN_POLICY):
        return named
    return FINAL_POLICY if Path(str(policy.get("model", ""))).name == "model.zip" else GIVEN_POLICY


def counts_for(ran: str | None, policy: str) -> bool:
    """True if trials that ran ``ran`` (`file_policy`) count in the table of ``policy``'s
    trials: their own policy's; a reference's (None: no policy) in every one; a policy file
    ``--model`` named (`GIVEN_POLICY`) in Table II's (`TABLE2_POLICY`)."""
    return ran in (None, policy) or (ran == GIVEN_POLICY and policy == TABLE2_POLICY)
