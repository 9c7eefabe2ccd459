"""Gymnasium environments: the adaptation MDP and the ProMP-RRL residual MDP.

Registered ids (``gymnasium.make(id, method=...)``):

- ``DistGPRL-DCP-v8``, ``DistGPRL-DBM-v8``: `distgprl.envs.adaptation.AdaptationEnv`;
- ``ProMPRRL-DCP-v8``, ``ProMPRRL-DBM-v8``: `distgprl.envs.residual.ResidualEnv`.

The version is `distgprl.config.ENVIRONMENT_VERSION`.
"""

from gymnasium.envs.registration import register, registry

from distgprl.config import ENVIRONMENT_VERSION
from distgprl.data import TASK_NAMES

for _task in TASK_NAMES:
    for _prefix, _version, _entry in (
        ("DistGPRL", ENVIRONMENT_VERSION, "distgprl.envs.adaptation:AdaptationEnv"),
        ("ProMPRRL", ENVIRONMENT_VERSION, "distgprl.envs.residual:ResidualEnv"),
    ):
        _id = f"{_prefix}-{_task.upper()}-v{_version}"
        if _id not in registry:
            register(id=_id, entry_point=_entry, kwargs={"task": _task})
