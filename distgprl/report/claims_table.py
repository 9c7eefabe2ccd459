"""The claims table's files (``claims_<preset>.csv`` and ``.md``) from `distgprl.report.claims`'
verdicts: per task first, the pooled estimate beside, the overall verdict last."""

from __future__ import annotations

from dataclasses import replace

from distgprl.report.aggregate import (
    ALL_TASKS,
    BOOTSTRAP_REPS,
    BOOTSTRAP_SEED,
    Estimate,
    Scores,
    tasks_of,
)
from distgprl.report.claims import TaskVerdict, Verdict, evaluate_claims
from distgprl.report.markdown import csv_text, markdown_table

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
