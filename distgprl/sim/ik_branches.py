"""Choosing one of the analytic IK's branches: the nearest to a reference configuration
within the joint limits, each branch wrapped by multiples of 2 pi (`distgprl.sim.robot.UR5e`
calls it for every pose the control loop commands).

`nearest_branch_exact` is the rule; `nearest_branch` makes the same choice faster: compiled
(numba, issue 29), starting from a hinted branch (the previous pose's) whose distance bounds
the others (tested against the rule from every hint, near-ties included, bit for bit).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi

__all__ = ["TWO_PI", "nearest_branch", "nearest_branch_exact", "nearest_branch_index"]


def nearest_branch_exact(
    solutions: Sequence[np.ndarray],
    reference: list[float],
    limits: Sequence[tuple[float, float]],
) -> list[float] | None:
    """The scalar nearest-branch rule of `UR5e.ik_nearest` (the reference its array form
    follows): each branch (6,) of ``solutions`` wrapped by multiples of 2 pi towards
    ``reference`` within ``limits`` ((lower, upper) per joint, rad); the first branch of
    smallest squared distance, or None if no branch fits the limits."""
    best: list[float] | None = None
    best_distance = math.inf
    for solution in solutions:
        candidate = []
        distance = 0.0
        for value, ref, (lower, upper) in zip(solution.tolist(), reference, limits, strict=True):
            if value != value:  # NaN: singular branch
                break
            value -= TWO_PI * round((value - ref) / TWO_PI)
            if value > upper:
                value -= TWO_PI
            elif value < lower:
                value += TWO_PI
            if value < lower or value > upper:
                break
            candidate.append(value)
            distance += (value - ref) ** 2
        else:
            if distance < best_distance:
                best, best_distance = candidate, distance
    return best


@njit(cache=True, nogil=True)
def _wrapped_branch(row, reference, lower, upper, bound, out):  # pragma: no cover - compiled
    """One branch (6,) of `nearest_branch_exact`'s rule wrapped into ``out`` (6,); returns
    its squared distance, or -1.0 if it leaves the limits, is singular, or its partial
    distance exceeds ``bound``. Same operations, in the same order, as the rule (``rint`` is
    Python's ``round``: halves to even)."""
    distance = 0.0
    for joint in range(row.shape[0]):
        value = row[joint]
        if value != value:  # NaN: singular branch
            return -1.0
        ref = reference[joint]
        turns = np.rint((value - ref) / TWO_PI) + 0.0  # + 0.0: -0.0 -> 0.0, as int(round())
        value -= TWO_PI * turns
        if value > upper[joint]:
            value -= TWO_PI
        elif value < lower[joint]:
            value += TWO_PI
        if value < lower[joint] or value > upper[joint]:
            return -1.0
        out[joint] = value
        difference = value - ref
        distance += difference * difference
        if distance > bound:  # partial sums only grow: it cannot be the nearest
            return -1.0
    return distance


@njit(cache=True, nogil=True)
def nearest_branch_index(solutions, reference, lower, upper, hint, best):  # pragma: no cover
    """Index of the chosen branch of ``solutions`` (k, 6), wrapped into ``best`` (6,), or
    -1 if none fits the limits: `nearest_branch`'s compiled kernel, callable from other
    compiled code (`distgprl.sim.ur_ik`)."""
    count = solutions.shape[0]
    scratch = np.empty(solutions.shape[1])
    bound = np.inf
    hinted = -1.0
    if hint < count:
        hinted = _wrapped_branch(solutions[hint], reference, lower, upper, np.inf, best)
        if hinted >= 0.0:
            bound = hinted
    chosen = -1
    best_distance = np.inf
    for index in range(count):
        if index == hint:
            distance = hinted
        else:
            distance = _wrapped_branch(solutions[index], reference, lower, upper, bound, scratch)
        if distance >= 0.0 and distance < best_distance:
            best_distance = distance
            if index != hint:
                best[:] = scratch
            elif chosen >= 0:  # an earlier branch overwrote the hint's wrap: wrap it again
                _wrapped_branch(solutions[index], reference, lower, upper, np.inf, best)
            chosen = index
    return chosen


def nearest_branch(
    solutions: np.ndarray,
    reference: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    hint: int = 0,
) -> tuple[np.ndarray | None, int]:
    """`nearest_branch_exact`'s choice, computed faster: (the branch (6,), rad, its index).

    Args:
        solutions: the IK branches, shape (k, 6), rad, float64 (k may be 0).
        reference: the configuration to be near, shape (6,), rad, float64.
        lower, upper: joint limits, shape (6,), rad, float64.
        hint: the branch to wrap first (e.g. the one chosen for the previous pose).

    The hinted branch's distance bounds the others, each dropped as soon as its partial
    squared distance exceeds it (partial sums of squares never decrease, so a dropped branch
    is farther than the hint, and a branch tying the hint is kept: the first of equals still
    wins). Returns (None, ``hint``) when no branch fits the limits.
    """
    best = np.empty(6)
    if len(solutions) == 0:
        return None, hint
    chosen = nearest_branch_index(solutions, reference, lower, upper, hint, best)
    return (None, hint) if chosen < 0 else (best, chosen)
