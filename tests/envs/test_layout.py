"""Action layouts: windows, segments and the covariance transform (DESIGN §3)."""

from __future__ import annotations

import numpy as np

from distgprl.agents.methods import get_method
from distgprl.config import EnvConfig
from distgprl.envs.adaptation import build_action_layout, min_jerk
from distgprl.skill.gp import GPSkill, KernelParams


def skill():
    tau = np.linspace(0, 1, 15)
    return GPSkill(KernelParams(0.12), tau, np.zeros((15, 6)), np.zeros(6), 4.0)


def test_windows_overlap_by_one_and_skip_the_end_points():
    layout = build_action_layout(skill(), EnvConfig(), get_method("dist-gprl"))
    np.testing.assert_array_equal(
        layout.indices, [[1, 2, 3, 4, 5], [5, 6, 7, 8, 9], [9, 10, 11, 12, 13]]
    )
    np.testing.assert_allclose(layout.segment_bounds, [0, 5 / 14, 9 / 14, 1])


def test_covariance_transform_applied_only_where_the_method_says():
    s = skill()
    with_s = build_action_layout(s, EnvConfig(), get_method("dist-gprl"))
    np.testing.assert_allclose(with_s.operators[1], s.window_operator([5, 6, 7, 8, 9], 1e-2))
    assert not np.allclose(with_s.operators[1], np.eye(5))
    for name in ("dist-gprl-nocov", "dist-gprl-global", "gprl"):
        layout = build_action_layout(s, EnvConfig(), get_method(name))
        for op in layout.operators:
            np.testing.assert_array_equal(op, np.eye(op.shape[0]))


def test_global_methods_adapt_all_interior_via_points_every_step():
    layout = build_action_layout(skill(), EnvConfig(), get_method("dist-gprl-global"))
    assert layout.indices.shape == (3, 13)
    np.testing.assert_array_equal(layout.indices[0], np.arange(1, 14))


def test_action_is_scaled_per_axis():
    config = EnvConfig(position_action_scale=0.1, rotation_action_scale=0.2)
    layout = build_action_layout(skill(), config, get_method("dist-gprl-nocov"))
    delta = layout.delta(0, np.ones(30))
    np.testing.assert_allclose(delta[:, :3], 0.1)
    np.testing.assert_allclose(delta[:, 3:], 0.2)


def test_min_jerk_blend_endpoints():
    u = np.array([-1.0, 0.0, 0.5, 1.0, 2.0])
    np.testing.assert_allclose(min_jerk(u), [0, 0, 0.5, 1, 1])


def test_global_action_moves_a_via_point_as_far_per_episode_as_a_window():
    config = EnvConfig(position_action_scale=0.1, rotation_action_scale=0.2)
    windowed = build_action_layout(skill(), config, get_method("dist-gprl-nocov"))
    for name in ("gprl", "dist-gprl-global"):
        layout = build_action_layout(skill(), config, get_method(name))
        total = sum(layout.delta(step, np.ones(78)) for step in range(layout.n_steps))
        per_window = windowed.delta(0, np.ones(30))[0]  # a non-overlap via-point: (6,)
        np.testing.assert_allclose(total, np.broadcast_to(per_window, total.shape))
