"""Claims per reading: every claim of `distgprl.report.claims` tested under Table I's reading
and each study reading (`study_verdicts`), and judged across them (`across_readings`).

Rules: docs/findings/protocol.md, "The claims per reading". Written as
``claims_robustness_<preset>.csv`` (`CSV_FIELDS`) and ``.md`` by `robustness_texts`.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass, replace

from distgprl.report.aggregate import BOOTSTRAP_SEED, PROPOSED, Scores, tasks_of
from distgprl.report.claims import FEW_SEEDS, NO_RUNS, Verdict, evaluate_claims, labels
from distgprl.report.markdown import csv_text, markdown_table
from distgprl.studies import TABLE_ONE, Reading, Study

# A study reading's verdict on a claim reading a method it acts on without a run under it:
NOT_RUN = "not run under this reading"  # the study trains the method: run it
OUTSIDE = "not tested by this study"  # the study does not train it: no run will come
UNEQUAL_SEEDS = "at unequal seeds"
PENDING = (NO_RUNS, FEW_SEEDS, NOT_RUN)

CSV_FIELDS = ("claim", "reading", "preset", "verdict", "detail")
"""Columns of ``claims_robustness_<preset>.csv``: per claim, a row per reading (its overall
verdict), then with several studies a row per study (reading ``across <study>``: Table I's
reading and that study's), then the verdict across every reading (reading ``across``)."""


@dataclass(frozen=True)
class ReadingVerdicts:
    """Every claim's verdict under one reading, the methods it acts on without a run under it
    (sorted), its study's name ("" for Table I's) and (task, Dist-GPRL's seeds) per task."""

    reading: Reading
    verdicts: tuple[Verdict, ...]
    not_run: tuple[str, ...]
    study: str = ""
    seeds: tuple[tuple[str, int], ...] = ()


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


def _not_run(verdict: Verdict, study: Study, reading: Reading, not_run: tuple[str, ...]) -> Verdict:
    """``verdict``, or where its test reads a method of ``not_run``, `NOT_RUN` (the study
    trains that method) or `OUTSIDE` (it does not), naming the methods."""
    lacking = [m for m in verdict.needs if m in not_run]
    if not lacking:
        return verdict
    outside = [m for m in lacking if m not in study.methods]
    detail = f"{labels(lacking)} under {reading.preset}: the reading changes it"
    if outside:
        trained = labels(study.methods)
        detail += f", and the {study.name} study trains {trained} only (not {labels(outside)})"
    else:
        detail += "; run it"
    word = OUTSIDE if outside else NOT_RUN
    return replace(verdict, per_task=(), pooled=None, verdict=word, detail=detail)


def study_verdicts(
    studies: Sequence[Study],
    reference: Scores,
    runs_of: Callable[[str], Scores],
    seed: int = BOOTSTRAP_SEED,
) -> list[ReadingVerdicts]:
    """Every claim under the reference reading (first), then under each of ``studies``'
    claim readings; ``runs_of(preset)`` gives a study preset's scores."""
    if not studies:
        raise ValueError("no study to read")
    tasks = tasks_of(reference)

    def seeds(scores: Scores) -> tuple[tuple[str, int], ...]:
        return tuple((task, len(scores.get((task, PROPOSED), ()))) for task in tasks)

    verdicts = tuple(evaluate_claims(reference, seed))
    out = [ReadingVerdicts(reference_reading(studies), verdicts, (), seeds=seeds(reference))]
    for study in studies:
        for reading in study.claim_readings:
            scores, not_run = reading_scores(reference, runs_of(reading.preset), study.acted_on)
            claims = evaluate_claims(scores, seed)
            verdicts = tuple(_not_run(v, study, reading, not_run) for v in claims)
            out.append(ReadingVerdicts(reading, verdicts, not_run, study.name, seeds(scores)))
    return out


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


def robustness_texts(results: Sequence[ReadingVerdicts], preset: str) -> tuple[str, str]:
    """(CSV, Markdown) of the claims per reading: a column per reading, then with several
    studies one per study, the verdict across them all last."""
    studies = list(dict.fromkeys(r.study for r in results if r.study))
    per_study = len(studies) > 1
    groups = [(f"across {s}", [r for r in results if r.study in ("", s)]) for s in studies]
    groups = [*(groups if per_study else []), ("across", list(results))]
    seeds = {r.reading.label: r.seeds for r in results}
    csv_rows: list[dict[str, str]] = []
    rows = []
    for index, claim in enumerate(v.claim for v in results[0].verdicts):
        own = [(r.reading, r.verdicts[index]) for r in results]
        csv_rows += [
            dict(claim=claim, reading=r.label, preset=r.preset, verdict=v.verdict, detail=v.detail)
            for r, v in own
        ]
        across = {
            label: across_readings(
                [(r.reading.label, r.verdicts[index].verdict) for r in group], seeds
            )
            for label, group in groups
        }
        csv_rows += [
            dict(claim=claim, reading=label, verdict=text) for label, text in across.items()
        ]
        *each, overall = across.values()
        rows.append([claim, *(v.verdict for _, v in own), *each, f"**{overall}**"])
    header = ["Claim", *(f"{r.reading.label} (`{r.reading.preset}`)" for r in results)]
    header += [f"Across Table I and the {name} study" for name in studies if per_study]
    intro = (
        f"Claims per reading ({preset} preset beside its studies): each claim's overall "
        "verdict (`distgprl.report.claims`) under Table I's readings and under each study "
        "reading, where a study reading replaces the methods it acts on (the operator: those "
        "with the covariance transform; the unit of r_tc: every trained method) by their runs "
        "under its preset and keeps the other methods' Table I runs. A claim counts as "
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
    if any(r.seeds for r in results):
        tasks = " / ".join(task.upper() for task, _ in results[0].seeds)
        counts = "; ".join(
            f"{r.reading.label} {' / '.join(str(n) for _, n in r.seeds)}" for r in results
        )
        markdown += (
            f"\nSeeds of Dist-GPRL per reading ({tasks}): {counts}. A verdict "
            f"across readings ending '{UNEQUAL_SEEDS}' compares readings with different "
            "numbers of runs; fewer seeds widen a reading's intervals, so a reading-dependent "
            "verdict there may be the seed count's.\n"
        )
    missing = [f"{r.reading.label}: {labels(r.not_run)}" for r in results if r.not_run]
    if missing:
        markdown += (
            "\nMethods a reading acts on without runs under it (the claims reading them are "
            f"'{NOT_RUN}' there while the study trains them, '{OUTSIDE}' where it does "
            "not): " + "; ".join(missing) + ".\n"
        )
    return csv_text(csv_rows, CSV_FIELDS), markdown
