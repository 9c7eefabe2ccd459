"""When each run learns: per study read beside a preset (`distgprl.studies`), every panel of
`onset_panels` (method × reading), task and seed, the learning-curve onset (`onset_step`; why
step 0 does not count: docs/findings/operator.md, "Decision rule"), whether it is ``early``
(at or before the `distgprl.studies.OnsetRule`'s ``by_step``) and the best and final policies'
evaluation success and collision; then each rule's verdict (`rule_verdict`). `distgprl tables`
writes ``onsets_<study>_<preset>.{csv,md}``.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import groupby
from pathlib import Path
from typing import Any

from distgprl.methods import TABLE_ORDER
from distgprl.report.aggregate import short_label
from distgprl.report.frame import curve_frame, run_frame, summaries
from distgprl.report.markdown import csv_text, markdown_table
from distgprl.report.seed_curves import reading_columns, run_curves
from distgprl.studies import OnsetRule, Study

THRESHOLD = 0.5
"""Curve success that counts as learned for a study without a control rule."""

CSV_FIELDS = list(
    "study task reading preset method seed onset_step early best_success best_collision "
    "final_success final_collision".split()
)


def onset_step(steps: Any, success: Any, threshold: float) -> int | None:
    """The first of ``steps`` (k,) after step 0 (the untrained policy) whose ``success`` (k,)
    is at least ``threshold``; None if none is."""
    pairs = zip(steps, success, strict=True)
    return next((int(s) for s, v in pairs if int(s) > 0 and float(v) >= threshold), None)


def study_rule(study: Study) -> OnsetRule | None:
    """The study's first decision rule (its threshold and ``by_step`` are every rule's:
    `Study` checks), or None."""
    return next((rule for _, rule in study.rules), None)


def onset_panels(study: Study) -> list[tuple[str, str, str]]:
    """(preset, method, reading label) per table row: each of the study's methods (Table I's
    order) under each reading, the reference's first; an operator study adds NoCov from the
    reference preset (`distgprl.report.seed_curves.reading_columns`' last panel)."""
    methods = [m for m in TABLE_ORDER if m in study.methods]
    panels = [(r.preset, m, r.label) for m in methods for r in study.all_readings]
    extra = [(p, m, title) for p, m, title in reading_columns(study) if m not in study.methods]
    return panels + extra


def run_label(study: Study, method: str, reading: str) -> str:
    """A table row's or figure row's name for ``method`` under ``reading`` (a row's
    ``reading``): "Dist-GPRL: correlation only"; a method the study does not train (an
    operator study's NoCov) by its reading label alone, which names it."""
    if method in study.methods:
        return f"{short_label(method)}: {reading}"
    return reading


def onset_threshold(study: Study) -> float:
    """The success that counts as learned: the study's rule's, else `THRESHOLD`."""
    rule = study_rule(study)
    return rule.threshold if rule else THRESHOLD


def onset_rows(root: str | Path, study: Study, tasks: list[str]) -> list[dict[str, Any]]:
    """One row per `onset_panels` panel, task and finished seed (CSV_FIELDS), panels in
    their order; the threshold and ``early`` from `study_rule` (``early`` empty without)."""
    rule, threshold = study_rule(study), onset_threshold(study)
    presets = dict.fromkeys(preset for preset, _, _ in onset_panels(study))
    curves = {preset: curve_frame(root, preset) for preset in presets}
    results = {
        (preset, policy): {
            key[:3]: summary for key, summary in summaries(run_frame(root, preset, policy))
        }
        for preset in presets
        for policy in ("best", "final")
    }
    rows = []
    for preset, method, reading in onset_panels(study):
        for task in tasks:
            for seed, (steps, values) in run_curves(curves[preset], task, method).items():
                onset = onset_step(steps, values["success_rate"], threshold)
                early = "" if rule is None else int(onset is not None and onset <= rule.by_step)
                keys = {"study": study.name, "task": task, "reading": reading, "preset": preset}
                row: dict[str, Any] = keys | {"method": method, "seed": seed, "early": early}
                row["onset_step"] = "" if onset is None else onset
                for policy in ("best", "final"):
                    summary = results[(preset, policy)].get((task, method, seed), {})
                    row[f"{policy}_success"] = summary.get("success_rate", "")
                    row[f"{policy}_collision"] = summary.get("collision_rate", "")
                rows.append(row)
    return rows


@dataclass(frozen=True)
class RuleVerdict:
    """A rule's verdict: ``early`` of ``runs`` finished runs at the rule's seeds of its
    reading and task learned early; ``verdict`` is the rule's conclusion, "awaiting", or
    "void" where the rule it needs (`OnsetRule.given`) did not give its ``if_early``."""

    early: int
    runs: int
    verdict: str


def _early_count(
    rows: list[dict[str, Any]], preset: str, method: str, task: str
) -> tuple[int, int]:
    mine = [r for r in rows if (r["preset"], r["method"], r["task"]) == (preset, method, task)]
    return sum(int(r["early"] == 1) for r in mine), len(mine)


def rule_verdict(rows: list[dict[str, Any]], study: Study, name: str) -> RuleVerdict:
    """The verdict of the study's rule ``name`` on its reading's runs among ``rows``
    (`onset_rows`) at the rule's seeds only (a run at another seed does not change it)."""
    reading, rule = study.rule(name)
    ruled = [r for r in rows if int(r["seed"]) in rule.seeds]
    early, runs = _early_count(ruled, reading.preset, study.methods[0], rule.task)
    needed = len(rule.seeds)
    if runs < needed:
        verdict = f"awaiting ({runs} of {needed} runs finished)"
    elif early >= rule.at_least:
        verdict = rule.if_early
    elif early <= rule.at_most:
        verdict = rule.if_late
    else:
        verdict = rule.if_between or f"undecided at {runs} seeds"
    if rule.given:
        _, given = study.rule(rule.given)
        before = rule_verdict(rows, study, rule.given).verdict
        if before.startswith("awaiting"):
            verdict = f"awaiting ({runs} of {needed} runs finished; {rule.given}: {before})"
        elif before != given.if_early:
            verdict = f"void: {rule.given} gave {_short(before)}"
    return RuleVerdict(early, runs, verdict)


def _short(conclusion: str) -> str:
    """A conclusion's name: its text before the first colon."""
    return conclusion.split(":")[0]


def _rate(value: Any) -> str:
    return "–" if value in ("", None) else f"{float(value):.2f}"


def _run_cell(row: dict[str, Any]) -> str:
    """A run's table cell: "onset step: best (final) success"."""
    best, final = _rate(row["best_success"]), _rate(row["final_success"])
    return f"{step_text(row['onset_step'])}: {best} ({final})"


def step_text(value: Any) -> str:
    """A training step as the onset tables and figure write it (``4 500``; "—" for none)."""
    return "—" if value in ("", None) else f"{int(value):,}".replace(",", " ")


def seeds_text(seeds: tuple[int, ...]) -> str:
    """``seeds`` as "0–4" where they are a run of consecutive integers, else listed."""
    if len(seeds) > 2 and list(seeds) == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}–{seeds[-1]}"
    return ", ".join(str(seed) for seed in seeds)


def _onset_table(
    title: str, rows: list[dict[str, Any]], study: Study, threshold: float, by_step: int | None
) -> str:
    """A Markdown table of ``rows`` (one task's): a line per (preset, method) panel in the
    rows' order, a column per seed (onset: best (final) success), how many reached
    ``threshold`` and, with ``by_step``, how many learned early."""
    seeds = sorted({r["seed"] for r in rows})
    header = ["Run", *[f"seed {s}" for s in seeds], f"reached {threshold:g}"]
    header += [] if by_step is None else [f"early (by step {step_text(by_step)})"]
    table = []
    for (preset, method), group in groupby(rows, key=lambda r: (r["preset"], r["method"])):
        runs = {r["seed"]: r for r in group}
        cells = [_run_cell(runs[seed]) if seed in runs else "" for seed in seeds]
        reached = sum(r["onset_step"] != "" for r in runs.values())
        label = run_label(study, method, next(iter(runs.values()))["reading"])
        line = [f"{label} (`{preset}`)", *cells, f"{reached}/{len(runs)}"]
        if by_step is not None:
            line.append(f"{sum(r['early'] == 1 for r in runs.values())}/{len(runs)}")
        table.append(line)
    return markdown_table(title, header, table)


def onset_texts(
    root: str | Path, study: Study, tasks: list[str], preset: str
) -> tuple[str, str] | None:
    """(CSV, Markdown) of the study's onsets beside ``preset``, or None without a finished
    run of any panel. The CSV has every finished seed; the Markdown's tables the study's seeds
    (`Study.seeds`) and, apart, the seeds only a rule reads; then each rule's verdict and, per
    reading with rules, its early count over all its finished seeds (decides nothing)."""
    rows = onset_rows(root, study, tasks)
    if not rows:
        return None
    rule, threshold = study_rule(study), onset_threshold(study)
    parts = [
        f"When each run learns ({study.name} study, {preset} preset): per method, reading and "
        "seed, "
        f"the first training step after step 0 (the untrained policy) at which the learning "
        f"curve's success (the curve TCs, the deterministic policy of that step) reaches "
        f"{threshold:g} (— never), then the best (final) policy's success on the evaluation "
        "TCs. Rules: `distgprl.report.onsets`."
    ]
    rule_tasks = {r.task for _, r in study.rules}
    for task in tasks:
        by_step = rule.by_step if rule is not None and task in rule_tasks else None
        beyond = (
            f"**{task.upper()}, seeds beyond the study's {seeds_text(study.seeds)}** (no "
            "table, figure or verdict across readings reads them; the rules below name "
            "their seeds)"
        )
        for title, inside in ((f"**{task.upper()}**", True), (beyond, False)):
            mine = [r for r in rows if r["task"] == task and (r["seed"] in study.seeds) == inside]
            if mine:
                parts.append(_onset_table(title, mine, study, threshold, by_step))
    for reading, own in study.rules:
        result = rule_verdict(rows, study, own.name)
        middle = ""
        if own.at_least - own.at_most > 1:  # a count between the two is possible
            middle = f", otherwise {_short(own.if_between) if own.if_between else 'undecided'}"
        needs = ""
        if own.given:
            needs = f"; needs {own.given} to give {_short(study.rule(own.given)[1].if_early)}"
        parts.append(
            f"**{reading.label}, {own.name}** (its rule, fixed before its first run: on "
            f"{own.task.upper()} seeds {seeds_text(own.seeds)} a run learns early if its "
            f"curve reaches {own.threshold:g} success after step 0 and by step "
            f"{step_text(own.by_step)}; {own.at_least} or more of {len(own.seeds)} → "
            f"{_short(own.if_early)}, {own.at_most} or fewer → {_short(own.if_late)}{middle}"
            f"{needs}): **{result.early} of {result.runs} seeds learn early: {result.verdict}**"
        )
    for reading in study.readings:
        for task in sorted({own.task for own in reading.rules}):
            early, runs = _early_count(rows, reading.preset, study.methods[0], task)
            parts.append(
                f"{reading.label}, every finished seed on {task.upper()} (descriptive; no rule "
                f"reads this count): {early} of {runs} learn early."
            )
    return csv_text(rows, CSV_FIELDS), "\n\n".join(parts) + "\n"
