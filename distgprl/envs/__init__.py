"""Gymnasium environments: the adaptation MDP and the ProMP-RRL residual MDP.

Registered ids (``gymnasium.make(id, method=...)``):

- ``DistGPRL-DCP-v2``, ``DistGPRL-DBM-v2``: `distgprl.envs.adaptation.AdaptationEnv`;
- ``ProMPRRL-DCP-v2``, ``ProMPRRL-DBM-v2``: `distgprl.envs.residual.ResidualEnv`.
"""

from gymnasium.envs.registration import register, registry

for _task in ("dcp", "dbm"):
    for _prefix, _entry in (
        ("DistGPRL", "distgprl.envs.adaptation:AdaptationEnv"),
        ("ProMPRRL", "distgprl.envs.residual:ResidualEnv"),
    ):
        _id = f"{_prefix}-{_task.upper()}-v2"
        if _id not in registry:
            register(id=_id, entry_point=_entry, kwargs={"task": _task})
