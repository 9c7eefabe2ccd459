"""The TC conditioning rule: how far each part of a skill moves with the observed object.

Algorithm 1's "condition GP on observed task configuration" (docs/findings/protocol.md,
rule 2): the skill from the interaction on moves with the object by the observed offset,
weighted by w(τ):

- w = 1 at the interaction (the tool meets the object where the object now is);
- after it, w falls linearly in τ to 0 at the end if the task's goal is fixed in the world
  (DCP: the push must end in the goal region, not at goal + offset), and stays 1 if the goal
  moves with the object (DBM: the bar is lifted where it hangs);
- before it, w = 0 for via-points (the approach via-points stay; the policy adapts them),
  and for a dense trajectory w ramps in with a minimum-jerk blend over ``ramp`` in τ, whose
  samples would otherwise jump at the interaction.

The same rule conditions the GP skill's via-points (`distgprl.adaptation.trajectories`), the
`demo` reference and ProMP-RRL's conditioned demonstrations (`distgprl.sim.tasks.base.
condition_by_translation`), so every method starts from the same conditioned skill.
"""

from __future__ import annotations

import numpy as np

__all__ = ["conditioning_weights", "smooth_step"]


def smooth_step(x: np.ndarray) -> np.ndarray:
    """Minimum-jerk blend 10x^3 - 15x^4 + 6x^5 of x clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    blend: np.ndarray = x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)
    return blend


def conditioning_weights(
    tau: np.ndarray, interaction_tau: float, goal_fixed_in_world: bool, ramp: float = 0.0
) -> np.ndarray:
    """w(τ) of the module docstring at normalised times ``tau`` (n,), in [0, 1], shape (n,).

    Args:
        tau: normalised times in [0, 1].
        interaction_tau: the interaction's normalised time (for via-points: the interaction
            via-point's time, so that it gets w = 1 exactly).
        goal_fixed_in_world: fall to 0 at τ = 1 after the interaction (else stay 1).
        ramp: width in τ of the minimum-jerk ramp-in before the interaction; 0 = none
            (w = 0 before it).
    """
    tau = np.asarray(tau, dtype=float)
    if not 0.0 <= interaction_tau < 1.0:
        raise ValueError(f"interaction_tau must lie in [0, 1), got {interaction_tau}")
    after = tau >= interaction_tau
    if goal_fixed_in_world:
        fall = 1.0 - (tau - interaction_tau) / (1.0 - interaction_tau)
        weights = np.where(after, np.clip(fall, 0.0, 1.0), 0.0)
    else:
        weights = np.where(after, 1.0, 0.0)
    if ramp > 0.0:
        weights = np.where(after, weights, smooth_step((tau - (interaction_tau - ramp)) / ramp))
    result: np.ndarray = weights
    return result
