"""The continuity blend of the adaptation env (distgprl/envs/via_point_env.py: min_jerk)."""

from __future__ import annotations

import numpy as np

from distgprl.adaptation.plan import min_jerk


def test_min_jerk_blend_endpoints():
    """10u^3 - 15u^4 + 6u^5 is 0 at and below 0, 1/2 at 1/2, 1 at and above 1."""
    u = np.array([-1.0, 0.0, 0.5, 1.0, 2.0])
    np.testing.assert_allclose(min_jerk(u), [0, 0, 0.5, 1, 1])
