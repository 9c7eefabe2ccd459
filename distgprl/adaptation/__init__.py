"""The adaptation core shared by the environment, the actor-loss regularisers and the hardware
adapter: how an RL action maps onto the skill's via-points and how the ``aux`` observation is
laid out (:mod:`distgprl.adaptation.layout`).

Numerics only (numpy): no gymnasium, torch or pybullet, so ``envs/`` and ``agents/`` both depend
on it and not on each other.
"""
