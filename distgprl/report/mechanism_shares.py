"""The cells of the mechanism table (`distgprl.report.mechanisms`; protocol v6, rule 7 in
docs/findings/protocol.md): the shaping shares of the return, the regulariser shares of the
actor gradient and the r_ga plateau, pure functions of result-file rows (evaluation CSVs,
``progress.csv``) given as mappings; no file is read here, neither torch nor pybullet imported.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
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

GRADIENT_ITEMS = (("l_sim", "grad_sim"), ("l_hap", "grad_hap"), ("l_hap_active", "grad_hap_active"))
"""(item, progress column) of the gradient shares, each against ``grad_q``."""

ACTIVE = "hap_active_fraction"
"""The ``progress.csv`` column of the share of samples outside C_safe."""

IDLE_PROGRESS = 0.05
"""`plateau_cell`: an episode whose r_tc is below this share of the task's progress weight
(and that neither succeeded nor collided) made no task progress worth the name."""


def _number(value: Any) -> float | None:
    """A CSV cell as a float; None where it is empty, NaN or absent."""
    if value is None or value == "" or (isinstance(value, float) and np.isnan(value)):
        return None
    return float(value)


def _mean(values: Sequence[float]) -> float | None:
    return float(np.mean(values)) if values else None


def _judged(mean: float) -> str:
    return "yes" if mean >= CRITERION else "no"


@dataclass(frozen=True)
class EpisodeRatios:
    """The shaping ratios of one evaluation file: its ``episodes``, those ``within`` d_min
    (``min_clearance`` < d_min), of those the ``zero_tc`` ones whose r_tc sums to 0 (no ratio,
    left out), and per term (``r_sd``, ``r_ga``) the others' |sum term| / |sum r_tc|."""

    episodes: int
    within: int
    zero_tc: int
    ratios: dict[str, list[float]]


def episode_ratios(rows: Sequence[Mapping[str, Any]], d_min: float) -> EpisodeRatios | None:
    """`EpisodeRatios` of evaluation ``rows`` with ``d_min`` (m); None where the rows do not
    record the return's parts (written before ``return_tc``/``return_sd``/``return_ga``)."""
    columns = ("return_tc", *(column for _, column in RETURN_TERMS))
    if any(_number(row.get(column)) is None for row in rows for column in columns):
        return None
    within = [row for row in rows if float(row["min_clearance"]) < d_min]
    paid = [row for row in within if float(row["return_tc"]) != 0.0]
    ratios = {
        term: [abs(float(row[column])) / abs(float(row["return_tc"])) for row in paid]
        for term, column in RETURN_TERMS
    }
    return EpisodeRatios(len(rows), len(within), len(within) - len(paid), ratios)


@dataclass(frozen=True)
class ReturnCell:
    """One shaping term's share of the return (term ``r_sd`` or ``r_ga``, the latter
    lambda_ga r_ga) for a method, task and policy: ``seeds`` runs pooled, ``recorded`` of them
    recording the return's parts; ``episodes``, ``within`` d_min and ``zero_tc`` summed over
    the recorded runs; ``shares`` the per-episode ratios (within d_min, r_tc ≠ 0)."""

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
        return _mean(self.shares)

    @property
    def median(self) -> float | None:
        return float(np.median(self.shares)) if self.shares else None

    @property
    def verdict(self) -> str:
        """``yes``/``no`` against `CRITERION`, ``not recorded``, or ``n/a`` (no episode
        within d_min with a nonzero r_tc: the term never acted)."""
        if self.recorded == 0:
            return NOT_RECORDED
        return "n/a" if self.mean is None else _judged(self.mean)


def return_cells(
    task: str,
    method: str,
    policy: str,
    runs: Sequence[tuple[Sequence[Mapping[str, Any]], float]],
) -> list[ReturnCell]:
    """The `ReturnCell` of r_sd and lambda_ga r_ga for a method's ``policy`` evaluations,
    ``runs`` = (evaluation rows, d_min in m) per seed."""
    recorded = [r for r in (episode_ratios(rows, d_min) for rows, d_min in runs) if r is not None]
    episodes, within, zero_tc = (
        sum(getattr(r, name) for r in recorded) for name in ("episodes", "within", "zero_tc")
    )
    counts = (len(runs), len(recorded), episodes, within, zero_tc)
    shares = {term: tuple(s for r in recorded for s in r.ratios[term]) for term, _ in RETURN_TERMS}
    return [ReturnCell(task, method, policy, term, *counts, shares[term]) for term in shares]


@dataclass(frozen=True)
class GradientCell:
    """One regulariser's share of the actor gradient at one learning-curve point (one of
    `POINTS`), over seeds: item ``l_sim``, ``l_hap`` (all samples) or ``l_hap_active`` (the
    samples outside C_safe); ``steps`` the point's RL step per seed that has it; ``shares``
    grad_item / grad_q per seed recording it; ``missing`` the seeds without the point or the
    column; ``inactive`` the seeds with ``hap_active_fraction`` = 0 (``l_hap_active`` only:
    no sample outside C_safe, the term does not act); ``active_fraction`` per seed recording
    it, ``hap_active_fraction`` (``l_hap_active`` only)."""

    task: str
    method: str
    item: str
    point: str
    steps: tuple[int, ...]
    shares: tuple[float, ...]
    missing: int = 0
    inactive: int = 0
    active_fraction: tuple[float, ...] = ()

    @property
    def mean(self) -> float | None:
        return _mean(self.shares)

    @property
    def verdict(self) -> str:
        """``yes``/``no`` against `CRITERION` (the mean over the seeds recording it),
        ``not recorded``, ``inactive`` (L_hap outside C_safe never acted) or ``n/a``
        (``l_hap`` over all samples: reported, not judged — the criterion is outside
        C_safe)."""
        if self.item == "l_hap":
            return "n/a"
        if self.mean is None:
            return "inactive" if self.inactive and not self.missing else NOT_RECORDED
        return _judged(self.mean)


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


def gradient_cells(
    task: str, method: str, runs: Sequence[Sequence[Mapping[str, Any]]]
) -> list[GradientCell]:
    """The `GradientCell` of every item the method uses (L_sim, L_hap) and point, from the
    ``progress.csv`` rows of each of its runs (one sequence per seed). A seed whose
    ``grad_hap_active`` is empty with ``hap_active_fraction`` = 0 is inactive, any other
    empty cell missing."""
    spec = METHODS[method]
    picked = [gradient_points(rows) for rows in runs]
    cells = []
    for item, column in GRADIENT_ITEMS:
        if not (spec.similarity_loss if item == "l_sim" else spec.hap_prior):
            continue
        for point in POINTS:
            rows = [points[point] for points in picked if point in points]
            shares, missing, inactive = [], len(picked) - len(rows), 0
            for row in rows:
                value = _number(row.get(column))
                if value is not None:
                    shares.append(value / float(row["grad_q"]))
                elif column == "grad_hap_active" and _number(row.get(ACTIVE)) == 0.0:
                    inactive += 1
                else:
                    missing += 1
            fractions = [_number(row.get(ACTIVE)) for row in rows if item == "l_hap_active"]
            steps = tuple(int(float(row["step"])) for row in rows)
            active = tuple(fraction for fraction in fractions if fraction is not None)
            shared = tuple(shares)
            cells.append(
                GradientCell(task, method, item, point, steps, shared, missing, inactive, active)
            )
    return cells


@dataclass(frozen=True)
class TaskReturns:
    """What one run's reward scale pays for the task (protocol v8, rule 1): its
    ``progress_weight``, the r_tc of a success (``success_return``) and the demonstration's mean
    r_tc on the evaluation TCs under that scale (``demo_return``)."""

    progress_weight: float
    success_return: float
    demo_return: float


@dataclass(frozen=True)
class PlateauCell:
    """How often a distance-reward method's policy idles on the r_ga plateau: of ``episodes``
    evaluation episodes of ``seeds`` runs, the ``idle`` ones (no success, no collision, r_tc <
    `IDLE_PROGRESS` of the task's progress weight) and their lambda_ga r_ga values
    ``idle_ga`` (the alignment reward paid for moving away from the obstacles instead of doing
    the task; docs/FINDINGS.md, "The first v7 runs: the attractor is r_ga, not r_sd").

    Rule 1's two ratios (protocol v8) measured on these episodes: ``ga_of_success``, each
    episode's lambda_ga Σ r_ga over its run's success r_tc (bound (a), 5 %), and
    ``idle_of_demo``, each idle episode's return (r_tc + r_sd + lambda_ga r_ga) over its run's
    demonstration r_tc (bound (b), 10 %)."""

    task: str
    method: str
    policy: str
    seeds: int
    episodes: int
    idle: int
    idle_ga: tuple[float, ...]
    ga_of_success: tuple[float, ...] = ()
    idle_of_demo: tuple[float, ...] = ()

    @property
    def share(self) -> float | None:
        return self.idle / self.episodes if self.episodes else None

    @property
    def mean_ga(self) -> float | None:
        return _mean(self.idle_ga)


def _episode_return(row: Mapping[str, Any]) -> float:
    """An evaluation row's return: r_tc + r_sd + lambda_ga r_ga (an absent part counts 0)."""
    parts = (_number(row.get(column)) for column in ("return_tc", "return_sd", "return_ga"))
    return sum(part or 0.0 for part in parts)


def plateau_cell(
    task: str,
    method: str,
    policy: str,
    runs: Sequence[tuple[Sequence[Mapping[str, Any]], TaskReturns]],
) -> PlateauCell | None:
    """The `PlateauCell` of ``runs``: (evaluation rows, the run's `TaskReturns`) per seed;
    None if no run records the return's parts."""
    episodes, idle_ga, seeds, ga_of_success, idle_of_demo = 0, [], 0, [], []
    for rows, returns in runs:
        recorded = [r for r in rows if _number(r.get("return_tc")) is not None]
        seeds += bool(recorded)
        episodes += len(recorded)
        for row in recorded:
            ga = _number(row.get("return_ga")) or 0.0
            ga_of_success.append(ga / returns.success_return)
            done = bool(round(float(row["success"]))) or bool(round(float(row["collision"])))
            if not done and float(row["return_tc"]) < IDLE_PROGRESS * returns.progress_weight:
                idle_ga.append(ga)
                idle_of_demo.append(_episode_return(row) / returns.demo_return)
    if not seeds:
        return None
    return PlateauCell(
        task,
        method,
        policy,
        seeds,
        episodes,
        len(idle_ga),
        tuple(idle_ga),
        tuple(ga_of_success),
        tuple(idle_of_demo),
    )


@dataclass(frozen=True)
class MechanismTable:
    """The mechanism table's parts: ``reach``, one row per trainable method, task and position
    axis (`distgprl.experiments.mechanisms.reach_rows` names its fields); the `return_cells`,
    `gradient_cells` and `plateau_cell` cells; ``note`` which runs were left out
    (`distgprl.report.runs.RunSelection.note`)."""

    preset: str
    reach: tuple[Mapping[str, Any], ...]
    returns: tuple[ReturnCell, ...]
    gradients: tuple[GradientCell, ...]
    note: str = ""
    plateau: tuple[PlateauCell, ...] = ()
