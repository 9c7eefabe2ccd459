"""Claims per reading: every claim of `distgprl.report.claims` tested under Table I's reading
and each study reading (`study_verdicts`), and judged across them (`across_readings`).
Rules: docs/findings/protocol.md, "The claims per reading"."""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence

import pandas as pd

from distgprl.report import claims
from distgprl.report.aggregate import ALL_TASKS, BOOTSTRAP_SEED, PROPOSED, Scores, tasks_of
from distgprl.report.markdown import csv_text, markdown_table
from distgprl.studies import TABLE_ONE, Reading, Study

# A study reading's verdict on a claim reading a method it acts on without a run under it:
NOT_RUN = "not run under this reading"  # the study trains the method: run it
OUTSIDE = "not tested by this study"  # the study does not train it: no run will come
UNEQUAL_SEEDS = "at unequal seeds"
PENDING = (claims.NO_RUNS, claims.FEW_SEEDS, NOT_RUN)

CSV_FIELDS = ("claim", "reading", "preset", "verdict", "detail")
"""Columns of ``claims_robustness_<preset>.csv``: per claim, a row per reading (its overall
verdict), then with several studies a row per study (reading ``across <study>``: Table I's
reading and that study's), then the verdict across every reading (reading ``across``)."""


def reading_scores(
    reference: Scores, reading_runs: Scores, acts_on: Callable[[str], bool]
) -> tuple[Scores, tuple[str, ...]]:
    """(scores, methods not run) of a study reading: ``reference``'s runs of the methods it
    leaves alone, ``reading_runs`` of those it acts on; not run: acted on, without a run."""
    scores = {key: runs for key, runs in reference.items() if not acts_on(key[1])}
    scores |= {key: runs for key, runs in reading_runs.items() if acts_on(key[1]) and runs}
    have = {method for _, method in scores}
    return scores, tuple(sorted({m for _, m in reference if acts_on(m) and m not in have}))


def reference_reading(studies: Sequence[Study]) -> Reading:
    """Table I's reading shared by ``studies``: the one study's reference, or with several one
    named by every studied constant's Table I value (one reference preset required)."""
    presets = {study.reference.preset for study in studies}
    if len(presets) != 1:
        raise ValueError(f"the studies read different Table I presets: {sorted(presets)}")
    if len(studies) == 1:
        return studies[0].reference
    values = [study.reference.label.removesuffix(TABLE_ONE) for study in studies]
    return Reading(presets.pop(), f"Table I ({'; '.join(values)})")


def _verdicts(
    reference: Scores, runs: Scores, seed: int, reading: Reading, study: Study | None = None
) -> pd.DataFrame:
    """`evaluate_claims`' rows under ``reading`` (``runs`` its study's runs) with ``reading``
    (label), ``preset``, ``study`` ("" for Table I's), ``not_run`` (the methods it acts on
    without a run) and ``seeds`` ((task, Dist-GPRL's seeds) per task); a claim reading a
    method of ``not_run`` keeps its `ALL_TASKS` row alone, `NOT_RUN` or `OUTSIDE`."""
    scores, not_run = reading_scores(reference, runs, study.acted_on) if study else (reference, ())
    seeds = tuple((task, len(scores.get((task, PROPOSED), ()))) for task in tasks_of(scores))
    name = study.name if study else ""
    needs = {claim: methods for claim, _, _, methods in claims.CLAIMS}
    rows = []
    for row in claims.records(claims.evaluate_claims(scores, seed)):
        row |= dict(reading=reading.label, preset=reading.preset, study=name)
        row |= dict(not_run=not_run, seeds=seeds)
        lacking = [m for m in needs[row["claim"]] if m in not_run]
        if study and lacking:
            if row["task"] != ALL_TASKS:
                continue  # no estimate per task of a claim reading a method without a run
            outside = [m for m in lacking if m not in study.methods]
            detail = f"{claims.labels(lacking)} under {reading.preset}: the reading changes it"
            trains = f", and the {name} study trains {claims.labels(study.methods)} only"
            detail += f"{trains} (not {claims.labels(outside)})" if outside else "; run it"
            row |= {"estimate": None, "verdict": OUTSIDE if outside else NOT_RUN, "detail": detail}
        rows.append(row)
    return pd.DataFrame(rows)


def study_verdicts(
    studies: Sequence[Study],
    reference: Scores,
    runs_of: Callable[[str], Scores],
    seed: int = BOOTSTRAP_SEED,
) -> pd.DataFrame:
    """`_verdicts` under the reference reading (first), then under each of ``studies``' claim
    readings; ``runs_of(preset)`` gives a study preset's scores."""
    if not studies:
        raise ValueError("no study to read")
    frames = [_verdicts(reference, {}, seed, reference_reading(studies))]
    for study in studies:
        for reading in study.claim_readings:
            frames.append(_verdicts(reference, runs_of(reading.preset), seed, reading, study))
    return pd.concat(frames, ignore_index=True)


def across_readings(
    verdicts: Sequence[tuple[str, str]], seeds: Mapping[str, Hashable] | None = None
) -> str:
    """The verdict across readings from (reading label, verdict) pairs (protocol); with
    ``seeds`` (label: its run counts) a decided verdict over unequal counts says so."""
    untested = [label for label, v in verdicts if v == OUTSIDE]
    tested = [(label, v) for label, v in verdicts if v != OUTSIDE]
    decided = [(label, v) for label, v in tested if v not in PENDING]
    pending = [label for label, v in tested if v in PENDING]
    distinct = list(dict.fromkeys(v for _, v in decided))
    unequal = seeds is not None and len({seeds[label] for label, _ in decided}) > 1
    tail = f"; untested: {', '.join(untested)}" if untested else ""
    caveat = f"; {UNEQUAL_SEEDS}" if unequal else ""
    if len(distinct) > 1:
        groups = [f"{v} under {', '.join(lab for lab, w in decided if w == v)}" for v in distinct]
        return "reading-dependent: " + "; ".join(groups) + tail + caveat
    if pending:
        so_far = (
            f"{distinct[0]} under {len(decided)} of {len(tested)} readings; " if decided else ""
        )
        return f"incomplete: {so_far}awaiting {', '.join(pending)}{tail}"
    if untested:
        every = f"every reading that tests it ({len(tested)} of {len(verdicts)}{tail})"
        return f"{distinct[0]} under {every}{caveat}"
    return f"{distinct[0]} under every reading{caveat}"


def robustness_texts(results: pd.DataFrame, preset: str) -> tuple[str, str]:
    """(CSV, Markdown) of the claims per reading (`study_verdicts`): a column per reading, then
    with several studies one per study, the verdict across them all last."""
    results = results[results.task == ALL_TASKS]
    studies = list(dict.fromkeys(s for s in results.study if s))
    per_study = len(studies) > 1
    groups = [(f"across {s}", ("", s)) for s in studies if per_study]
    groups.append(("across", ("", *studies)))
    readings = claims.records(results.drop_duplicates("reading"))
    seeds = {r["reading"]: r["seeds"] for r in readings}
    csv_rows: list[claims.Row] = []
    rows = []
    for _, group in results.groupby("claim", sort=False):
        own = claims.records(group)
        claim = own[0]["claim"]
        across = {
            label: across_readings(
                [(r["reading"], r["verdict"]) for r in own if r["study"] in names], seeds
            )
            for label, names in groups
        }
        csv_rows += own
        csv_rows += [
            dict(claim=claim, reading=label, verdict=text) for label, text in across.items()
        ]
        *each, overall = across.values()
        rows.append([claim, *(r["verdict"] for r in own), *each, f"**{overall}**"])
    header = ["Claim", *(f"{r['reading']} (`{r['preset']}`)" for r in readings)]
    header += [f"Across Table I and the {name} study" for name in studies if per_study]
    intro = (
        f"Claims per reading ({preset} preset beside its studies): each claim's overall "
        "verdict (`distgprl.report.claims`) under Table I's readings and under each study "
        "reading, where a study reading replaces the methods it acts on (the operator's: "
        "those with the covariance transform) by their runs under its preset and keeps the "
        "other methods' Table I runs. A claim counts as "
        "reproduced only where it is reproduced under every reading; a verdict that changes "
        "with the reading is reading-dependent (rules: `distgprl.report.robustness`)."
    )
    if per_study:
        intro += (
            " With several studies, each study's column judges Table I's reading and that "
            "study's readings alone (one study's runs can be complete while another's wait); "
            "the last column judges them all."
        )
    markdown = markdown_table(intro, [*header, "Across readings"], rows)
    tasks = " / ".join(task.upper() for task, _ in readings[0]["seeds"])
    counts = "; ".join(
        f"{r['reading']} {' / '.join(str(n) for _, n in r['seeds'])}" for r in readings
    )
    markdown += (
        f"\nSeeds of Dist-GPRL per reading ({tasks}): {counts}. A verdict "
        f"across readings ending '{UNEQUAL_SEEDS}' compares readings with different "
        "numbers of runs; fewer seeds widen a reading's intervals, so a reading-dependent "
        "verdict there may be the seed count's.\n"
    )
    missing = [f"{r['reading']}: {claims.labels(r['not_run'])}" for r in readings if r["not_run"]]
    if missing:
        markdown += (
            "\nMethods a reading acts on without runs under it (the claims reading them are "
            f"'{NOT_RUN}' there while the study trains them, '{OUTSIDE}' where it does "
            "not): " + "; ".join(missing) + ".\n"
        )
    return csv_text(csv_rows, CSV_FIELDS), markdown
