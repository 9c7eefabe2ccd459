"""When each run learns: the learning-curve onset per reading and seed, and a control's verdict.

A mean over seeds averages an early and a late learner into one slope; the studies' question
("does this reading leave the r_ga plateau, and when?") is per run. For every study
(`distgprl.studies`) read beside a preset, every method it trains under each of its readings
(`onset_panels`: the control included; for an operator study also NoCov, which no reading
changes), this tabulates per task and seed:

- ``onset_step``: the first learning-curve step after step 0 (``progress.csv``; the curve
  TCs, the deterministic policy of that step) at which success reaches the threshold — the
  control's pre-registered `distgprl.studies.OnsetRule` where the study has one, else
  `THRESHOLD` — empty when it never does. Step 0 is the untrained policy, whose curve success
  is 0.00–0.60 by seed under every reading and says nothing about learning (Table I's DCP
  seeds 0 and 2 start at 0.40–0.44 and fall onto the plateau at step 1 500);
- ``early`` (with a rule): whether that step is at or before the rule's ``by_step``;
- the best and the final policy's success and collision on the evaluation TCs (Table I's
  ``summary_best.json`` and ``summary.json``).

A control's verdict (`rule_verdict`) applies its rule to its own runs of the rule's task:
with fewer than the rule's seeds finished it is "awaiting", otherwise the count of early runs
decides it as the rule states, fixed before the control's first run
(docs/findings/operator.md, "The uncoupled-signal control"). The other readings' counts are
listed beside it, measured the same way, and decide nothing.

Reads result files only; `distgprl tables` writes ``onsets_<study>_<preset>.{csv,md}``.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.curves import reading_columns, seed_curves
from distgprl.report.markdown import markdown_table
from distgprl.report.paired import FINAL_POLICY
from distgprl.report.runs import TABLE_POLICY
from distgprl.report.table1 import per_seed_rows
from distgprl.studies import OnsetRule, Study

__all__ = [
    "CSV_FIELDS",
    "THRESHOLD",
    "RuleVerdict",
    "onset_panels",
    "onset_rows",
    "onset_step",
    "onset_texts",
    "rule_verdict",
    "study_rule",
]

THRESHOLD = 0.5
"""Curve success that counts as learned for a study without a control rule."""

CSV_FIELDS = [
    "study",
    "task",
    "reading",
    "preset",
    "method",
    "seed",
    "onset_step",
    "early",
    "best_success",
    "best_collision",
    "final_success",
    "final_collision",
]


def onset_step(steps: Any, success: Any, threshold: float) -> int | None:
    """The first of ``steps`` (k,) after step 0 whose ``success`` (k,) is at least
    ``threshold``; None if none is (step 0 is the untrained policy: module docstring)."""
    for step, value in zip(steps, success, strict=True):
        if int(step) > 0 and float(value) >= threshold:
            return int(step)
    return None


def study_rule(study: Study) -> OnsetRule | None:
    """The first control rule of the study's readings (the threshold its table uses)."""
    return next((r.rule for r in study.readings if r.rule is not None), None)


def _evaluations(
    root: str | Path, preset: str, policy: str
) -> dict[tuple[str, str, int], dict[str, Any]]:
    return {(r["task"], r["method"], r["seed"]): r for r in per_seed_rows(root, preset, policy)}


def onset_panels(study: Study) -> list[tuple[str, str, str]]:
    """(preset, method, reading label) per table row: each of the study's methods (Table I's
    order) under each reading, the reference's first; an operator study adds NoCov from the
    reference preset (`distgprl.report.curves.reading_columns`' last panel)."""
    methods = [m for m in TABLE_ORDER if m in study.methods]
    panels = [(r.preset, m, r.label) for m in methods for r in study.all_readings]
    extra = [(p, m, title) for p, m, title in reading_columns(study) if m not in study.methods]
    return panels + extra


def onset_rows(root: str | Path, study: Study, tasks: list[str]) -> list[dict[str, Any]]:
    """One row per `onset_panels` panel, task and finished seed (CSV_FIELDS), panels in
    their order; the threshold and ``early`` from `study_rule` (``early`` empty without)."""
    rule = study_rule(study)
    threshold = rule.threshold if rule else THRESHOLD
    evaluations: dict[tuple[str, str], dict[tuple[str, str, int], dict[str, Any]]] = {}
    rows = []
    for preset, method, reading in onset_panels(study):
        for policy in (TABLE_POLICY, FINAL_POLICY):
            if (preset, policy) not in evaluations:
                evaluations[(preset, policy)] = _evaluations(root, preset, policy)
        for task in tasks:
            for seed, (steps, values) in seed_curves(root, preset, task, method).items():
                onset = onset_step(steps, values["success_rate"], threshold)
                best = evaluations[(preset, TABLE_POLICY)].get((task, method, seed), {})
                final = evaluations[(preset, FINAL_POLICY)].get((task, method, seed), {})
                early = "" if rule is None else int(onset is not None and onset <= rule.by_step)
                rows.append(
                    {
                        "study": study.name,
                        "task": task,
                        "reading": reading,
                        "preset": preset,
                        "method": method,
                        "seed": seed,
                        "onset_step": "" if onset is None else onset,
                        "early": early,
                        "best_success": best.get("success_rate", ""),
                        "best_collision": best.get("collision_rate", ""),
                        "final_success": final.get("success_rate", ""),
                        "final_collision": final.get("collision_rate", ""),
                    }
                )
    return rows


@dataclass(frozen=True)
class RuleVerdict:
    """A control's verdict under its rule: ``early`` of ``runs`` finished runs of the rule's
    task learned early; ``verdict`` is the rule's conclusion, "undecided" or "awaiting"."""

    reading: str
    early: int
    runs: int
    verdict: str

    @property
    def text(self) -> str:
        return f"{self.early} of {self.runs} seeds learn early: {self.verdict}"


def _early_count(
    rows: list[dict[str, Any]], preset: str, method: str, task: str
) -> tuple[int, int]:
    mine = [r for r in rows if (r["preset"], r["method"], r["task"]) == (preset, method, task)]
    return sum(int(r["early"] == 1) for r in mine), len(mine)


def rule_verdict(rows: list[dict[str, Any]], study: Study, preset: str) -> RuleVerdict:
    """The verdict of the control ``preset``'s rule on its runs among ``rows`` (`onset_rows`):
    seeds 0 .. ``rule.seeds`` - 1 only (a further seed, run later, does not change it)."""
    reading = next(r for r in study.readings if r.preset == preset)
    rule = reading.rule
    if rule is None:
        raise ValueError(f"{preset} has no decision rule")
    ruled = [r for r in rows if int(r["seed"]) < rule.seeds]
    early, runs = _early_count(ruled, preset, study.methods[0], rule.task)
    if runs < rule.seeds:
        verdict = f"awaiting ({runs} of {rule.seeds} runs finished)"
    elif early >= rule.at_least:
        verdict = rule.if_early
    elif early <= rule.at_most:
        verdict = rule.if_late
    else:
        verdict = f"undecided at {runs} seeds"
    return RuleVerdict(reading.label, early, runs, verdict)


def _rate(value: Any) -> str:
    return "–" if value in ("", None) else f"{float(value):.2f}"


def _step(value: Any) -> str:
    return "—" if value in ("", None) else f"{int(value):,}".replace(",", " ")


def onset_texts(
    root: str | Path, study: Study, tasks: list[str], preset: str
) -> tuple[str, str] | None:
    """(CSV, Markdown) of the study's onsets beside ``preset``, or None without a finished
    run of any panel."""
    rows = onset_rows(root, study, tasks)
    if not rows:
        return None
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    rule = study_rule(study)
    threshold = rule.threshold if rule else THRESHOLD
    parts = [
        f"When each run learns ({study.name} study, {preset} preset): per method, reading and "
        "seed, "
        f"the first training step after step 0 (the untrained policy) at which the learning "
        f"curve's success (the curve TCs, the deterministic policy of that step) reaches "
        f"{threshold:g} (— never), then the best (final) policy's success on the evaluation "
        "TCs. Rules: `distgprl.report.onsets`."
    ]
    for task in tasks:
        mine = [r for r in rows if r["task"] == task]
        if not mine:
            continue
        seeds = sorted({r["seed"] for r in mine})
        header = ["Run", *[f"seed {s}" for s in seeds], f"reached {threshold:g}"]
        by_step = rule.by_step if rule is not None and rule.task == task else None
        if by_step is not None:
            header.append(f"early (by step {_step(by_step)})")
        panels: dict[tuple[str, str], list[dict[str, Any]]] = {}  # (preset, method): its runs
        for r in mine:
            panels.setdefault((r["preset"], r["method"]), []).append(r)
        table = []
        for (panel_preset, method), runs in panels.items():
            cells = {
                r["seed"]: f"{_step(r['onset_step'])}: {_rate(r['best_success'])} "
                f"({_rate(r['final_success'])})"
                for r in runs
            }
            name = f"{runs[0]['reading']} (`{panel_preset}`)"
            if method in study.methods:
                name = f"{METHODS[method].label.removesuffix(' (ours)')}: {name}"
            line = [
                name,
                *[cells.get(s, "") for s in seeds],
                f"{sum(r['onset_step'] != '' for r in runs)}/{len(runs)}",
            ]
            if by_step is not None:
                line.append(f"{sum(r['early'] == 1 for r in runs)}/{len(runs)}")
            table.append(line)
        parts.append(markdown_table(f"**{task.upper()}**", header, table))
    for reading in study.readings:
        own = reading.rule
        if own is not None:
            verdict = rule_verdict(rows, study, reading.preset)
            parts.append(
                f"**{reading.label}** (its rule, fixed before its first run: on "
                f"{own.task.upper()} a run learns early if its curve reaches "
                f"{own.threshold:g} success after step 0 and by step {_step(own.by_step)}; "
                f"{own.at_least} or more of {own.seeds} → {own.if_early.split(':')[0]}, "
                f"{own.at_most} or fewer → {own.if_late.split(':')[0]}, otherwise "
                f"undecided): **{verdict.text}**"
            )
    return buffer.getvalue(), "\n\n".join(parts) + "\n"
