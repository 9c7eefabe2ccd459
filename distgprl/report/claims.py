"""The paper's claims, each tested by one statistic of the runs on each task, the estimate
pooling the tasks beside, and an overall verdict combined from the tasks' (`combine`).
Rules: docs/findings/protocol.md, "The claims rules as `distgprl.report.claims` applies them"."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, cast

import numpy as np
import pandas as pd

from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.aggregate import (
    ALL_TASKS,
    BOOTSTRAP_REPS,
    BOOTSTRAP_SEED,
    HIGHER_IS_BETTER,
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

BALANCE = "Dist-GPRL balances success, collisions and kinematic retention"
BALANCE_AXES = ("success_rate", "collision_rate", "mean_kinematic_retention")
"""The balance claim's axes (their direction: `HIGHER_IS_BETTER`)."""
_NONE = Estimate(np.nan, np.nan, np.nan, ())

Row = dict[str, Any]
"""A claim's ``task`` (or `ALL_TASKS`), ``estimate``, ``verdict`` and ``detail`` (what else
the rule read)."""


def records(frame: pd.DataFrame) -> list[Row]:
    """The frame's rows as dicts."""
    return cast(list[Row], frame.to_dict("records"))


def _judge(own: Estimate, read: list[Estimate], holds: bool, fails: bool, detail: str = "") -> Row:
    """A rule's row (no task yet): reproduced if it ``holds``, refuted if it ``fails``;
    `NO_RUNS` or `FEW_SEEDS` while an estimate it ``read`` lacks runs or an interval."""
    if any(not e.seeds for e in read):
        verdict = NO_RUNS
    elif any(not e.has_interval for e in read):
        verdict = FEW_SEEDS
    else:
        verdict = REPRODUCED if holds else REFUTED if fails else INCONCLUSIVE
    return {"estimate": own, "verdict": verdict, "detail": detail}


def combine(per_task: Sequence[tuple[str, str]]) -> str:
    """The overall verdict from (task, verdict) pairs (protocol, `combine`)."""
    verdicts = [v for _, v in per_task]
    if not verdicts or NO_RUNS in verdicts:
        return NO_RUNS
    if any(v not in (REPRODUCED, REFUTED, INCONCLUSIVE) for v in verdicts):
        return FEW_SEEDS
    deciding = {w: [task.upper() for task, v in per_task if v == w] for w in (REPRODUCED, REFUTED)}
    if all(deciding.values()):
        return TASKS_DISAGREE
    for word, tasks in deciding.items():
        if tasks:
            return word if len(tasks) == len(verdicts) else f"{word} on {', '.join(tasks)}"
    return INCONCLUSIVE


def _above(a: Estimate, b: Estimate, higher_is_better: bool = True) -> bool:
    """Whether ``a``'s interval lies entirely on the better side of ``b``'s."""
    return a.low > b.high if higher_is_better else b.low > a.high


def _iqms(scores: Scores, tasks: list[str], key: str, seed: int) -> dict[str, Estimate]:
    return {m: method_estimate(scores, tasks, m, key, "iqm", seed) for m in RANKED}


def poi_verdict(scores: Scores, tasks: list[str], seed: int, versus: str, key: str) -> Row:
    """ "Dist-GPRL improves on ``versus`` in ``key``" by the PoI rule; the detail counts the
    run pairs favouring Dist-GPRL on one task and, for a curve measure, each method's runs
    that learned (a finite ``learned_drop``)."""
    estimate = poi(scores, tasks, PROPOSED, versus, key, seed)
    parts = [f"{estimate.pairs_text()} favour Dist-GPRL"] if estimate.pairs_text() else []
    if len(tasks) == 1 and key in ("steps_to_gain", "learned_drop", "learning_auc"):
        drops = {m: strata(scores, tasks, m, "learned_drop")[0] for m in (PROPOSED, versus)}
        learned = [f"{short_label(m)} {np.isfinite(d).sum()}/{len(d)}" for m, d in drops.items()]
        parts.append(f"runs that learned: {', '.join(learned)}")
    return _judge(estimate, [estimate], estimate.low > 0.5, estimate.high < 0.5, ", ".join(parts))


def extreme_verdict(scores: Scores, tasks: list[str], seed: int, method: str, key: str) -> Row:
    """ "``method`` has the highest ``key``" by the IQM-interval rule."""
    estimates = _iqms(scores, tasks, key, seed)
    own = estimates.pop(method)
    rival = max(estimates, key=lambda m: estimates[m].point if estimates[m].seeds else -1.0)
    shown = estimates[rival].seeds
    detail = f"highest other: {short_label(rival)} {estimates[rival].text()}" if shown else ""
    others = list(estimates.values())
    highest = all(_above(own, other) for other in others)
    beaten = any(_above(other, own) for other in others)
    return _judge(own, [own, *others], highest, beaten, detail)


def conservative_verdict(scores: Scores, tasks: list[str], seed: int) -> Row:
    """ "ProMP-RRL is conservative"; the value is its collision IQM."""
    method = "promp-rrl"
    success = _iqms(scores, tasks, "success_rate", seed)
    collision = _iqms(scores, tasks, "collision_rate", seed)
    others = [m for m in RANKED if m != method]
    below = sum(_above(collision[m], collision[method]) for m in others)
    above = sum(_above(collision[method], collision[m]) for m in others)
    conservative = _above(success[PROPOSED], success[method]) and below >= len(others) / 2
    bold = _above(success[method], success[PROPOSED]) or above >= len(others) / 2
    detail = (
        f"success IQM {success[method].text()} vs Dist-GPRL {success[PROPOSED].text()}; "
        f"collision IQM below {below}, above {above} of {len(others)} others"
    )
    shown = detail if success[method].seeds and success[PROPOSED].seeds else ""
    read = [*success.values(), *collision.values()]
    return _judge(collision[method], read, conservative, bold, shown)


def labels(methods: Sequence[str]) -> str:
    """The methods' short labels, comma-separated; ``none`` for no method."""
    return ", ".join(short_label(m) for m in methods) or "none"


def balance_verdict(scores: Scores, tasks: list[str], seed: int) -> Row:
    """The balance claim by three-axis dominance on IQM intervals; the value is Dist-GPRL's
    retention IQM, the detail its success and collision IQMs and the non-dominated set."""
    iqm = {key: _iqms(scores, tasks, key, seed) for key in BALANCE_AXES}

    def dominates(a: str, b: str) -> bool:
        better = [_above(iqm[k][a], iqm[k][b], HIGHER_IS_BETTER[k]) for k in BALANCE_AXES]
        worse = [_above(iqm[k][b], iqm[k][a], HIGHER_IS_BETTER[k]) for k in BALANCE_AXES]
        return any(better) and not any(worse)

    dominated_by = {b: [a for a in RANKED if a != b and dominates(a, b)] for b in RANKED}
    dominating = [m for m in RANKED if PROPOSED in dominated_by[m]]
    balances = not dominated_by[PROPOSED] and bool(dominating)
    read = [e for per in iqm.values() for e in per.values()]
    detail = (
        f"success IQM {iqm['success_rate'][PROPOSED].text()}, collision IQM "
        f"{iqm['collision_rate'][PROPOSED].text()}; dominates {labels(dominating)}; "
        f"dominated by {labels(dominated_by[PROPOSED])}; non-dominated: "
        f"{labels([m for m in RANKED if not dominated_by[m]])}"
    )
    shown = detail if all(e.has_interval for e in read) else ""
    own = iqm["mean_kinematic_retention"][PROPOSED]
    return _judge(own, read, balances, bool(dominated_by[PROPOSED]), shown)


Claim = tuple[str, str, Callable[[Scores, list[str], int], Row], tuple[str, ...]]
"""(claim, test in words, rule(scores, tasks, seed) on one task or several pooled, the
methods whose runs it reads)."""

MEASURES = {
    "success_rate": "success",
    "collision_rate": "fewer collisions",
    "steps_to_gain": "fewer steps until the curve holds 0.2 above the untrained policy's",
    "learned_drop": "smaller mean drop of curve success once learned (never learned: worst)",
    "learning_auc": "larger mean gain of curve success over the untrained policy's",
}
"""What a PoI claim's score measures, as its test says."""


def _poi_claim(claim: str, versus: str, key: str) -> Claim:
    test = f"PoI of Dist-GPRL over {short_label(versus)}, {MEASURES[key]}"
    return claim, test, partial(poi_verdict, versus=versus, key=key), (PROPOSED, versus)


CLAIMS: tuple[Claim, ...] = (
    _poi_claim("Windowed adaptation beats global", "dist-gprl-global", "success_rate"),
    _poi_claim("The distance rewards lower collisions", "gprl-h", "collision_rate"),
    _poi_claim("The HAP prior raises final success", "gprl-d", "success_rate"),
    _poi_claim("The HAP prior speeds convergence", "gprl-d", "steps_to_gain"),
    _poi_claim("The covariance transform improves stability", "dist-gprl-nocov", "learned_drop"),
    _poi_claim(
        "The covariance transform improves sample efficiency", "dist-gprl-nocov", "learning_auc"
    ),
    (
        "Dist-GPRL has the best success",
        "Dist-GPRL's success IQM interval vs every other trained method's",
        partial(extreme_verdict, method=PROPOSED, key="success_rate"),
        RANKED,
    ),
    (
        BALANCE,
        "Dist-GPRL's (success, collision, kinematic retention) IQM intervals vs each "
        "trained method's: the non-dominated set",
        balance_verdict,
        RANKED,
    ),
    (
        "ProMP-RRL is conservative (few collisions, low success)",
        "ProMP-RRL's collision and success IQM intervals vs the other trained methods'",
        conservative_verdict,
        RANKED,
    ),
    (
        "GPRL collides most",
        "GPRL's collision IQM interval vs every other trained method's",
        partial(extreme_verdict, method="gprl", key="collision_rate"),
        RANKED,
    ),
)
"""Every claim in the paper's order: the PoI claims, then the ranking claims."""


def _waiting_for(scores: Scores, tasks: list[str], needs: tuple[str, ...]) -> str:
    """``no runs yet: GPRL-D (DCP), ...``: the methods of ``needs`` without runs (on which
    tasks where only some lack one)."""
    missing = []
    for method in needs:
        lacking = [task.upper() for task in tasks if not scores.get((task, method))]
        if len(lacking) == len(tasks):
            missing.append(short_label(method))
        elif lacking:
            missing.append(f"{short_label(method)} ({', '.join(lacking)})")
    return f"no runs yet: {', '.join(missing)}"


def evaluate_claims(scores: Scores, seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """A `Row` per claim of `CLAIMS` and task of ``scores``, then its `ALL_TASKS` row (the
    pooled estimate beside, empty with one task; the overall verdict), with ``claim``, ``test``."""
    tasks = tasks_of(scores)
    rows = []
    for claim, test, rule, needs in CLAIMS:
        per_task = [{"task": task, **rule(scores, [task], seed)} for task in tasks]
        pooled = rule(scores, tasks, seed)["estimate"] if len(tasks) > 1 else _NONE
        verdict = combine([(row["task"], row["verdict"]) for row in per_task])
        detail = _waiting_for(scores, tasks, needs) if verdict == NO_RUNS else ""
        overall = {"task": ALL_TASKS, "estimate": pooled, "verdict": verdict, "detail": detail}
        rows += [{"claim": claim, "test": test} | row for row in [*per_task, overall]]
    return pd.DataFrame(rows)


CSV_FIELDS = tuple("claim test task value ci_low ci_high seeds pairs verdict detail".split())
"""Columns of ``claims_<preset>.csv``: the rows of `evaluate_claims`, the estimate's cells as
`estimate_cells` writes them. The value of the ProMP-RRL row is its collision IQM, of the
balance row Dist-GPRL's kinematic-retention IQM (the other IQMs in ``detail``)."""


def _text(estimate: Estimate) -> str:
    # a PoI to three digits: a bound just below 0.5 does not print 0.50 beside a decided verdict
    return estimate.text(3 if estimate.pairs else 2)


def claims_texts(scores: Scores, preset: str, seed: int = BOOTSTRAP_SEED) -> tuple[str, str]:
    """(CSV, Markdown) of the claims table: per task first, pooled beside, overall last."""
    tasks = tasks_of(scores)
    frame = evaluate_claims(scores, seed)
    cells = []
    for _, group in frame.groupby(["claim", "test"], sort=False):
        *per_task, overall = records(group)
        shown = [f"{_text(row['estimate'])}: **{row['verdict']}**" for row in per_task]
        shown += [_text(overall["estimate"])] if len(tasks) > 1 else []
        notes = [f"{row['task'].upper()}: {row['detail']}" for row in per_task if row["detail"]]
        also = "; ".join(filter(None, [*notes, overall["detail"]])) or "–"
        verdict = f"**{overall['verdict']}**"
        cells.append([overall["claim"], overall["test"], *shown, verdict, also])
    caption = (
        f"Claims of the paper ({preset} preset): the verdict on each task, then the overall "
        f"verdict combined from the tasks' (reproduced only if no task refutes; 'the tasks "
        f"disagree' if one reproduces and another refutes); the estimate pooling the tasks is "
        f"beside, it decides nothing. Bootstrap intervals ({BOOTSTRAP_REPS} replicates, 95 %); "
        f"a PoI's never narrower than its score bound. Rules: `distgprl.report.claims`"
    )
    header = ["Claim", "Test", *(f"{t.upper()} [95 % CI]" for t in tasks)]
    header += ["Pooled (beside)"] if len(tasks) > 1 else []
    markdown = markdown_table(caption, [*header, "Verdict", "Also"], cells)
    rows = [row | estimate_cells(row["estimate"]) for row in records(frame)]
    return csv_text(rows, CSV_FIELDS), markdown
