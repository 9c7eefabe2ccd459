"""The cells of the mechanism table (`distgprl.report.mechanisms`): the shaping shares of
the return and the regulariser shares of the actor gradient, computed from the rows of the
result files (evaluation CSVs, ``progress.csv``), and the table they make with the reach rows.

Pure functions of the rows they are given; no file is read here. Imports neither torch nor
pybullet.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from distgprl.methods import METHODS

CRITERION = 0.05
"""The pre-registered share (rule 7): each shaping term ≥ 5 % of the return where it acts,
each regulariser's actor gradient ≥ 5 % of the Q term's (L_hap: outside C_safe)."""

NOT_RECORDED = "not recorded"
"""What a cell says whose result files predate the columns it needs."""

POINTS = ("first", "middle", "last")
"""The learning-curve points of the gradient shares."""

RETURN_TERMS = (("r_sd", "return_sd"), ("r_ga", "return_ga"))
"""(term, evaluation column) of the shaping shares; ``return_ga`` holds lambda_ga r_ga."""

GRADIENT_ITEMS = (
    ("l_sim", "grad_sim"),
    ("l_hap", "grad_hap"),
    ("l_hap_active", "grad_hap_active"),
)
"""(item, progress column) of the gradient shares, each against ``grad_q``."""


@dataclass(frozen=True)
class EpisodeRatios:
    """The shaping ratios of one evaluation file's episodes that pass within d_min.

    Attributes:
        episodes: episodes in the file.
        within: episodes whose ``min_clearance`` < d_min.
        zero_tc: of those, the episodes whose r_tc sums to 0 (no ratio; left out).
        ratios: per term (``r_sd``, ``r_ga``), |sum term| / |sum r_tc| of the others.
    """

    episodes: int
    within: int
    zero_tc: int
    ratios: dict[str, list[float]]


def _number(value: Any) -> float | None:
    """A CSV cell as a float; None where it is empty, NaN or absent."""
    if value is None or value == "" or (isinstance(value, float) and np.isnan(value)):
        return None
    return float(value)


def episode_ratios(rows: Sequence[Mapping[str, Any]], d_min: float) -> EpisodeRatios | None:
    """`EpisodeRatios` of evaluation ``rows`` with ``d_min`` (m); None where the rows do not
    record the return's parts (written before ``return_tc``/``return_sd``/``return_ga``)."""
    columns = ("return_tc", *(column for _, column in RETURN_TERMS))
    if any(_number(row.get(column)) is None for row in rows for column in columns):
        return None
    within = [row for row in rows if float(row["min_clearance"]) < d_min]
    ratios: dict[str, list[float]] = {term: [] for term, _ in RETURN_TERMS}
    zero = 0
    for row in within:
        task = abs(float(row["return_tc"]))
        if task == 0.0:
            zero += 1
            continue
        for term, column in RETURN_TERMS:
            ratios[term].append(abs(float(row[column])) / task)
    return EpisodeRatios(len(rows), len(within), zero, ratios)


@dataclass(frozen=True)
class ReturnCell:
    """One shaping term's share of the return for a method, task and policy, over seeds.

    Attributes:
        task, method, policy, term: what the cell is (term ``r_sd`` or ``r_ga``, the latter
            lambda_ga r_ga).
        seeds: runs pooled; ``recorded``: how many of them record the return's parts.
        episodes, within, zero_tc: episodes, those within d_min, those with r_tc = 0 (summed
            over the recorded runs).
        shares: the per-episode ratios used (within d_min, r_tc ≠ 0).
    """

    task: str
    method: str
    policy: str
    term: str
    seeds: int
    recorded: int
    episodes: int
    within: int
    zero_tc: int
    shares: tuple[float, ...]

    @property
    def mean(self) -> float | None:
        return float(np.mean(self.shares)) if self.shares else None

    @property
    def median(self) -> float | None:
        return float(np.median(self.shares)) if self.shares else None

    @property
    def verdict(self) -> str:
        """``yes``/``no`` against `CRITERION`, ``not recorded``, or ``n/a`` (no episode
        within d_min with a nonzero r_tc: the term never acted)."""
        if self.recorded == 0:
            return NOT_RECORDED
        mean = self.mean
        if mean is None:
            return "n/a"
        return "yes" if mean >= CRITERION else "no"


@dataclass(frozen=True)
class GradientCell:
    """One regulariser's share of the actor gradient at one learning-curve point, over seeds.

    Attributes:
        task, method, item, point: item ``l_sim``, ``l_hap`` (all samples) or
            ``l_hap_active`` (the samples outside C_safe); point one of `POINTS`.
        steps: the points' RL steps, one per seed that has the point.
        shares: per seed recording it, grad_item / grad_q.
        missing: seeds whose file lacks the column (or, for ``l_hap_active``, has no sample
            outside C_safe; see ``inactive``).
        inactive: seeds with ``hap_active_fraction`` = 0 (``l_hap_active`` only: no sample
            outside C_safe, the term does not act).
        active_fraction: per seed recording it, ``hap_active_fraction``.
    """

    task: str
    method: str
    item: str
    point: str
    steps: tuple[int, ...]
    shares: tuple[float, ...]
    missing: int = 0
    inactive: int = 0
    active_fraction: tuple[float, ...] = field(default=())

    @property
    def mean(self) -> float | None:
        return float(np.mean(self.shares)) if self.shares else None

    @property
    def verdict(self) -> str:
        """``yes``/``no`` against `CRITERION` (the mean over the seeds recording it),
        ``not recorded``, ``inactive`` (L_hap outside C_safe never acted) or ``n/a``
        (``l_hap`` over all samples: reported, not judged — the criterion is outside
        C_safe)."""
        if self.item == "l_hap":
            return "n/a"
        mean = self.mean
        if mean is None:
            return "inactive" if self.inactive and not self.missing else NOT_RECORDED
        return "yes" if mean >= CRITERION else "no"


def gradient_points(rows: Sequence[Mapping[str, Any]]) -> dict[str, Mapping[str, Any]]:
    """The first, middle and last `progress.csv` rows (by step) that recorded the actor's
    gradient norms (``grad_q`` > 0; the step-0 point, before any transition, has none):
    `POINTS` -> row; empty if no row did. The middle one is row (n - 1) // 2 of n."""
    recorded = sorted(
        (row for row in rows if (_number(row.get("grad_q")) or 0.0) > 0.0),
        key=lambda row: int(float(row["step"])),
    )
    if not recorded:
        return {}
    picks = (0, (len(recorded) - 1) // 2, len(recorded) - 1)
    return {point: recorded[index] for point, index in zip(POINTS, picks, strict=True)}


def _gradient_share(row: Mapping[str, Any], column: str) -> tuple[str, float | None]:
    """(status, grad_column / grad_q): status ``ok``, ``missing`` (column absent or empty
    without a reason) or ``inactive`` (``grad_hap_active`` empty because no sample was outside
    C_safe)."""
    value = _number(row.get(column))
    if value is not None:
        return "ok", value / float(row["grad_q"])
    if column == "grad_hap_active" and _number(row.get("hap_active_fraction")) == 0.0:
        return "inactive", None
    return "missing", None


def gradient_cells(
    task: str, method: str, runs: Sequence[Sequence[Mapping[str, Any]]]
) -> list[GradientCell]:
    """The `GradientCell` of every item the method uses (L_sim, L_hap) and point, from the
    ``progress.csv`` rows of each of its runs (one sequence per seed)."""
    spec = METHODS[method]
    items = [
        (item, column)
        for item, column in GRADIENT_ITEMS
        if (spec.similarity_loss if item == "l_sim" else spec.hap_prior)
    ]
    picked = [gradient_points(rows) for rows in runs]
    cells = []
    for item, column in items:
        for point in POINTS:
            steps, shares, fractions = [], [], []
            missing = inactive = 0
            for points in picked:
                if point not in points:
                    missing += 1
                    continue
                row = points[point]
                steps.append(int(float(row["step"])))
                status, share = _gradient_share(row, column)
                if share is not None:
                    shares.append(share)
                missing += status == "missing"
                inactive += status == "inactive"
                fraction = _number(row.get("hap_active_fraction"))
                if item == "l_hap_active" and fraction is not None:
                    fractions.append(fraction)
            cells.append(
                GradientCell(
                    task,
                    method,
                    item,
                    point,
                    tuple(steps),
                    tuple(shares),
                    missing,
                    inactive,
                    tuple(fractions),
                )
            )
    return cells


def return_cells(
    task: str,
    method: str,
    policy: str,
    runs: Sequence[tuple[Sequence[Mapping[str, Any]], float]],
) -> list[ReturnCell]:
    """The `ReturnCell` of r_sd and lambda_ga r_ga for a method's ``policy`` evaluations,
    ``runs`` = (evaluation rows, d_min in m) per seed."""
    per_run = [episode_ratios(rows, d_min) for rows, d_min in runs]
    recorded = [r for r in per_run if r is not None]
    return [
        ReturnCell(
            task,
            method,
            policy,
            term,
            len(runs),
            len(recorded),
            sum(r.episodes for r in recorded),
            sum(r.within for r in recorded),
            sum(r.zero_tc for r in recorded),
            tuple(share for r in recorded for share in r.ratios[term]),
        )
        for term, _ in RETURN_TERMS
    ]


IDLE_PROGRESS = 0.05
"""`plateau_cell`: an episode whose r_tc is below this share of the task's progress weight
(and that neither succeeded nor collided) made no task progress worth the name."""


@dataclass(frozen=True)
class PlateauCell:
    """How often a distance-reward method's policy idles on the r_ga plateau: evaluation
    episodes with no success, no collision and r_tc < `IDLE_PROGRESS` of the task's progress
    weight, pooled over seeds, and the mean lambda_ga r_ga they collect (the alignment reward
    paid for moving away from the obstacles instead of doing the task; docs/FINDINGS.md,
    "... the attractor is r_ga, not r_sd").

    Attributes:
        task, method, policy: what the cell is.
        seeds, episodes: runs pooled and their evaluation episodes.
        idle: the idle episodes; ``idle_ga``: their lambda_ga r_ga values.
    """

    task: str
    method: str
    policy: str
    seeds: int
    episodes: int
    idle: int
    idle_ga: tuple[float, ...]

    @property
    def share(self) -> float | None:
        return self.idle / self.episodes if self.episodes else None

    @property
    def mean_ga(self) -> float | None:
        return float(np.mean(self.idle_ga)) if self.idle_ga else None


def plateau_cell(
    task: str,
    method: str,
    policy: str,
    runs: Sequence[tuple[Sequence[Mapping[str, Any]], float]],
) -> PlateauCell | None:
    """The `PlateauCell` of ``runs``: (evaluation rows, the run's progress weight) per seed;
    None if no run records the return's parts."""
    episodes, idle_ga, seeds = 0, [], 0
    for rows, progress_weight in runs:
        recorded = [r for r in rows if _number(r.get("return_tc")) is not None]
        if not recorded:
            continue
        seeds += 1
        episodes += len(recorded)
        for row in recorded:
            tc = _number(row["return_tc"])
            ga = _number(row.get("return_ga"))
            done = bool(round(float(row["success"]))) or bool(round(float(row["collision"])))
            if not done and tc is not None and tc < IDLE_PROGRESS * progress_weight:
                idle_ga.append(ga if ga is not None else 0.0)
    if not seeds:
        return None
    return PlateauCell(task, method, policy, seeds, episodes, len(idle_ga), tuple(idle_ga))


@dataclass(frozen=True)
class MechanismTable:
    """The mechanism table's three parts and the runs left out.

    Attributes:
        preset: the preset's name.
        reach: one row per trainable method, task and position axis
            (`distgprl.experiments.mechanisms.reach_rows`: ``task``, ``method``, ``axis``,
            ``kind``, ``one_step_min_m``, ``one_step_max_m``, ``episode_min_m``,
            ``episode_max_m``, ``tc_range_m``, ``gate_max``).
        returns: the shaping shares of the return (`return_cells`).
        gradients: the regulariser shares of the actor gradient (`gradient_cells`).
        note: which runs were left out (`distgprl.report.runs.RunSelection.note`).
        plateau: the idle episodes on the r_ga plateau (`plateau_cell`).
    """

    preset: str
    reach: tuple[Mapping[str, Any], ...]
    returns: tuple[ReturnCell, ...]
    gradients: tuple[GradientCell, ...]
    note: str = ""
    plateau: tuple[PlateauCell, ...] = ()
