"""The paper's claims, each tested by one statistic of the runs, with a verdict.

One row per claim the paper makes in its results and discussion: the statistic that tests it
(`distgprl.report.aggregate`: stratified bootstrap, `BOOTSTRAP_REPS` replicates, 95 %
intervals), its value and interval, and the verdict *reproduced*, *refuted* or
*inconclusive*. Every statistic pools both tasks, one stratum per task (task group
`ALL_TASKS`; a single task if only one has runs). The rules below were fixed, with the
learning-curve measures (`aggregate.curve_measures`), before any run of the v5 paper preset
existed; they are not to be tuned to the results.

Probability-of-improvement claims (Dist-GPRL over one other method, on one score; "fewer" or
"lower" scores are improvements where the claim says so):

- *reproduced* if the PoI interval lies entirely above 0.5;
- *refuted* if it lies entirely below 0.5;
- *inconclusive* otherwise (the interval contains 0.5).

Ranking claims compare IQM intervals of the seven trained methods of Table I (`RANKED`):

- "Dist-GPRL has the best success": *reproduced* if its success-IQM interval lies entirely
  above every other method's; *refuted* if some method's lies entirely above Dist-GPRL's;
  else *inconclusive*.
- "GPRL collides most": the same rule on collision IQM, for GPRL.
- "ProMP-RRL is conservative (few collisions, low success)": *reproduced* if its success-IQM
  interval lies entirely below Dist-GPRL's and its collision-IQM interval lies entirely below
  those of at least half (3) of the six other methods; *refuted* if its success-IQM interval
  lies entirely above Dist-GPRL's or its collision-IQM interval lies entirely above those of
  at least half of the others; else *inconclusive*.

- "Dist-GPRL balances collisions and kinematic retention": on the pair (collision IQM, lower
  is better; kinematic-retention IQM, the mean velocity cosine to the demonstration, higher
  is better) method A *dominates* B if A's interval lies entirely on the better side of B's on
  both. *Reproduced* if no trained method dominates Dist-GPRL and Dist-GPRL dominates at
  least one; *refuted* if some method dominates it; else *inconclusive*.

Every claim is *inconclusive (no runs)* while a method it needs has no run (its detail names
them), and
*inconclusive (fewer than 2 seeds)* while one has a task with a single seed (no interval).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from dataclasses import dataclass, replace

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
    task_groups,
)
from distgprl.report.markdown import markdown_table

RANKED = tuple(name for name in TABLE_ORDER if METHODS[name].trainable)
"""The methods the ranking claims rank: Table I's trained methods (not the references)."""

REPRODUCED, REFUTED, INCONCLUSIVE = "reproduced", "refuted", "inconclusive"
NO_RUNS = f"{INCONCLUSIVE} (no runs)"
FEW_SEEDS = f"{INCONCLUSIVE} (fewer than 2 seeds)"


@dataclass(frozen=True)
class Verdict:
    """A tested claim.

    Attributes:
        claim: the paper's claim in a few words.
        test: the statistic that tests it, in words.
        estimate: its value and 95 % interval (empty seeds with no runs).
        verdict: `REPRODUCED`, `REFUTED` or an `INCONCLUSIVE` text (module docstring rules).
        detail: what else the rule looked at (for a PoI claim pooling two tasks, the PoI on
            each task alone, `per_task_poi`).
    """

    claim: str
    test: str
    estimate: Estimate
    verdict: str
    detail: str = ""


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
        "steps_to_80",
        "fewer steps to 80 % of the final curve success",
    ),
    PoiClaim(
        "The covariance transform improves stability",
        "dist-gprl-nocov",
        "late_variance",
        "lower variance of curve success over the last third of the curve",
    ),
    PoiClaim(
        "The covariance transform improves sample efficiency",
        "dist-gprl-nocov",
        "curve_auc",
        "higher normalised area under the success curve",
    ),
)
"""The claims tested by a probability of improvement, in the paper's order."""


def _label(method: str) -> str:
    return METHODS[method].label.removesuffix(" (ours)")


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


def _above(a: Estimate, b: Estimate) -> bool:
    """Whether ``a``'s interval lies entirely above ``b``'s."""
    return a.low > b.high


def extreme_verdict(
    scores: Scores, tasks: list[str], method: str, key: str, claim: str, seed: int
) -> Verdict:
    """``claim``, "``method`` has the highest ``key``", by the IQM-interval rule (module
    docstring)."""
    estimates = {m: method_estimate(scores, tasks, m, key, "iqm", seed) for m in RANKED}
    own = estimates[method]
    others = {m: e for m, e in estimates.items() if m != method}
    rival = max(others, key=lambda m: -1.0 if not others[m].seeds else others[m].point)
    detail = f"highest other: {_label(rival)} {others[rival].text()}" if others[rival].seeds else ""
    verdict = _availability(list(estimates.values()))
    if verdict is None:
        if all(_above(own, other) for other in others.values()):
            verdict = REPRODUCED
        elif any(_above(other, own) for other in others.values()):
            verdict = REFUTED
        else:
            verdict = INCONCLUSIVE
    what = key.removesuffix("_rate")
    test = f"{_label(method)}'s {what} IQM interval vs every other trained method's"
    return Verdict(claim, test, own, verdict, detail)


def conservative_verdict(scores: Scores, tasks: list[str], seed: int) -> Verdict:
    """ "ProMP-RRL is conservative" by its rule (module docstring)."""
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
    test = "ProMP-RRL's collision and success IQM intervals vs the other trained methods'"
    claim = "ProMP-RRL is conservative (few collisions, low success)"
    return Verdict(claim, test, collision[method], verdict, detail)


def _better(a: Estimate, b: Estimate, higher_is_better: bool) -> bool:
    """Whether ``a``'s interval lies entirely on the better side of ``b``'s."""
    return _above(a, b) if higher_is_better else _above(b, a)


def balance_verdict(scores: Scores, tasks: list[str], seed: int) -> Verdict:
    """ "Dist-GPRL balances collisions and kinematic retention" by its dominance rule (module
    docstring)."""
    keys = (("collision_rate", False), ("mean_kinematic_retention", True))
    estimates = {
        key: {m: method_estimate(scores, tasks, m, key, "iqm", seed) for m in RANKED}
        for key, _ in keys
    }
    others = [m for m in RANKED if m != PROPOSED]

    def dominates(a: str, b: str) -> bool:
        return all(_better(estimates[k][a], estimates[k][b], up) for k, up in keys)

    dominated_by = [m for m in others if dominates(m, PROPOSED)]
    dominating = [m for m in others if dominates(PROPOSED, m)]
    verdict = _availability([e for per in estimates.values() for e in per.values()])
    if verdict is None:
        if dominated_by:
            verdict = REFUTED
        elif dominating:
            verdict = REPRODUCED
        else:
            verdict = INCONCLUSIVE
    own = estimates["mean_kinematic_retention"][PROPOSED]
    detail = ""
    if own.seeds and estimates["collision_rate"][PROPOSED].seeds:
        detail = (
            f"collision IQM {estimates['collision_rate'][PROPOSED].text()}; dominates "
            f"{', '.join(_label(m) for m in dominating) or 'none'}; dominated by "
            f"{', '.join(_label(m) for m in dominated_by) or 'none'}"
        )
    test = "Dist-GPRL's (collision, kinematic retention) IQM intervals vs each trained method's"
    claim = "Dist-GPRL balances collisions and kinematic retention"
    return Verdict(claim, test, own, verdict, detail)


def claims_group(scores: Scores) -> list[str]:
    """The tasks the claims pool: every task with runs (`ALL_TASKS`), or the single one."""
    groups = dict(task_groups(scores))
    return groups.get(ALL_TASKS, next(iter(groups.values()), []))


def evaluate_claims(scores: Scores, seed: int = BOOTSTRAP_SEED) -> list[Verdict]:
    """Every claim of the paper tested on ``scores`` (module docstring), in the paper's
    order: the ablation claims by PoI, then the ranking claims."""
    tasks = claims_group(scores)
    verdicts = []
    for claim in POI_CLAIMS:
        estimate = poi(scores, tasks, PROPOSED, claim.versus, claim.key, seed)
        test = f"PoI of Dist-GPRL over {_label(claim.versus)}, {claim.measure}"
        detail = per_task_poi(scores, tasks, claim, seed) if len(tasks) > 1 else ""
        verdict = Verdict(claim.claim, test, estimate, poi_verdict(estimate), detail)
        verdicts.append(_name_the_missing(verdict, scores, tasks, (PROPOSED, claim.versus)))
    rules: list[Callable[[], Verdict]] = [
        lambda: extreme_verdict(
            scores, tasks, PROPOSED, "success_rate", "Dist-GPRL has the best success", seed
        ),
        lambda: balance_verdict(scores, tasks, seed),
        lambda: conservative_verdict(scores, tasks, seed),
        lambda: extreme_verdict(
            scores, tasks, "gprl", "collision_rate", "GPRL collides most", seed
        ),
    ]
    verdicts += [_name_the_missing(rule(), scores, tasks, RANKED) for rule in rules]
    return verdicts


TASKS_DISAGREE = "the tasks disagree"
"""Said after the per-task PoIs when one task's interval lies above 0.5 and another's below:
the pooled PoI then averages opposite effects (its interval may still contain 0.5)."""


def per_task_poi(scores: Scores, tasks: list[str], claim: PoiClaim, seed: int) -> str:
    """The detail of a pooled PoI claim: the same PoI on each task alone (``DCP 1.00 [1.00,
    1.00]; DBM 0.00 [0.00, 0.00]``), and `TASKS_DISAGREE` where the tasks' intervals lie on
    opposite sides of 0.5. Information beside the verdict; the rule stays the pooled one."""
    estimates = {t: poi(scores, [t], PROPOSED, claim.versus, claim.key, seed) for t in tasks}
    parts = [f"{t.upper()} {e.text()}" for t, e in estimates.items() if e.seeds]
    if not parts:
        return ""
    text = "per task: " + "; ".join(parts)
    verdicts = {poi_verdict(e) for e in estimates.values()}
    if {REPRODUCED, REFUTED} <= verdicts:
        text += f" ({TASKS_DISAGREE})"
    return text


def _name_the_missing(
    verdict: Verdict, scores: Scores, tasks: list[str], needed: tuple[str, ...]
) -> Verdict:
    """An `NO_RUNS` verdict with the methods it waits for in its detail (those of ``needed``
    without a run on any task of ``tasks``: a pooled estimate drops empty task strata)."""
    if verdict.verdict != NO_RUNS:
        return verdict
    missing = [_label(m) for m in needed if all(not scores.get((task, m)) for task in tasks)]
    note = f"no runs yet: {', '.join(missing)}"
    return replace(verdict, detail=f"{verdict.detail}; {note}" if verdict.detail else note)


CSV_FIELDS = ("claim", "test", "value", "ci_low", "ci_high", "seeds", "verdict", "detail")
"""Columns of ``claims_<preset>.csv`` (``seeds`` per task stratum, ``;``-separated; value and
interval empty without runs, the interval empty below two seeds). The ProMP-RRL row's value is
its collision IQM, its success IQM is in ``detail``; the balance row's value is Dist-GPRL's
kinematic-retention IQM, its collision IQM is in ``detail``."""


def claims_texts(scores: Scores, preset: str, seed: int = BOOTSTRAP_SEED) -> tuple[str, str]:
    """(CSV, Markdown) of the claims table (`evaluate_claims`)."""
    verdicts = evaluate_claims(scores, seed)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(CSV_FIELDS), lineterminator="\n")
    writer.writeheader()
    for v in verdicts:
        e = v.estimate
        writer.writerow(
            {
                "claim": v.claim,
                "test": v.test,
                "value": e.point if e.seeds else "",
                "ci_low": e.low if e.has_interval else "",
                "ci_high": e.high if e.has_interval else "",
                "seeds": ";".join(str(n) for n in e.seeds),
                "verdict": v.verdict,
                "detail": v.detail,
            }
        )
    tasks = claims_group(scores)
    pooled = " + ".join(t.upper() for t in tasks) if tasks else "no task"
    caption = (
        f"Claims of the paper ({preset} preset; {pooled}, stratified bootstrap, "
        f"{BOOTSTRAP_REPS} replicates, 95 % intervals). Verdict rules: "
        "`distgprl.report.claims` (PoI interval above 0.5: reproduced, below: refuted)"
    )
    header = ["Claim", "Test", "Value [95 % CI]", "Verdict", "Also"]
    rows = [[v.claim, v.test, v.estimate.text(), v.verdict, v.detail or "–"] for v in verdicts]
    return buffer.getvalue(), markdown_table(caption, header, rows)
