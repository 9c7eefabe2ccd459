"""The paper's claims, each tested by one statistic of the runs, per task, with a verdict.

One row per claim the paper makes in its results and discussion: the statistic that tests
it (`distgprl.report.aggregate`: bootstrap intervals, `BOOTSTRAP_REPS` replicates, 95 %; a
PoI's interval never narrower than its score bound), its value, interval and verdict on
**each task alone**, then an overall verdict combined from the tasks' by the rule below.
The estimate pooling both tasks (one stratum per task) is shown beside the per-task ones,
never instead of them: pooled, opposite decisive effects (a PoI of 1 on DCP and 0 on DBM)
average to 0.5 and read as "no effect". Why each rule is as it is: docs/findings/protocol.md,
"Claims rules that cannot mislead".

Per task, probability-of-improvement claims (Dist-GPRL over one other method, on one score;
"fewer" or "lower" scores are improvements where the claim says so):

- *reproduced* if the PoI interval lies entirely above 0.5;
- *refuted* if it lies entirely below 0.5;
- *inconclusive* otherwise (the interval contains 0.5).

The curve claims use the learning measures of `aggregate.curve_measures`, each against the
untrained policy's curve success, never the run's own final value:

- "The HAP prior speeds convergence" ("accelerates convergence"): ``steps_to_gain``, the
  first step from which the curve holds `aggregate.GAIN_MARGIN` above its start for
  `aggregate.GAIN_POINTS` points (never: censored, the worst). Converging means rising to a
  level, so a curve that never rises cannot converge fast.
- "The covariance transform improves stability": ``learned_drop``, the mean drop of curve
  success per curve period once the run has learned (never learned: +inf, the worst).
  Stability is keeping what was learned; a flat curve has learned nothing to keep.
- "The covariance transform improves sample efficiency" ("better performance earlier in
  training"): ``learning_auc``, the mean gain of curve success over the untrained policy's
  during training. It rewards learning early and learning much, and gives nothing for
  staying at the start (a shrunk action that keeps the demonstration's level unchanged).

Per task, ranking claims compare IQM intervals of the seven trained methods of Table I
(`RANKED`):

- "Dist-GPRL has the best success": *reproduced* if its success-IQM interval lies entirely
  above every other method's; *refuted* if some method's lies entirely above Dist-GPRL's;
  else *inconclusive*.
- "GPRL collides most": the same rule on collision IQM, for GPRL.
- "ProMP-RRL is conservative (few collisions, low success)": *reproduced* if its success-IQM
  interval lies entirely below Dist-GPRL's and its collision-IQM interval lies entirely below
  those of at least half (3) of the six other methods; *refuted* if its success-IQM interval
  lies entirely above Dist-GPRL's or its collision-IQM interval lies entirely above those of
  at least half of the others; else *inconclusive*.
- "Dist-GPRL balances success, collisions and kinematic retention": on the three IQMs
  (success, higher is better; collision, lower; kinematic retention, the mean velocity cosine
  to the demonstration, higher), A is *decisively better* than B on an axis if A's interval
  lies entirely on the better side of B's; A *dominates* B if A is decisively better on at
  least one axis and decisively worse on none (Pareto dominance where overlapping intervals
  count as a tie). The non-dominated set is every method no other dominates. *Reproduced* if
  Dist-GPRL is non-dominated and dominates at least one method (a balance, not a tie with
  everyone); *refuted* if some method dominates it; else *inconclusive*.

Overall, from the per-task verdicts (`combine`):

- *reproduced* if every task reproduces the claim;
- *reproduced on T* if some tasks T reproduce it and none refutes it (the others
  inconclusive);
- *refuted* if every task refutes it; *refuted on T* if some tasks T refute it and none
  reproduces it;
- *the tasks disagree* if one task reproduces it and another refutes it;
- *inconclusive* if no task decides it.

Every claim is *inconclusive (no runs)* while a method it needs has no run on a task with
runs (its detail names them), and *inconclusive (fewer than 2 seeds)* while one has a task
with a single seed (no interval).

The claims table's files (``claims_<preset>.csv`` and ``.md``, `claims_texts`): per task
first, the pooled estimate beside, the overall verdict last.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.aggregate import (
    ALL_TASKS,
    BOOTSTRAP_REPS,
    BOOTSTRAP_SEED,
    PROPOSED,
    Estimate,
    Scores,
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
        verdict: `REPRODUCED`, `REFUTED` or an `INCONCLUSIVE` text (module docstring).
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


def poi_verdict(estimate: Estimate) -> str:
    """The PoI rule (module docstring) applied to ``estimate``."""
    missing = _availability([estimate])
    if missing:
        return missing
    if estimate.low > 0.5:
        return REPRODUCED
    if estimate.high < 0.5:
        return REFUTED
    return INCONCLUSIVE


def _task_name(task: str) -> str:
    return "pooled" if task == ALL_TASKS else task.upper()


def combine(per_task: Sequence[TaskVerdict]) -> str:
    """The overall verdict from the per-task ones (module docstring): every task must
    reproduce for *reproduced*; one reproducing and another refuting is `TASKS_DISAGREE`."""
    verdicts = [v.verdict for v in per_task]
    if not verdicts or NO_RUNS in verdicts:
        return NO_RUNS
    if any(v not in DECIDED for v in verdicts):
        return FEW_SEEDS
    reproducing = [_task_name(v.task) for v in per_task if v.verdict == REPRODUCED]
    refuting = [_task_name(v.task) for v in per_task if v.verdict == REFUTED]
    if reproducing and refuting:
        return TASKS_DISAGREE
    if reproducing:
        full = len(reproducing) == len(verdicts)
        return REPRODUCED if full else f"{REPRODUCED} on {', '.join(reproducing)}"
    if refuting:
        return REFUTED if len(refuting) == len(verdicts) else f"{REFUTED} on {', '.join(refuting)}"
    return INCONCLUSIVE


def _above(a: Estimate, b: Estimate) -> bool:
    """Whether ``a``'s interval lies entirely above ``b``'s."""
    return a.low > b.high


def _better(a: Estimate, b: Estimate, higher_is_better: bool) -> bool:
    """Whether ``a``'s interval lies entirely on the better side of ``b``'s."""
    return _above(a, b) if higher_is_better else _above(b, a)


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
    single = len(tasks) == 1
    parts = [f"{estimate.pairs_text()} favour Dist-GPRL"] if estimate.pairs_text() else []
    if single and claim.key in CURVE_KEYS and estimate.seeds:
        task = tasks[0]
        parts.append(
            f"runs that learned: Dist-GPRL {_learned(scores, task, PROPOSED)}, "
            f"{short_label(claim.versus)} {_learned(scores, task, claim.versus)}"
        )
    name = tasks[0] if single else ALL_TASKS
    return TaskVerdict(name, estimate, poi_verdict(estimate), ", ".join(parts))


def extreme_verdict(
    scores: Scores, tasks: list[str], method: str, key: str, seed: int
) -> TaskVerdict:
    """ "``method`` has the highest ``key``" on ``tasks`` by the IQM-interval rule."""
    estimates = {m: method_estimate(scores, tasks, m, key, "iqm", seed) for m in RANKED}
    own = estimates[method]
    others = {m: e for m, e in estimates.items() if m != method}
    rival = max(others, key=lambda m: -1.0 if not others[m].seeds else others[m].point)
    detail = (
        f"highest other: {short_label(rival)} {others[rival].text()}" if others[rival].seeds else ""
    )
    verdict = _availability(list(estimates.values()))
    if verdict is None:
        if all(_above(own, other) for other in others.values()):
            verdict = REPRODUCED
        elif any(_above(other, own) for other in others.values()):
            verdict = REFUTED
        else:
            verdict = INCONCLUSIVE
    return TaskVerdict(tasks[0] if len(tasks) == 1 else ALL_TASKS, own, verdict, detail)


def conservative_verdict(scores: Scores, tasks: list[str], seed: int) -> TaskVerdict:
    """ "ProMP-RRL is conservative" on ``tasks`` by its rule (module docstring)."""
    method = "promp-rrl"
    success = {m: method_estimate(scores, tasks, m, "success_rate", "iqm", seed) for m in RANKED}
    collision = {
        m: method_estimate(scores, tasks, m, "collision_rate", "iqm", seed) for m in RANKED
    }
    others = [m for m in RANKED if m != method]
    half = len(others) / 2
    below = sum(_above(collision[m], collision[method]) for m in others)
    above = sum(_above(collision[method], collision[m]) for m in others)
    detail = (
        ""
        if not (success[method].seeds and success[PROPOSED].seeds)
        else (
            f"success IQM {success[method].text()} vs Dist-GPRL {success[PROPOSED].text()}; "
            f"collision IQM below {below}, above {above} of {len(others)} others"
        )
    )
    verdict = _availability([*success.values(), *collision.values()])
    if verdict is None:
        if _above(success[PROPOSED], success[method]) and below >= half:
            verdict = REPRODUCED
        elif _above(success[method], success[PROPOSED]) or above >= half:
            verdict = REFUTED
        else:
            verdict = INCONCLUSIVE
    name = tasks[0] if len(tasks) == 1 else ALL_TASKS
    return TaskVerdict(name, collision[method], verdict, detail)


def non_dominated(estimates: dict[str, dict[str, Estimate]]) -> dict[str, list[str]]:
    """{method: the methods dominating it} on `BALANCE_AXES` (module docstring: decisively
    better on one axis, decisively worse on none); a method with an empty list is in the
    non-dominated set. ``estimates`` is {score: {method: IQM estimate}}."""
    methods = list(next(iter(estimates.values())))

    def dominates(a: str, b: str) -> bool:
        better = [_better(estimates[k][a], estimates[k][b], up) for k, up, _ in BALANCE_AXES]
        worse = [_better(estimates[k][b], estimates[k][a], up) for k, up, _ in BALANCE_AXES]
        return any(better) and not any(worse)

    return {b: [a for a in methods if a != b and dominates(a, b)] for b in methods}


def balance_verdict(scores: Scores, tasks: list[str], seed: int) -> TaskVerdict:
    """ "Dist-GPRL balances success, collisions and kinematic retention" on ``tasks`` by the
    three-axis dominance rule (module docstring). The value is Dist-GPRL's retention IQM;
    the detail gives its success and collision IQMs and the non-dominated set."""
    estimates = {
        key: {m: method_estimate(scores, tasks, m, key, "iqm", seed) for m in RANKED}
        for key, _, _ in BALANCE_AXES
    }
    name = tasks[0] if len(tasks) == 1 else ALL_TASKS
    own = estimates["mean_kinematic_retention"][PROPOSED]
    verdict = _availability([e for per in estimates.values() for e in per.values()])
    if verdict is not None:
        return TaskVerdict(name, own, verdict)
    dominated_by = non_dominated(estimates)
    front = [m for m in RANKED if not dominated_by[m]]
    dominating = [m for m in RANKED if PROPOSED in dominated_by[m]]
    if dominated_by[PROPOSED]:
        verdict = REFUTED
    elif dominating:
        verdict = REPRODUCED
    else:
        verdict = INCONCLUSIVE
    detail = (
        f"success IQM {estimates['success_rate'][PROPOSED].text()}, collision IQM "
        f"{estimates['collision_rate'][PROPOSED].text()}; dominates "
        f"{', '.join(short_label(m) for m in dominating) or 'none'}; dominated by "
        f"{', '.join(short_label(m) for m in dominated_by[PROPOSED]) or 'none'}; non-dominated: "
        f"{', '.join(short_label(m) for m in front)}"
    )
    return TaskVerdict(name, own, verdict, detail)


TaskRule = Callable[[list[str]], TaskVerdict]
"""A claim's test on a list of tasks (one task, or several pooled)."""


def _claim(
    scores: Scores, claim: str, test: str, rule: TaskRule, needed: tuple[str, ...]
) -> Verdict:
    """``claim`` tested by ``rule`` on each task with runs, pooled beside, and combined."""
    tasks = tasks_of(scores)
    per_task = tuple(rule([task]) for task in tasks)
    pooled = rule(tasks) if len(tasks) > 1 else None
    verdict = Verdict(claim, test, per_task, pooled, combine(per_task), needs=needed)
    return _name_the_missing(verdict, scores, tasks, needed)


def evaluate_claims(scores: Scores, seed: int = BOOTSTRAP_SEED) -> list[Verdict]:
    """Every claim of the paper tested on ``scores`` (module docstring), in the paper's
    order: the ablation claims by PoI, then the ranking claims."""
    verdicts = []
    for claim in POI_CLAIMS:

        def rule(tasks: list[str], claim: PoiClaim = claim) -> TaskVerdict:
            return poi_task_verdict(scores, tasks, claim, seed)

        test = f"PoI of Dist-GPRL over {short_label(claim.versus)}, {claim.measure}"
        verdicts.append(_claim(scores, claim.claim, test, rule, (PROPOSED, claim.versus)))
    ranking: list[tuple[str, str, TaskRule]] = [
        (
            "Dist-GPRL has the best success",
            "Dist-GPRL's success IQM interval vs every other trained method's",
            lambda tasks: extreme_verdict(scores, tasks, PROPOSED, "success_rate", seed),
        ),
        (
            BALANCE,
            "Dist-GPRL's (success, collision, kinematic retention) IQM intervals vs each "
            "trained method's: the non-dominated set",
            lambda tasks: balance_verdict(scores, tasks, seed),
        ),
        (
            "ProMP-RRL is conservative (few collisions, low success)",
            "ProMP-RRL's collision and success IQM intervals vs the other trained methods'",
            lambda tasks: conservative_verdict(scores, tasks, seed),
        ),
        (
            "GPRL collides most",
            "GPRL's collision IQM interval vs every other trained method's",
            lambda tasks: extreme_verdict(scores, tasks, "gprl", "collision_rate", seed),
        ),
    ]
    verdicts += [_claim(scores, claim, test, rule, RANKED) for claim, test, rule in ranking]
    return verdicts


def _name_the_missing(
    verdict: Verdict, scores: Scores, tasks: list[str], needed: tuple[str, ...]
) -> Verdict:
    """A `NO_RUNS` verdict with the methods it waits for in its detail (those of ``needed``
    without a run on some task of ``tasks``, with the task where only some lack it)."""
    if verdict.verdict != NO_RUNS:
        return verdict
    missing = []
    for method in needed:
        lacking = [task for task in tasks if not scores.get((task, method))]
        if not tasks or len(lacking) == len(tasks):
            missing.append(short_label(method))
        elif lacking:
            missing.append(f"{short_label(method)} ({', '.join(t.upper() for t in lacking)})")
    return replace(verdict, detail=f"no runs yet: {', '.join(missing)}")


CSV_FIELDS: tuple[str, ...] = ("claim", "test", "task", "value", "ci_low", "ci_high", "seeds")
CSV_FIELDS += ("pairs",)
CSV_FIELDS += ("verdict", "detail")
"""Columns of ``claims_<preset>.csv``: one row per claim and task, then the claim's
`ALL_TASKS` row, whose value and interval are the pooled estimate and whose verdict is the
overall one (`combine` of the task rows; the pooled estimate does not decide it). ``seeds``
are the runs per task stratum, ``;``-separated; ``pairs`` a PoI's run pairs per stratum;
value and interval empty without runs, the interval empty below two seeds. The ProMP-RRL
row's value is its collision IQM, its success IQM is in ``detail``; the balance row's value
is Dist-GPRL's kinematic-retention IQM, its success and collision IQMs are in ``detail``."""


def _csv_row(verdict: Verdict, task: TaskVerdict, overall: bool) -> dict[str, object]:
    e = task.estimate
    return {
        "claim": verdict.claim,
        "test": verdict.test,
        "task": task.task,
        "value": e.point if e.seeds else "",
        "ci_low": e.low if e.has_interval else "",
        "ci_high": e.high if e.has_interval else "",
        "seeds": ";".join(str(n) for n in e.seeds),
        "pairs": ";".join(str(n) for n in e.pairs),
        "verdict": verdict.verdict if overall else task.verdict,
        "detail": verdict.detail if overall else task.detail,
    }


def _cell(task: TaskVerdict) -> str:
    """``value [low, high]: **verdict**``; a PoI with three digits, so that a bound just
    below 0.5 does not print as 0.50 beside a decided verdict."""
    digits = 3 if task.estimate.pairs else 2
    return f"{task.estimate.text(digits)}: **{task.verdict}**"


def claims_texts(scores: Scores, preset: str, seed: int = BOOTSTRAP_SEED) -> tuple[str, str]:
    """(CSV, Markdown) of the claims table (`evaluate_claims`): per task first, pooled
    beside, the overall verdict last."""
    verdicts = evaluate_claims(scores, seed)
    tasks = tasks_of(scores)
    csv_rows = []
    for v in verdicts:
        csv_rows += [_csv_row(v, task, overall=False) for task in v.per_task]
        summary = v.pooled or TaskVerdict(ALL_TASKS, Estimate(float("nan"), 0, 0, ()), "")
        csv_rows.append(_csv_row(v, replace(summary, task=ALL_TASKS), overall=True))
    caption = (
        f"Claims of the paper ({preset} preset): the verdict on each task, then the overall "
        f"verdict combined from the tasks' (reproduced only if no task refutes; 'the tasks "
        f"disagree' if one reproduces and another refutes); the estimate pooling the tasks is "
        f"beside, it decides nothing. Bootstrap intervals ({BOOTSTRAP_REPS} replicates, 95 %); "
        f"a PoI's never narrower than its score bound. Rules: `distgprl.report.claims`"
    )
    header = ["Claim", "Test", *(f"{t.upper()} [95 % CI]" for t in tasks)]
    header += ["Pooled (beside)"] if len(tasks) > 1 else []
    header += ["Verdict", "Also"]
    rows = []
    for v in verdicts:
        line = [v.claim, v.test, *(_cell(t) for t in v.per_task)]
        if v.pooled is not None:
            line.append(v.pooled.estimate.text(3 if v.pooled.estimate.pairs else 2))
        also = [f"{t.task.upper()}: {t.detail}" for t in v.per_task if t.detail]
        also += [v.detail] if v.detail else []
        rows.append([*line, f"**{v.verdict}**", "; ".join(also) or "–"])
    return csv_text(csv_rows, CSV_FIELDS), markdown_table(caption, header, rows)
