"""The TC conditioning rule (distgprl/skill/conditioning.py; environment v6)."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.skill.conditioning import conditioning_weights


def test_a_goal_fixed_in_the_world_brings_the_end_back():
    """Goal fixed (DCP): w = 0 before the interaction, 1 at it, linear to 0 at the end, so
    the conditioned push ends at the demonstration's end (the goal), not goal + offset."""
    tau = np.linspace(0, 1, 15)
    interaction = tau[5]
    w = conditioning_weights(tau, interaction, goal_fixed_in_world=True)
    np.testing.assert_array_equal(w[:5], 0.0)
    assert w[5] == 1.0 and w[-1] == 0.0
    np.testing.assert_allclose(np.diff(w[5:]), -1.0 / 9.0)


def test_a_goal_that_moves_with_the_object_keeps_the_whole_shift():
    """Goal moving with the object (DBM): every via-point from the interaction on moves by
    the full offset (v5's rule)."""
    tau = np.linspace(0, 1, 15)
    w = conditioning_weights(tau, tau[6], goal_fixed_in_world=False)
    np.testing.assert_array_equal(w, np.r_[np.zeros(6), np.ones(9)])


def test_the_dense_ramp_is_continuous_and_only_before_the_interaction():
    """With a ramp (dense trajectories), w rises smoothly from 0 to 1 over ``ramp`` before the
    interaction, without a jump, and the part after it is unchanged."""
    tau = np.linspace(0, 1, 2001)
    w = conditioning_weights(tau, 0.4, goal_fixed_in_world=True, ramp=0.15)
    assert np.max(np.abs(np.diff(w))) < 0.01
    np.testing.assert_array_equal(w[tau <= 0.25], 0.0)
    after = tau >= 0.4
    np.testing.assert_allclose(w[after], conditioning_weights(tau[after], 0.4, True))
    with pytest.raises(ValueError):
        conditioning_weights(tau, 1.0, True)
