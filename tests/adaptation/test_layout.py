"""Action layouts (windows, segments, the covariance transform; DESIGN §3) and the aux
observation contract (distgprl/adaptation/layout.py)."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.adaptation.layout import AuxLayout, build_action_layout, reach_scales
from distgprl.config_types import EnvConfig
from distgprl.methods import get_method
from distgprl.skill.gp import GPSkill
from distgprl.skill.kernels import KernelParams
from distgprl.skill.operator import axis_operator

V5 = EnvConfig(covariance_scale="signal", action_scale_rule="fixed")
"""v5's operator and fixed scales (the ``operator-signal`` study reading)."""

AXIS_KERNELS = (KernelParams(0.06, 0.08, 1e-10), KernelParams(0.04, 0.016, 1e-10)) + (
    KernelParams(0.05, 0.04, 0.0),
) * 4
"""A zero-mean fit's six axis kernels (x, y like DCP's; constant axes at 0.2 rad)."""

TC_RANGE = np.array([0.2, 0.2, 0.0])


def skill():
    tau = np.linspace(0, 1, 15)
    return GPSkill(
        KernelParams(0.12),
        tau,
        np.zeros((15, 6)),
        np.zeros(6),
        4.0,
        axis_scale=np.full(6, 0.3),
        axis_kernels=AXIS_KERNELS,
    )


def test_windows_overlap_by_one_and_skip_the_end_points():
    layout = build_action_layout(skill(), V5, get_method("dist-gprl"))
    np.testing.assert_array_equal(
        layout.indices, [[1, 2, 3, 4, 5], [5, 6, 7, 8, 9], [9, 10, 11, 12, 13]]
    )
    np.testing.assert_allclose(layout.segment_bounds, [0, 5 / 14, 9 / 14, 1])


def test_covariance_transform_applied_only_where_the_method_says():
    """S_W per axis (v5: K_a = sigma_f^2 s_a^2 R, here 1 * 0.3^2 R for every axis) for the
    methods with the transform; the identity for every axis elsewhere."""
    s = skill()
    with_s = build_action_layout(s, V5, get_method("dist-gprl"))
    assert with_s.operators.shape == (3, 6, 5, 5)
    expected = s.window_operator([5, 6, 7, 8, 9], 1e-2 / 0.3**2)
    for axis in range(6):
        np.testing.assert_allclose(with_s.operators[1, axis], expected)
    assert not np.allclose(with_s.operators[1, 0], np.eye(5))
    for name in ("dist-gprl-nocov", "dist-gprl-global", "gprl"):
        layout = build_action_layout(s, EnvConfig(), get_method(name), tc_range=TC_RANGE)
        for per_axis in layout.operators:
            for op in per_axis:
                np.testing.assert_array_equal(op, np.eye(op.shape[0]))


def test_each_axis_gets_its_own_operator_and_the_delta_applies_it_per_axis():
    """ActionLayout.delta applies axis a's S_W to the scaled action's column a only."""
    tau = np.linspace(0, 1, 15)
    scales = np.array([0.05, 0.1, 0.2, 0.2, 0.3, 0.4])
    s = GPSkill(KernelParams(0.12), tau, np.zeros((15, 6)), np.zeros(6), 4.0, axis_scale=scales)
    layout = build_action_layout(s, V5, get_method("dist-gprl"))
    raw = np.random.default_rng(3).uniform(-1, 1, 30)
    delta = layout.delta(0, raw)
    scaled = raw.reshape(5, 6) * layout.scale
    for axis in range(6):
        floor = (0.05, 0.05, 0.05, 0.2, 0.2, 0.2)[axis]
        variance = max(scales[axis], floor) ** 2
        operator = s.window_operator([1, 2, 3, 4, 5], 1e-2 / variance)
        np.testing.assert_allclose(delta[:, axis], operator @ scaled[:, axis], atol=1e-12)


def test_global_methods_adapt_all_interior_via_points_every_step():
    layout = build_action_layout(skill(), V5, get_method("dist-gprl-global"))
    assert layout.indices.shape == (3, 13)
    np.testing.assert_array_equal(layout.indices[0], np.arange(1, 14))


def test_action_is_scaled_per_axis():
    config = EnvConfig(
        action_scale_rule="fixed", position_action_scale=0.1, rotation_action_scale=0.2
    )
    layout = build_action_layout(skill(), config, get_method("dist-gprl-nocov"))
    delta = layout.delta(0, np.ones(30))
    np.testing.assert_allclose(delta[:, :3], 0.1)
    np.testing.assert_allclose(delta[:, 3:], 0.2)


def test_global_action_moves_a_via_point_as_far_per_episode_as_a_window():
    config = EnvConfig(
        action_scale_rule="fixed", position_action_scale=0.1, rotation_action_scale=0.2
    )
    windowed = build_action_layout(skill(), config, get_method("dist-gprl-nocov"))
    for name in ("gprl", "dist-gprl-global"):
        layout = build_action_layout(skill(), config, get_method(name))
        total = sum(layout.delta(step, np.ones(78)) for step in range(layout.n_steps))
        per_window = windowed.delta(0, np.ones(30))[0]  # a non-overlap via-point: (6,)
        np.testing.assert_allclose(total, np.broadcast_to(per_window, total.shape))


def independent_correlation_operator(via_times, length_scale, correlation_lambda):
    """S = K (K + lambda I)^-1 from scratch, K the SE kernel's correlation matrix (unit
    signal variance, gp.py Eq. global_S) at the via-point times."""
    diff = via_times[:, None] - via_times[None, :]
    k = np.exp(-0.5 * (diff / length_scale) ** 2)
    return k @ np.linalg.inv(k + correlation_lambda * np.eye(len(via_times)))


def test_configured_correlation_lambda_reaches_the_layout_operators():
    """build_action_layout's S_W equal the window blocks of an independently computed
    K (K + lambda I)^-1 for the configured lambda (0.1 and the default 1e-2), and the two
    lambdas give different operators; the unit-variance K (v4, ``covariance_scale="unit"``)
    ignores the signal variance."""
    tau = np.linspace(0, 1, 15)
    s = GPSkill(KernelParams(0.12, 1.7, 1e-6), tau, np.zeros((15, 6)), np.zeros(6), 4.0)
    operators = {}
    for correlation_lambda in (0.1, EnvConfig().correlation_lambda):
        config = EnvConfig(
            correlation_lambda=correlation_lambda,
            covariance_scale="unit",
            action_scale_rule="fixed",
        )
        layout = build_action_layout(s, config, get_method("dist-gprl"))
        full = independent_correlation_operator(tau, 0.12, correlation_lambda)
        assert layout.operators.shape == (3, 6, 5, 5)
        for window, per_axis in zip(layout.indices, layout.operators, strict=True):
            for operator in per_axis:
                np.testing.assert_allclose(operator, full[np.ix_(window, window)], atol=1e-10)
        operators[correlation_lambda] = layout.operators
    assert EnvConfig().correlation_lambda == 1e-2
    assert np.abs(operators[0.1] - operators[1e-2]).max() > 1e-2


def test_the_table_one_operator_is_the_zero_mean_gp_per_axis():
    """Environment v6: axis a's S_W is the window block of K_a (K_a + lambda I)^-1 with K_a
    the axis's own zero-mean kernel (variance in m^2), recomputed here from scratch; x and y
    differ because their variances do; the eigenvalues lie in (0, 1)."""
    s = skill()
    layout = build_action_layout(s, EnvConfig(), get_method("dist-gprl"), tc_range=TC_RANGE)
    tau = s.via_times
    for axis, kernel in enumerate(AXIS_KERNELS):
        diff = tau[:, None] - tau[None, :]
        k = kernel.signal_variance * np.exp(-0.5 * (diff / kernel.length_scale) ** 2)
        full = k @ np.linalg.inv(k + 1e-2 * np.eye(15))
        window = layout.indices[1]
        np.testing.assert_allclose(
            layout.operators[1, axis], full[np.ix_(window, window)], atol=1e-9
        )
        eigenvalues = np.linalg.eigvalsh(layout.operators[1, axis])
        assert 0 < eigenvalues.min() and eigenvalues.max() < 1
    assert not np.allclose(layout.operators[1, 0], layout.operators[1, 1])


def test_reach_rule_gives_every_window_via_point_the_tc_range_in_one_step():
    """Rule "reach": with the Table I operator, the smallest one-step reach over all window
    via-points, sum_j |S_W,ij| * scale, equals max(TC range, minimum reach) on every axis;
    every method of the task gets the same scales (NoCov then reaches more, global methods
    as much per episode), whatever operator the run uses."""
    s = skill()
    config = EnvConfig()
    table_one = build_action_layout(s, config, get_method("dist-gprl"), tc_range=TC_RANGE)
    reach = np.abs(table_one.operators).sum(axis=-1).min(axis=(0, 2)) * table_one.scale
    expected = np.r_[np.maximum(TC_RANGE, 0.1), [0.05] * 3]
    np.testing.assert_allclose(reach, expected, rtol=1e-12)
    np.testing.assert_allclose(table_one.scale, reach_scales(s, config, TC_RANGE))
    nocov = build_action_layout(s, config, get_method("dist-gprl-nocov"), tc_range=TC_RANGE)
    np.testing.assert_allclose(nocov.scale, table_one.scale)
    assert np.all(nocov.scale >= expected)
    study = EnvConfig(covariance_scale="signal")
    other = build_action_layout(s, study, get_method("dist-gprl"), tc_range=TC_RANGE)
    np.testing.assert_allclose(other.scale, table_one.scale)
    with pytest.raises(ValueError, match="tc_range"):
        build_action_layout(s, config, get_method("dist-gprl"))


def test_the_correlation_operator_keeps_the_correlation_and_drops_the_shrink():
    """``operator-correlation``: each row of the Table I S_W divided by its row sum, so every
    via-point's reach equals the action scale, and the rows keep the Table I operator's
    proportions (the correlation)."""
    s = skill()
    table_one = build_action_layout(s, EnvConfig(), get_method("dist-gprl"), tc_range=TC_RANGE)
    corr = build_action_layout(
        s, EnvConfig(covariance_scale="correlation"), get_method("dist-gprl"), tc_range=TC_RANGE
    )
    np.testing.assert_allclose(np.abs(corr.operators).sum(axis=-1), 1.0, atol=1e-12)
    ratio = corr.operators / table_one.operators
    np.testing.assert_allclose(ratio, np.broadcast_to(ratio[..., :1], ratio.shape), rtol=1e-9)
    direct = axis_operator(s.via_times, AXIS_KERNELS[0], 1e-2)[np.ix_(range(1, 6), range(1, 6))]
    np.testing.assert_allclose(table_one.operators[0, 0], direct, atol=1e-12)


def test_the_uncoupled_signal_control_moves_each_via_point_as_far_as_signal_on_its_own():
    """``operator-signal-uncoupled``: per step and axis a diagonal S_W whose entries are the
    signal reading's row gains, so a raw action reaches every via-point exactly as far as
    under ``signal`` and moves no other; the action scale stays Table I's."""
    s = skill()
    signal = build_action_layout(
        s, EnvConfig(covariance_scale="signal"), get_method("dist-gprl"), tc_range=TC_RANGE
    )
    control = build_action_layout(
        s,
        EnvConfig(covariance_scale="signal-uncoupled"),
        get_method("dist-gprl"),
        tc_range=TC_RANGE,
    )
    eye = np.eye(signal.points_per_step)
    assert np.abs(signal.operators * (1 - eye)).max() > 1e-3  # the signal reading couples
    np.testing.assert_array_equal(control.operators * (1 - eye), 0.0)
    np.testing.assert_allclose(
        np.diagonal(control.operators, axis1=-2, axis2=-1),
        np.abs(signal.operators).sum(axis=-1),
        rtol=1e-12,
    )
    np.testing.assert_allclose(control.scale, signal.scale)
    raw = np.zeros(signal.points_per_step * 6)
    raw[2 * 6 + 0] = 1.0  # only the third via-point's x
    moved = np.flatnonzero(np.abs(control.delta(1, raw)).sum(axis=1))
    assert moved.tolist() == [2]
    assert np.count_nonzero(np.abs(signal.delta(1, raw)).sum(axis=1) > 1e-12) > 1


def test_a_skill_without_axis_kernels_cannot_build_the_table_one_operator():
    """A skill saved without (no ``axis_kernels``) raises instead of falling back."""
    tau = np.linspace(0, 1, 15)
    old = GPSkill(KernelParams(0.12), tau, np.zeros((15, 6)), np.zeros(6), 4.0)
    with pytest.raises(ValueError, match="axis_kernels"):
        build_action_layout(old, EnvConfig(), get_method("dist-gprl"), tc_range=TC_RANGE)


@pytest.mark.parametrize("anchors", [False, True])
def test_aux_slices_read_back_what_pack_writes(anchors):
    """The slices of `AuxLayout` tile [0, size) in order and recover Gamma, the step's one-hot
    (clipped to the last step) and the anchors from `pack`'s float32 vector."""
    rng = np.random.default_rng(0)
    layout = AuxLayout(15, 3, anchors)
    gamma, anchor = rng.normal(size=(15, 6)), rng.normal(size=(15, 3))
    for step in (0, 2, 3):
        aux = layout.pack(gamma, step, anchor if anchors else None)
        assert aux.dtype == np.float32 and aux.shape == (layout.size,)
        assert layout.size == 15 * 6 + 3 + (45 if anchors else 0)
        assert layout.gamma.stop == layout.step.start and layout.step.stop == layout.anchor.start
        np.testing.assert_array_equal(aux[layout.gamma], gamma.ravel().astype(np.float32))
        np.testing.assert_array_equal(aux[layout.step], np.eye(3)[min(step, 2)])
        expected = anchor.ravel() if anchors else np.empty(0)
        np.testing.assert_array_equal(aux[layout.anchor], expected.astype(np.float32))


def test_aux_pack_refuses_anchors_that_do_not_match_the_layout():
    """Anchors are required exactly when the layout has the anchors block."""
    with pytest.raises(ValueError, match="missing"):
        AuxLayout(15, 3, anchors=True).pack(np.zeros((15, 6)), 0)
    with pytest.raises(ValueError, match="not expected"):
        AuxLayout(15, 3).pack(np.zeros((15, 6)), 0, np.zeros((15, 3)))
