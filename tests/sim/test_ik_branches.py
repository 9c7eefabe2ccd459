"""`distgprl.sim.ik_branches`: the compiled nearest-branch choice is the scalar rule's, bit for
bit, on arrays built to hit its edge cases (the IK-generated cases are in test_robot.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from distgprl.sim.ik_branches import TWO_PI, nearest_branch, nearest_branch_exact

LOWER = np.array([-TWO_PI, -TWO_PI, -math.pi, -TWO_PI, -TWO_PI, -TWO_PI])
UPPER = -LOWER


def _same(chosen: np.ndarray | None, expected: list[float] | None) -> bool:
    if expected is None:
        return chosen is None
    return (
        chosen is not None
        and chosen.tolist() == expected
        and np.array_equal(np.signbit(chosen), np.signbit(expected))
    )


def _check_every_hint(solutions: np.ndarray, reference: np.ndarray) -> None:
    limits = tuple(zip(LOWER.tolist(), UPPER.tolist(), strict=True))
    expected = nearest_branch_exact(list(solutions), reference.tolist(), limits)
    for hint in range(len(solutions) + 1):
        chosen, index = nearest_branch(solutions, reference, LOWER, UPPER, hint)
        assert _same(chosen, expected), (solutions, reference, hint)
        if chosen is not None:  # the index names the chosen branch
            assert nearest_branch_exact([solutions[index]], reference.tolist(), limits) == expected
        else:
            assert index == hint


def test_random_branches_with_nans_signed_zeros_ties_and_branches_outside_the_limits():
    """From every hint, the compiled choice equals the rule's: random branches over several
    turns (wrap-around both ways), some NaN (singular), some out of the elbow's +-pi limit,
    exact -0.0 and +0.0 joint values near the reference (the sign of zero survives), and
    duplicated branches (exact ties: the first wins)."""
    rng = np.random.default_rng(11)
    for case in range(3000):
        count = int(rng.integers(1, 9))
        solutions = rng.uniform(-3 * math.pi, 3 * math.pi, (count, 6))
        reference = rng.uniform(-2 * math.pi, 2 * math.pi, 6)
        if case % 3 == 0:
            solutions[rng.uniform(size=(count, 6)) < 0.2] = -0.0
            reference[rng.uniform(size=6) < 0.5] = rng.uniform(-0.1, 0.1)
        if case % 5 == 0:
            solutions[int(rng.integers(count)), int(rng.integers(6))] = np.nan
        if case % 4 == 0 and count >= 2:
            solutions[-1] = solutions[0]
        if case % 7 == 0:
            reference = solutions[0].copy()
            reference[np.isnan(reference)] = 0.0
        _check_every_hint(np.ascontiguousarray(solutions), reference)


@pytest.mark.parametrize("half_turns", [1.0, 3.0, -1.0, -3.0])
def test_exact_half_turn_offsets_round_half_to_even(half_turns):
    """A branch exactly an odd number of half turns from the reference ((value - ref) / 2 pi
    = k + 0.5 exactly) is wrapped as Python's ``round`` does it: halves to even."""
    reference = np.array([0.0, 0.25, 0.0, 0.0, 0.0, 0.0])
    solutions = np.zeros((2, 6))
    solutions[0, 0] = half_turns * math.pi
    solutions[1, 3] = half_turns * math.pi
    _check_every_hint(solutions, reference)


def test_no_branch_within_the_limits_gives_none_and_keeps_the_hint():
    """All branches singular or outside the limits (no multiple of 2 pi brings them in):
    (None, hint), as the rule's None; and no branches at all: (None, hint)."""
    lower, upper = LOWER.copy(), UPPER.copy()
    lower[2], upper[2] = -1.0, 1.0
    limits = tuple(zip(lower.tolist(), upper.tolist(), strict=True))
    solutions = np.full((3, 6), 0.5)
    solutions[0, 2] = 2.0
    solutions[1, 0] = np.nan
    solutions[2, 2] = -1.5 - TWO_PI
    assert nearest_branch_exact(list(solutions), [0.0] * 6, limits) is None
    for hint in range(4):
        chosen, index = nearest_branch(solutions, np.zeros(6), lower, upper, hint)
        assert chosen is None and index == hint
    assert nearest_branch(np.zeros((0, 6)), np.zeros(6), LOWER, UPPER, 2) == (None, 2)
