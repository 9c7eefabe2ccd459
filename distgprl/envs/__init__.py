"""Gymnasium environments: the adaptation MDP and the ProMP-RRL residual MDP.

Registered ids (``gymnasium.make(id, method=...)``):

- ``DistGPRL-DCP-v4``, ``DistGPRL-DBM-v4``: `distgprl.envs.adaptation.AdaptationEnv`;
- ``ProMPRRL-DCP-v3``, ``ProMPRRL-DBM-v3``: `distgprl.envs.residual.ResidualEnv`.
"""

from gymnasium.envs.registration import register, registry

from distgprl.data import TASK_NAMES

for _task in TASK_NAMES:
    for _prefix, _version, _entry in (
        ("DistGPRL", 4, "distgprl.envs.adaptation:AdaptationEnv"),
        ("ProMPRRL", 3, "distgprl.envs.residual:ResidualEnv"),
    ):
        _id = f"{_prefix}-{_task.upper()}-v{_version}"
        if _id not in registry:
            register(id=_id, entry_point=_entry, kwargs={"task": _task})
