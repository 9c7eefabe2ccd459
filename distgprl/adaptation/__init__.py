"""The adaptation core shared by the environment, the actor-loss regularisers, the hardware
adapter and the bench: how an RL action maps onto the skill's via-points and how the ``aux``
observation is laid out (:mod:`distgprl.adaptation.layout`), the plan state of an episode
(Gamma, TC conditioning, segment maps, the window update; :mod:`distgprl.adaptation.plan`)
and the trajectory models it adapts, the GP skill and ProMP-RRL's residual
(:mod:`distgprl.adaptation.trajectories`).

Numerics only (numpy, the skill models): no gymnasium, torch or pybullet, so ``envs/`` and
``agents/`` both depend on it and not on each other.
"""
