"""Choosing one of the analytic IK's branches: the nearest to a reference configuration
within the joint limits, each branch wrapped by multiples of 2 pi (`distgprl.sim.robot.UR5e`
calls it for every pose the control loop commands).

`nearest_branch_exact` is the rule; `nearest_branch` makes the same choice faster, starting
from a hinted branch (the previous pose's) whose distance bounds the others (tested from every
hint, near-ties included).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

TWO_PI = 2.0 * math.pi

__all__ = ["TWO_PI", "nearest_branch", "nearest_branch_exact"]


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


def _wrapped_branch(
    row: list[float],
    reference: list[float],
    limits: Sequence[tuple[float, float]],
    bound: float,
) -> tuple[list[float], float] | None:
    """One branch of `nearest_branch_exact`'s rule: (wrapped joints, squared distance), or
    None if it leaves the limits, is singular, or its distance exceeds ``bound``."""
    candidate = []
    distance = 0.0
    for value, ref, (lower, upper) in zip(row, reference, limits, strict=True):
        if value != value:  # NaN: singular branch
            return None
        value -= TWO_PI * round((value - ref) / TWO_PI)
        if value > upper:
            value -= TWO_PI
        elif value < lower:
            value += TWO_PI
        if value < lower or value > upper:
            return None
        candidate.append(value)
        distance += (value - ref) ** 2
        if distance > bound:  # partial sums only grow: it cannot be the nearest
            return None
    return candidate, distance


def nearest_branch(
    solutions: Sequence[np.ndarray],
    reference: list[float],
    limits: Sequence[tuple[float, float]],
    hint: int = 0,
) -> tuple[list[float] | None, int]:
    """`nearest_branch_exact`'s choice, computed faster: (the branch, its index).

    Branch ``hint`` (e.g. the one chosen for the previous pose) is wrapped first; its
    distance bounds the others, each dropped as soon as its partial squared distance
    exceeds it (partial sums of squares never decrease, so a dropped branch is farther
    than the hint, and a branch tying the hint is kept: the first of equals still wins).
    """
    rows = [solution.tolist() for solution in solutions]
    hinted = _wrapped_branch(rows[hint], reference, limits, math.inf) if hint < len(rows) else None
    bound = math.inf if hinted is None else hinted[1]
    best: list[float] | None = None
    best_index = hint
    best_distance = math.inf
    for index, row in enumerate(rows):
        branch = hinted if index == hint else _wrapped_branch(row, reference, limits, bound)
        if branch is not None and branch[1] < best_distance:
            best, best_distance = branch
            best_index = index
    return best, best_index
