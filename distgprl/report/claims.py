"""The paper's claims, each tested by one statistic of the runs, per task, with a verdict.

One row per claim the paper makes in its results and discussion: the statistic that tests it
(`distgprl.report.aggregate`), its value, 95 % interval and verdict on each task alone, the
estimate pooling both tasks (one stratum per task) beside it, never instead of it, then an
overall verdict combined from the tasks' (`combine`). The rules ("protocol" below):
docs/findings/protocol.md, "The claims rules as `distgprl.report.claims` applies them"; why
each is as it is: "Claims rules that cannot mislead" there. Written as ``claims_<preset>.csv``
(`CSV_FIELDS`) and ``.md`` by `claims_texts`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.aggregate import (
    ALL_TASKS,
    BOOTSTRAP_REPS,
    BOOTSTRAP_SEED,
    PROPOSED,
    Estimate,
    Scores,
    estimate_cells,
    method_estimate,
    poi,
    short_label,
    strata,
    tasks_of,
)
from distgprl.report.markdown import csv_text, markdown_table

RANKED = tuple(name for name in TABLE_ORDER if METHODS[name].trainable)
"""The methods the ranking claims rank: Table I's trained methods (not the references)."""

REPRODUCED, REFUTED, INCONCLUSIVE = "reproduced", "refuted", "inconclusive"
NO_RUNS = f"{INCONCLUSIVE} (no runs)"
FEW_SEEDS = f"{INCONCLUSIVE} (fewer than 2 seeds)"
TASKS_DISAGREE = "the tasks disagree"
"""The overall verdict when one task reproduces a claim and another refutes it."""

DECIDED = (REPRODUCED, REFUTED, INCONCLUSIVE)
"""The verdicts a task with runs of every needed method (two or more seeds) can reach."""


@dataclass(frozen=True)
class TaskVerdict:
    """A claim tested on one task alone (or, `ALL_TASKS`, on the tasks pooled).

    Attributes:
        task: the task's name, or `ALL_TASKS` for the pooled estimate.
        estimate: the statistic's value and 95 % interval.
        verdict: `REPRODUCED`, `REFUTED` or an `INCONCLUSIVE` text (protocol).
        detail: what else the rule looked at on this task.
    """

    task: str
    estimate: Estimate
    verdict: str
    detail: str = ""


@dataclass(frozen=True)
class Verdict:
    """A tested claim: its per-task verdicts, the overall one, the pooled estimate beside.

    Attributes:
        claim: the paper's claim in a few words.
        test: the statistic that tests it, in words.
        per_task: one `TaskVerdict` per task with runs, in the paper's order.
        pooled: the same statistic pooling the tasks (one stratum each), shown beside the
            per-task ones; None with a single task.
        verdict: the overall verdict, `combine` of the per-task ones.
        detail: what the overall verdict waits for (methods without runs), if anything.
        needs: the methods whose runs the test reads.
    """

    claim: str
    test: str
    per_task: tuple[TaskVerdict, ...]
    pooled: TaskVerdict | None
    verdict: str
    detail: str = ""
    needs: tuple[str, ...] = ()

    def on(self, task: str) -> TaskVerdict:
        """The verdict on ``task`` (`ALL_TASKS`: the pooled one)."""
        if task == ALL_TASKS and self.pooled is not None:
            return self.pooled
        return next(v for v in self.per_task if v.task == task)


@dataclass(frozen=True)
class PoiClaim:
    """A claim tested by Dist-GPRL's probability of improvement over ``versus`` on ``key``."""

    claim: str
    versus: str
    key: str
    measure: str


POI_CLAIMS = (
    PoiClaim("Windowed adaptation beats global", "dist-gprl-global", "success_rate", "success"),
    PoiClaim(
        "The distance rewards lower collisions", "gprl-h", "collision_rate", "fewer collisions"
    ),
    PoiClaim("The HAP prior raises final success", "gprl-d", "success_rate", "success"),
    PoiClaim(
        "The HAP prior speeds convergence",
        "gprl-d",
        "steps_to_gain",
        "fewer steps until the curve holds 0.2 above the untrained policy's",
    ),
    PoiClaim(
        "The covariance transform improves stability",
        "dist-gprl-nocov",
        "learned_drop",
        "smaller mean drop of curve success once learned (never learned: worst)",
    ),
    PoiClaim(
        "The covariance transform improves sample efficiency",
        "dist-gprl-nocov",
        "learning_auc",
        "larger mean gain of curve success over the untrained policy's",
    ),
)
"""The claims tested by a probability of improvement, in the paper's order."""

BALANCE = "Dist-GPRL balances success, collisions and kinematic retention"
BALANCE_AXES = (
    ("success_rate", True, "success"),
    ("collision_rate", False, "collision"),
    ("mean_kinematic_retention", True, "retention"),
)
"""The balance claim's axes: (score, higher is better, label)."""


def _availability(estimates: list[Estimate]) -> str | None:
    """`NO_RUNS` or `FEW_SEEDS` if some estimate lacks runs or an interval, else None."""
    if any(not e.seeds for e in estimates):
        return NO_RUNS
    if any(not e.has_interval for e in estimates):
        return FEW_SEEDS
    return None


def _decide(reproduced: bool, refuted: bool) -> str:
    """`REPRODUCED` if ``reproduced``, else `REFUTED` if ``refuted``, else `INCONCLUSIVE`."""
    return REPRODUCED if reproduced else REFUTED if refuted else INCONCLUSIVE


def _where(tasks: list[str]) -> str:
    """The `TaskVerdict.task` of a test on ``tasks``: the one task, or `ALL_TASKS` pooled."""
    return tasks[0] if len(tasks) == 1 else ALL_TASKS


def combine(per_task: Sequence[TaskVerdict]) -> str:
    """The overall verdict from the per-task ones (protocol): every task must
    reproduce for *reproduced*; one reproducing and another refuting is `TASKS_DISAGREE`."""
    verdicts = [v.verdict for v in per_task]
    if not verdicts or NO_RUNS in verdicts:
        return NO_RUNS
    if any(v not in DECIDED for v in verdicts):
        return FEW_SEEDS
    reproducing = [v.task.upper() for v in per_task if v.verdict == REPRODUCED]
    refuting = [v.task.upper() for v in per_task if v.verdict == REFUTED]
    if reproducing and refuting:
        return TASKS_DISAGREE
    for word, deciding in ((REPRODUCED, reproducing), (REFUTED, refuting)):
        if deciding:
            return word if len(deciding) == len(verdicts) else f"{word} on {', '.join(deciding)}"
    return INCONCLUSIVE


def _above(a: Estimate, b: Estimate) -> bool:
    """Whether ``a``'s interval lies entirely above ``b``'s."""
    return a.low > b.high


def _better(a: Estimate, b: Estimate, higher_is_better: bool) -> bool:
    """Whether ``a``'s interval lies entirely on the better side of ``b``'s."""
    return _above(a, b) if higher_is_better else _above(b, a)


def _iqms(scores: Scores, tasks: list[str], key: str, seed: int) -> dict[str, Estimate]:
    """{method: its ``key`` IQM estimate on ``tasks``} for every method of `RANKED`."""
    return {m: method_estimate(scores, tasks, m, key, "iqm", seed) for m in RANKED}


CURVE_KEYS = ("steps_to_gain", "learned_drop", "learning_auc")
"""The learning measures (`aggregate.curve_measures`); their claims also count the runs
that learned, so a verdict driven by runs that never learned says so."""


def _learned(scores: Scores, task: str, method: str) -> str:
    """``k/n``: ``method``'s runs on ``task`` whose curve held `aggregate.GAIN_MARGIN` above
    its start (a finite ``learned_drop``)."""
    drops = strata(scores, [task], method, "learned_drop")[0]
    return f"{int(np.isfinite(drops).sum())}/{len(drops)}"


def poi_task_verdict(scores: Scores, tasks: list[str], claim: PoiClaim, seed: int) -> TaskVerdict:
    """``claim`` on ``tasks`` (one task, or all pooled) by the PoI rule; its detail counts
    the run pairs favouring Dist-GPRL on a single task (``25/25 run pairs``) and, for a
    curve claim, the runs of each method that learned at all."""
    estimate = poi(scores, tasks, PROPOSED, claim.versus, claim.key, seed)
    parts = [f"{estimate.pairs_text()} favour Dist-GPRL"] if estimate.pairs_text() else []
    if len(tasks) == 1 and claim.key in CURVE_KEYS and estimate.seeds:
        parts.append(
            f"runs that learned: Dist-GPRL {_learned(scores, tasks[0], PROPOSED)}, "
            f"{short_label(claim.versus)} {_learned(scores, tasks[0], claim.versus)}"
        )
    verdict = _availability([estimate]) or _decide(estimate.low > 0.5, estimate.high < 0.5)
    return TaskVerdict(_where(tasks), estimate, verdict, ", ".join(parts))


def extreme_verdict(
    scores: Scores, tasks: list[str], method: str, key: str, seed: int
) -> TaskVerdict:
    """ "``method`` has the highest ``key``" on ``tasks`` by the IQM-interval rule."""
    estimates = _iqms(scores, tasks, key, seed)
    own = estimates.pop(method)
    rival = max(estimates, key=lambda m: estimates[m].point if estimates[m].seeds else -1.0)
    detail = f"highest other: {short_label(rival)} {estimates[rival].text()}"
    verdict = _availability([own, *estimates.values()]) or _decide(
        all(_above(own, other) for other in estimates.values()),
        any(_above(other, own) for other in estimates.values()),
    )
    return TaskVerdict(_where(tasks), own, verdict, detail if estimates[rival].seeds else "")


def conservative_verdict(scores: Scores, tasks: list[str], seed: int) -> TaskVerdict:
    """ "ProMP-RRL is conservative" on ``tasks`` by its rule (protocol)."""
    method = "promp-rrl"
    success = _iqms(scores, tasks, "success_rate", seed)
    collision = _iqms(scores, tasks, "collision_rate", seed)
    others = [m for m in RANKED if m != method]
    below = sum(_above(collision[m], collision[method]) for m in others)
    above = sum(_above(collision[method], collision[m]) for m in others)
    detail = (
        f"success IQM {success[method].text()} vs Dist-GPRL {success[PROPOSED].text()}; "
        f"collision IQM below {below}, above {above} of {len(others)} others"
    )
    verdict = _availability([*success.values(), *collision.values()]) or _decide(
        _above(success[PROPOSED], success[method]) and below >= len(others) / 2,
        _above(success[method], success[PROPOSED]) or above >= len(others) / 2,
    )
    shown = success[method].seeds and success[PROPOSED].seeds
    return TaskVerdict(_where(tasks), collision[method], verdict, detail if shown else "")


def non_dominated(estimates: dict[str, dict[str, Estimate]]) -> dict[str, list[str]]:
    """{method: the methods dominating it} on `BALANCE_AXES` (protocol: decisively
    better on one axis, decisively worse on none); a method with an empty list is in the
    non-dominated set. ``estimates`` is {score: {method: IQM estimate}}."""
    methods = list(next(iter(estimates.values())))

    def dominates(a: str, b: str) -> bool:
        better = [_better(estimates[k][a], estimates[k][b], up) for k, up, _ in BALANCE_AXES]
        worse = [_better(estimates[k][b], estimates[k][a], up) for k, up, _ in BALANCE_AXES]
        return any(better) and not any(worse)

    return {b: [a for a in methods if a != b and dominates(a, b)] for b in methods}


def _labels(methods: list[str]) -> str:
    return ", ".join(short_label(m) for m in methods) or "none"


def balance_verdict(scores: Scores, tasks: list[str], seed: int) -> TaskVerdict:
    """ "Dist-GPRL balances success, collisions and kinematic retention" on ``tasks`` by the
    three-axis dominance rule (protocol). The value is Dist-GPRL's retention IQM;
    the detail gives its success and collision IQMs and the non-dominated set."""
    estimates = {key: _iqms(scores, tasks, key, seed) for key, _, _ in BALANCE_AXES}
    own = estimates["mean_kinematic_retention"][PROPOSED]
    missing = _availability([e for per in estimates.values() for e in per.values()])
    if missing is not None:
        return TaskVerdict(_where(tasks), own, missing)
    dominated_by = non_dominated(estimates)
    dominating = [m for m in RANKED if PROPOSED in dominated_by[m]]
    verdict = _decide(not dominated_by[PROPOSED] and bool(dominating), bool(dominated_by[PROPOSED]))
    detail = (
        f"success IQM {estimates['success_rate'][PROPOSED].text()}, collision IQM "
        f"{estimates['collision_rate'][PROPOSED].text()}; dominates {_labels(dominating)}; "
        f"dominated by {_labels(dominated_by[PROPOSED])}; non-dominated: "
        f"{_labels([m for m in RANKED if not dominated_by[m]])}"
    )
    return TaskVerdict(_where(tasks), own, verdict, detail)


TaskRule = Callable[..., TaskVerdict]
"""A claim's test, ``rule(scores, tasks, seed=seed)``, on one task or several pooled."""

RANKING_CLAIMS: tuple[tuple[str, str, TaskRule], ...] = (
    (
        "Dist-GPRL has the best success",
        "Dist-GPRL's success IQM interval vs every other trained method's",
        partial(extreme_verdict, method=PROPOSED, key="success_rate"),
    ),
    (
        BALANCE,
        "Dist-GPRL's (success, collision, kinematic retention) IQM intervals vs each "
        "trained method's: the non-dominated set",
        balance_verdict,
    ),
    (
        "ProMP-RRL is conservative (few collisions, low success)",
        "ProMP-RRL's collision and success IQM intervals vs the other trained methods'",
        conservative_verdict,
    ),
    (
        "GPRL collides most",
        "GPRL's collision IQM interval vs every other trained method's",
        partial(extreme_verdict, method="gprl", key="collision_rate"),
    ),
)
"""The ranking claims, in the paper's order: (claim, test in words, rule); each reads the
runs of every method of `RANKED`."""


def _claim(
    scores: Scores, seed: int, claim: str, test: str, rule: TaskRule, needed: tuple[str, ...]
) -> Verdict:
    """``claim`` tested by ``rule`` on each task with runs, pooled beside, and combined; a
    `NO_RUNS` verdict names in its detail the methods of ``needed`` it waits for (with the
    tasks where only some lack a run)."""
    tasks = tasks_of(scores)
    per_task = tuple(rule(scores, [task], seed=seed) for task in tasks)
    pooled = rule(scores, tasks, seed=seed) if len(tasks) > 1 else None
    verdict = Verdict(claim, test, per_task, pooled, combine(per_task), needs=needed)
    if verdict.verdict != NO_RUNS:
        return verdict
    missing = []
    for method in needed:
        lacking = [task.upper() for task in tasks if not scores.get((task, method))]
        if not tasks or len(lacking) == len(tasks):
            missing.append(short_label(method))
        elif lacking:
            missing.append(f"{short_label(method)} ({', '.join(lacking)})")
    return replace(verdict, detail=f"no runs yet: {', '.join(missing)}")


def evaluate_claims(scores: Scores, seed: int = BOOTSTRAP_SEED) -> list[Verdict]:
    """Every claim of the paper tested on ``scores`` (protocol), in the paper's
    order: the ablation claims by PoI (`POI_CLAIMS`), then the ranking claims."""
    tests: list[tuple[str, str, TaskRule, tuple[str, ...]]] = [
        (
            c.claim,
            f"PoI of Dist-GPRL over {short_label(c.versus)}, {c.measure}",
            partial(poi_task_verdict, claim=c),
            (PROPOSED, c.versus),
        )
        for c in POI_CLAIMS
    ]
    tests += [(*ranking, RANKED) for ranking in RANKING_CLAIMS]
    return [_claim(scores, seed, *test) for test in tests]


CSV_FIELDS = tuple("claim test task value ci_low ci_high seeds pairs verdict detail".split())
"""Columns of ``claims_<preset>.csv``: one row per claim and task, then the claim's
`ALL_TASKS` row, whose value and interval are the pooled estimate and whose verdict is the
overall one (`combine` of the task rows; the pooled estimate does not decide it); value,
interval, seeds and pairs as `aggregate.estimate_cells` writes them. The ProMP-RRL
row's value is its collision IQM, its success IQM is in ``detail``; the balance row's value
is Dist-GPRL's kinematic-retention IQM, its success and collision IQMs are in ``detail``."""


def _estimate_text(estimate: Estimate) -> str:
    """``value [low, high]``; a PoI with three digits, so that a bound just below 0.5 does
    not print as 0.50 beside a decided verdict."""
    return estimate.text(3 if estimate.pairs else 2)


def _csv_rows(claim: Verdict) -> list[dict[str, object]]:
    """The `CSV_FIELDS` rows of ``claim``: one per task, then the overall one."""
    pooled = claim.pooled.estimate if claim.pooled else Estimate(math.nan, 0, 0, ())
    overall = TaskVerdict(ALL_TASKS, pooled, claim.verdict, claim.detail)
    return [
        {
            "claim": claim.claim,
            "test": claim.test,
            "task": row.task,
            **estimate_cells(row.estimate),
            "verdict": row.verdict,
            "detail": row.detail,
        }
        for row in (*claim.per_task, overall)
    ]


def _markdown_row(claim: Verdict) -> list[str]:
    """``claim``'s Markdown row: each task's estimate and verdict, the pooled estimate with
    several tasks, the overall verdict and the details."""
    cells = [claim.claim, claim.test]
    cells += [f"{_estimate_text(t.estimate)}: **{t.verdict}**" for t in claim.per_task]
    cells += [_estimate_text(claim.pooled.estimate)] if claim.pooled is not None else []
    also = [f"{t.task.upper()}: {t.detail}" for t in claim.per_task if t.detail]
    also += [claim.detail] if claim.detail else []
    return [*cells, f"**{claim.verdict}**", "; ".join(also) or "–"]


def claims_texts(scores: Scores, preset: str, seed: int = BOOTSTRAP_SEED) -> tuple[str, str]:
    """(CSV, Markdown) of the claims table (`evaluate_claims`): per task first, pooled
    beside, the overall verdict last."""
    verdicts = evaluate_claims(scores, seed)
    tasks = tasks_of(scores)
    caption = (
        f"Claims of the paper ({preset} preset): the verdict on each task, then the overall "
        f"verdict combined from the tasks' (reproduced only if no task refutes; 'the tasks "
        f"disagree' if one reproduces and another refutes); the estimate pooling the tasks is "
        f"beside, it decides nothing. Bootstrap intervals ({BOOTSTRAP_REPS} replicates, 95 %); "
        f"a PoI's never narrower than its score bound. Rules: `distgprl.report.claims`"
    )
    header = ["Claim", "Test", *(f"{t.upper()} [95 % CI]" for t in tasks)]
    header += ["Pooled (beside)"] if len(tasks) > 1 else []
    rows = [row for v in verdicts for row in _csv_rows(v)]
    markdown = markdown_table(caption, [*header, "Verdict", "Also"], map(_markdown_row, verdicts))
    return csv_text(rows, CSV_FIELDS), markdown
