"""When each run learns (``onsets_<study>_<preset>.{csv,md}``): a `CSV_FIELDS` row per panel,
task and finished seed, and each rule's verdict (docs/findings/operator.md, "Decision rule")."""

from __future__ import annotations

from itertools import groupby
from pathlib import Path
from typing import Any

from distgprl.methods import TABLE_ORDER
from distgprl.report.aggregate import short_label
from distgprl.report.frame import curve_frame, run_frame, summaries
from distgprl.report.markdown import csv_text, markdown_table, number_text
from distgprl.report.seed_curves import reading_columns, run_curves
from distgprl.studies import OnsetRule, Study

CSV_FIELDS = (
    "study task reading preset method seed onset_step early best_success best_collision "
    "final_success final_collision"
).split()
"""``onset_step``: `onset_step` (empty: never); ``early``: 1 if at or before the rule's
``by_step`` (empty without a rule); best and final: the evaluation's success and collision."""


def onset_step(steps: Any, success: Any, threshold: float) -> int | None:
    """The first of ``steps`` (k,) after step 0 (the untrained policy) whose ``success`` (k,)
    is at least ``threshold``; None if none is."""
    pairs = zip(steps, success, strict=True)
    return next((int(s) for s, v in pairs if int(s) > 0 and float(v) >= threshold), None)


def study_rule(study: Study) -> tuple[OnsetRule | None, float]:
    """The study's first rule (whose threshold and ``by_step`` are every rule's) or None, and
    the curve success that counts as learned (0.5 without a rule)."""
    rule = next((rule for _, rule in study.rules), None)
    return rule, rule.threshold if rule else 0.5


def onset_panels(study: Study) -> list[tuple[str, str, str]]:
    """(preset, method, reading label) per table row: each study method (Table I's order)
    under each reading, the reference's first, then NoCov for an operator study."""
    methods = [m for m in TABLE_ORDER if m in study.methods]
    panels = [(r.preset, m, r.label) for m in methods for r in study.all_readings]
    extra = [(p, m, title) for p, m, title in reading_columns(study) if m not in study.methods]
    return panels + extra


def run_label(study: Study, method: str, reading: str) -> str:
    """A row's name, "Dist-GPRL: correlation only"; NoCov (not a study method) by its label."""
    return f"{short_label(method)}: {reading}" if method in study.methods else reading


def onset_rows(root: str | Path, study: Study, tasks: list[str]) -> list[dict[str, Any]]:
    """One `CSV_FIELDS` row per `onset_panels` panel, task and finished seed, in that order."""
    rule, threshold = study_rule(study)
    panels = onset_panels(study)
    presets = dict.fromkeys(preset for preset, _, _ in panels)
    curves = {preset: curve_frame(root, preset) for preset in presets}
    results = {
        (preset, *key): summary
        for preset in presets
        for policy in ("best", "final")
        for key, summary in summaries(run_frame(root, preset, policy))
    }
    rows = []
    for preset, method, reading in panels:
        for task in tasks:
            for seed, (steps, values) in run_curves(curves[preset], task, method).items():
                onset = onset_step(steps, values["success_rate"], threshold)
                early = "" if rule is None else int(onset is not None and onset <= rule.by_step)
                keys = {"study": study.name, "task": task, "reading": reading, "preset": preset}
                row: dict[str, Any] = keys | {"method": method, "seed": seed, "early": early}
                row["onset_step"] = "" if onset is None else onset
                for policy in ("best", "final"):
                    summary = results.get((preset, task, method, seed, policy), {})
                    row[f"{policy}_success"] = summary.get("success_rate", "")
                    row[f"{policy}_collision"] = summary.get("collision_rate", "")
                rows.append(row)
    return rows


def _early_count(rows: list[dict[str, Any]], *panel: str) -> tuple[int, int]:
    """(early, runs) among ``rows`` of ``panel`` = (preset, method, task)."""
    mine = [r for r in rows if (r["preset"], r["method"], r["task"]) == panel]
    return sum(int(r["early"] == 1) for r in mine), len(mine)


def rule_verdict(rows: list[dict[str, Any]], study: Study, name: str) -> tuple[int, int, str]:
    """(early, runs, verdict) of the study's rule ``name`` on `onset_rows` at its seeds: the
    rule's conclusion, "awaiting", or "void" where its ``given`` rule did not give ``if_early``."""
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
        before = rule_verdict(rows, study, rule.given)[2]
        if before.startswith("awaiting"):
            verdict = f"awaiting ({runs} of {needed} runs finished; {rule.given}: {before})"
        elif before != study.rule(rule.given)[1].if_early:
            verdict = f"void: {rule.given} gave {_short(before)}"
    return early, runs, verdict


def _short(conclusion: str) -> str:
    return conclusion.split(":")[0]


def step_text(value: Any) -> str:
    """A training step as ``4 500``; "—" for none."""
    return "—" if value in ("", None) else f"{int(value):,}".replace(",", " ")


def seeds_text(seeds: tuple[int, ...]) -> str:
    """``seeds`` as "0–4" where they are a run of consecutive integers, else listed."""
    if len(seeds) > 2 and list(seeds) == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}–{seeds[-1]}"
    return ", ".join(str(seed) for seed in seeds)


def _run_cell(row: dict[str, Any]) -> str:
    """A run's table cell: "onset step: best (final) success"."""
    best, final = (number_text(row[f"{policy}_success"], 2) for policy in ("best", "final"))
    return f"{step_text(row['onset_step'])}: {best} ({final})"


def _onset_table(title: str, rows: list[dict[str, Any]], study: Study, by_step: int | None) -> str:
    """One task's ``rows`` as a table: a line per panel, a cell per seed ("onset: best (final)
    success"), how many reached the threshold and, with ``by_step``, how many learned early."""
    seeds = sorted({r["seed"] for r in rows})
    header = ["Run", *[f"seed {s}" for s in seeds], f"reached {study_rule(study)[1]:g}"]
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


def _rule_text(rows: list[dict[str, Any]], study: Study, name: str) -> str:
    """A rule's paragraph: the rule as fixed before its first run, then its verdict."""
    reading, rule = study.rule(name)
    early, runs, verdict = rule_verdict(rows, study, name)
    middle = needs = ""
    if rule.at_least - rule.at_most > 1:  # a count between the two is possible
        middle = f", otherwise {_short(rule.if_between) if rule.if_between else 'undecided'}"
    if rule.given:
        needs = f"; needs {rule.given} to give {_short(study.rule(rule.given)[1].if_early)}"
    return (
        f"**{reading.label}, {name}** (its rule, fixed before its first run: on "
        f"{rule.task.upper()} seeds {seeds_text(rule.seeds)} a run learns early if its "
        f"curve reaches {rule.threshold:g} success after step 0 and by step "
        f"{step_text(rule.by_step)}; {rule.at_least} or more of {len(rule.seeds)} → "
        f"{_short(rule.if_early)}, {rule.at_most} or fewer → {_short(rule.if_late)}{middle}"
        f"{needs}): **{early} of {runs} seeds learn early: {verdict}**"
    )


def onset_texts(
    root: str | Path, study: Study, tasks: list[str], preset: str
) -> tuple[str, str] | None:
    """(CSV of every finished seed, Markdown) of the study's onsets beside ``preset``, or None
    without a finished run. Per task a table of the study's seeds and one of a rule's further
    seeds, then each rule's verdict and each ruled reading's early count over all its seeds."""
    rows = onset_rows(root, study, tasks)
    if not rows:
        return None
    rule, threshold = study_rule(study)
    parts = [
        f"When each run learns ({study.name} study, {preset} preset): per method, reading and "
        "seed, the first training step after step 0 (the untrained policy) at which the "
        "learning curve's success (the curve TCs, the deterministic policy of that step) "
        f"reaches {threshold:g} (— never), then the best (final) policy's success on the "
        "evaluation TCs. Rules: `distgprl.report.onsets`."
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
                parts.append(_onset_table(title, mine, study, by_step))
    parts += [_rule_text(rows, study, own.name) for _, own in study.rules]
    for reading in study.readings:
        for task in sorted({own.task for own in reading.rules}):
            early, runs = _early_count(rows, reading.preset, study.methods[0], task)
            parts.append(
                f"{reading.label}, every finished seed on {task.upper()} (descriptive; no rule "
                f"reads this count): {early} of {runs} learn early."
            )
    return csv_text(rows, CSV_FIELDS), "\n\n".join(parts) + "\n"
