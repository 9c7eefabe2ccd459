"""The numerics of ProMP-RRL as residual RL (`distgprl.adaptation.residual_control`)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from distgprl.adaptation.residual_control import (
    SLEW_TIME_S,
    compose,
    control_schedule,
    hold_residual,
    residual_range,
    rotation_error,
    slew_limited,
    variance_gate,
)


@pytest.mark.parametrize(("duration", "steps"), [(4.8, 48), (5.0, 50), (0.95, 10)])
def test_schedule_has_duration_times_rate_steps_covering_every_control_period(duration, steps):
    """At 10 Hz on a 25 Hz loop: ceil(duration x 10) RL steps, each executing the control
    periods that end in its 0.1 s (2 and 3 alternately), every period exactly once, in order;
    the hold fraction reaches 1 at each step's last period."""
    schedule = control_schedule(duration, 0.04, 10.0)
    assert schedule.n_steps == steps
    flat = np.concatenate(schedule.steps)
    np.testing.assert_array_equal(flat, np.arange(round(duration / 0.04)))
    for j, indices in enumerate(schedule.steps):
        times = schedule.times[indices]
        assert np.all(times > j / 10 - 1e-9) and np.all(times <= (j + 1) / 10 + 1e-9)
        assert schedule.fraction[indices[-1]] == pytest.approx(1.0)
        np.testing.assert_allclose(np.diff(schedule.fraction[indices]), 1.0 / len(indices))
    counts = [len(s) for s in control_schedule(4.8, 0.04, 10.0).steps]
    assert counts[:4] == [2, 3, 2, 3] and sum(counts) == 120
    np.testing.assert_allclose(
        control_schedule(4.8, 0.04, 10.0).step_duration[:2], [0.08, 0.12], atol=1e-12
    )


def test_schedule_refuses_a_rate_above_the_control_loop():
    """An RL step shorter than a control period would execute no pose."""
    with pytest.raises(ValueError, match="faster than the control loop"):
        control_schedule(4.8, 0.04, 30.0)


def test_gate_is_the_std_over_its_maximum_and_zero_where_there_is_no_variance():
    """``uncertain``: sigma / max sigma (the mean of the three positional stds), so a
    zero-variance instant passes nothing and a larger variance passes more; ``certain`` is
    its complement; a ProMP without variance passes nothing (``uncertain``)."""
    std = np.array([[0.0, 0.0, 0.0], [0.01, 0.02, 0.03], [0.04, 0.04, 0.04], [0.01, 0.01, 0.01]])
    gate = variance_gate(std)
    np.testing.assert_allclose(gate, [0.0, 0.5, 1.0, 0.25])
    assert gate[0] == 0.0
    np.testing.assert_allclose(variance_gate(std, "certain"), 1.0 - gate)
    np.testing.assert_array_equal(variance_gate(np.zeros((5, 3))), np.zeros(5))
    with pytest.raises(ValueError, match="gate mode"):
        variance_gate(std, "sometimes")  # type: ignore[arg-type]


def test_residual_range_is_the_tc_range_floored_by_the_minimum_reach():
    """max(TC range, 0.1 m) per position axis, 0.05 rad per rotation axis."""
    np.testing.assert_allclose(
        residual_range(np.array([0.035, 0.2, 0.0]), 0.1, 0.05), [0.1, 0.2, 0.1, 0.05, 0.05, 0.05]
    )


def test_slew_limit_moves_at_most_range_times_duration_over_the_slew_time():
    """A target across the range is approached at the slew limit; a near one is reached."""
    scale = np.array([0.2, 0.1, 0.1, 0.05, 0.05, 0.05])
    far = slew_limited(np.zeros(6), scale, scale, 0.1)
    np.testing.assert_allclose(far, scale * 0.1 / SLEW_TIME_S)
    near = 0.1 * scale
    np.testing.assert_allclose(slew_limited(np.zeros(6), near, scale, 0.1), near)
    np.testing.assert_allclose(slew_limited(far, -scale, scale, 0.1), np.zeros(6), atol=1e-15)


def test_hold_goes_linearly_from_the_previous_residual_to_the_new_one():
    previous, target = np.arange(6.0), np.arange(6.0) + 3.0
    held = hold_residual(previous, target, np.array([1 / 3, 2 / 3, 1.0]))
    np.testing.assert_allclose(held, previous + np.array([[1.0], [2.0], [3.0]]))


def test_compose_adds_the_gated_residual_and_a_zero_gate_keeps_the_nominal_exactly():
    """Position: p + g dp; orientation: Exp(g dr) R (world frame); gate 0: the nominal, bit
    for bit."""
    nominal = np.array([[0.5, 0.1, 0.3, 0.0, 0.0, 0.0], [0.4, -0.2, 0.2, 3.1, 0.1, -0.05]])
    residual = np.array([[0.1, -0.2, 0.05, 0.02, -0.01, 0.03]] * 2)
    poses = compose(nominal, residual, np.array([0.0, 0.5]))
    np.testing.assert_array_equal(poses[0], nominal[0])
    np.testing.assert_allclose(poses[1, :3], nominal[1, :3] + 0.5 * residual[1, :3])
    expected = Rotation.from_rotvec(0.5 * residual[1, 3:]) * Rotation.from_rotvec(nominal[1, 3:])
    np.testing.assert_allclose(
        Rotation.from_rotvec(poses[1, 3:]).as_matrix(), expected.as_matrix(), atol=1e-12
    )
    assert np.linalg.norm(poses[1, 3:] - nominal[1, 3:]) < 0.1  # no 2 pi jump near pi
    np.testing.assert_allclose(rotation_error(poses[1], nominal[1]), 0.5 * residual[1, 3:])
