"""The documentation site's generated pages, made at build time (mkdocs-gen-files runs this
file as a script during ``make docs``), so that none of them can go stale:

- the **results pages**: the first screen of ``results/index.md`` (`results_summary`: Table I
  in brief, the learning curves, each claim's verdict with the number that decides it, from
  the committed CSVs of ``paper_figures/`` and the archived environment's), every table and
  figure ``make tables`` committed under ``paper_figures/`` (``results/tables.md``) and the
  archived environment's (``results/env-v7.md``), copied in at build time — the reference
  presets' outputs only (`is_published`: never a ``*_ci.*`` file);
- the **benchmarks page**: the committed ``results/bench/bench_full.json`` as the tables
  `distgprl.experiments.bench.markdown.markdown_table` makes of it;
- the **configuration reference**: every field of the frozen dataclasses of
  ``distgprl/config_types.py`` with its type, default and documented meaning and unit, and
  the shipped presets' YAML files;
- the **result schema**'s column lists (``distgprl/schema.py``) with their documentation;
- the **Python API pages** (``reference/api/*.md``): one mkdocstrings block per module of
  each subpackage, found on disk, so a new module appears without editing a page;
- the **changelog** (``CHANGELOG.md``).

A hand-written page under ``docs/`` asks for generated content with a line
``<!-- generated: NAME -->`` (NAME a key of `GENERATORS`); the build replaces the line.
The functions return Markdown and import nothing heavy (no torch, pybullet), so the tests
(``tests/test_docs.py``) call them directly.
"""

from __future__ import annotations

import ast
import csv
import dataclasses
import html
import importlib.util
import inspect
import json
import logging
import re
import shutil
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPOSITORY = Path(__file__).resolve().parents[1]
DOCS = REPOSITORY / "docs"
PACKAGE = REPOSITORY / "distgprl"
FIGURES = REPOSITORY / "paper_figures"
RESULTS = REPOSITORY / "results"
BENCH = RESULTS / "bench"
ARCHIVE = RESULTS / "archive" / "env-v7"
"""The archived environment's results (v7: Table I at five seeds and its studies, complete)."""
ARCHIVE_FIGURES = ARCHIVE / "paper_figures"
ARCHIVE_VERSION = 7

if str(REPOSITORY) not in sys.path:  # mkdocs runs this file with its own sys.path
    sys.path.insert(0, str(REPOSITORY))

MARKER = re.compile(r"^<!-- generated: ([a-z0-9-]+) -->$", re.MULTILINE)
"""The line a hand-written page puts where a generator's Markdown goes."""

FIGURE_DIR = "results/figures"
"""Where the site holds the copied figures (``paper_figures/*.png``, the benchmark figure)."""
FIGURE_SITE_FOLDER = "figures"
"""`FIGURE_DIR` relative to the results pages (``results/*.md``)."""
ARCHIVE_FIGURE_DIR = f"{FIGURE_DIR}/env-v7"
"""Where the site holds the archived environment's figures."""

LOG = logging.getLogger("mkdocs.plugins.docs_pages")

# -- the results page -------------------------------------------------------------------------

RESULT_TABLES: tuple[tuple[str, str], ...] = (
    ("table1_paper.md", "Table I"),
    ("table1_final_paper.md", "Table I of the final policy"),
    ("table1_paper_per_seed.md", "Table I per run"),
    ("table1_final_paper_per_seed.md", "Table I of the final policy, per run"),
    ("one_demo_study_paper.md", "Beside Table I: ProMP-RRL on one demonstration (a study)"),
    ("aggregates_paper.md", "Aggregates over seeds (IQM)"),
    ("table1_repair_paper.md", "Table I + repair: the safety layer in the loop"),
    ("table2_paper.md", "Table II: hardware trials (digital twin)"),
    ("table2_best_paper.md", "Beside Table II: the trials of Table I's policies (the best)"),
    ("table2_noise_paper.md", "The twin's robustness to perception error"),
    ("claims_paper.md", "The claims"),
    ("claims_robustness_paper.md", "The claims per reading (the operator study)"),
    ("onsets_operators_paper.md", "When each run learns: the operator study and its control"),
    ("mechanisms_paper.md", "The mechanism table"),
    ("paired_vs_demo_paper.md", "Every run against the unadapted demonstration, TC by TC"),
    ("paired_vs_dist-gprl_paper.md", "Every run against Dist-GPRL of the same seed, TC by TC"),
    ("paired_best_vs_final_paper.md", "Best against final policy, TC by TC"),
)
"""The results page's tables, in its order: (file under paper_figures/, heading). A Markdown
table of ``paper_figures/`` not listed here still appears, under "Other tables"."""

RESULT_FIGURES: tuple[tuple[str, str], ...] = (
    ("all_methods_paper.png", "Learning curves of every method (on the curve TCs)"),
    ("hap_effect_paper.png", "The HAP prior's effect: Dist-GPRL against GPRL-D"),
    ("covariance_effect_paper.png", "The covariance transform's effect: Dist-GPRL against NoCov"),
    ("table2_noise_paper.png", "Twin success and collision against the perception error"),
    ("sensitivity_operators_paper.png", "The operator study: Dist-GPRL per reading of S"),
    ("curves_operators_paper.png", "The operator study: learning curves per reading, seed by seed"),
    ("onsets_operators_paper.png", "The operator study: when each run first reaches 0.5 success"),
    ("rollout_dcp.gif", "A DCP rollout: Dist-GPRL's Table I policy (left) beside the demo"),
    ("rollout_dbm.gif", "A DBM rollout: the TC-conditioned demonstration"),
    ("dcp_scene.png", "The DCP scene"),
    ("dbm_scene.png", "The DBM scene"),
)
"""The results page's figures, in its order; other PNGs of ``paper_figures/`` follow."""


def site_table(table: str) -> str:
    """A committed Markdown table as the site shows it: every bracket pair that is no inline
    link escaped, so that "0.86 [0.61, 1.00] [2]" (an interval, then the seeds) stays text
    and is not read as a reference link to "2" (which strict mode would refuse)."""
    return re.sub(r"\[([^\[\]]*)\](?!\()", r"\\[\1\\]", table.strip())


def _demote(table: str) -> str:
    """A committed Markdown table as a section body (its caption line kept as a paragraph)."""
    return site_table(table) + "\n"


def _source(figures: Path) -> str:
    """``figures`` as the repository path a page names (``paper_figures``, ...)."""
    return figures.relative_to(REPOSITORY).as_posix() if figures.is_relative_to(REPOSITORY) else ""


def results_tables(figures: Path = FIGURES) -> str:
    """Every published Markdown table of ``figures`` (`is_published`), each under a heading
    that names its file: the listed ones (`RESULT_TABLES`) first, then any other."""
    present = {path.name for path in published_files(figures, "*.md")}
    source = _source(figures)
    parts = []
    for name, title in RESULT_TABLES:
        if name in present:
            text = (figures / name).read_text()
            parts.append(f"### {title}\n\n`{source}/{name}`\n\n{_demote(text)}")
    others = sorted(present - {name for name, _ in RESULT_TABLES})
    if others:
        parts.append("### Other tables\n")
        for name in others:
            text = (figures / name).read_text()
            parts.append(f"#### `{name}`\n\n{_demote(text)}")
    if not parts:
        parts.append(
            "No table is committed: `make tables` writes them once the `paper` preset has "
            "evaluated runs.\n"
        )
    return "\n".join(parts)


def result_figures(figures: Path = FIGURES, site_folder: str = "figures") -> str:
    """Every published PNG figure and GIF rollout of ``figures`` (`is_published`; copied
    into the site's ``site_folder``, relative to the page, by `main`), the listed ones
    (`RESULT_FIGURES`) first, each with its PDF's path where one is committed."""
    present = {
        path.name for pattern in ("*.png", "*.gif") for path in published_files(figures, pattern)
    }
    order = [name for name, _ in RESULT_FIGURES if name in present]
    order += sorted(present - set(order))
    titles = dict(RESULT_FIGURES)
    source = _source(figures)
    parts = []
    for name in order:
        title = titles.get(name, name.rsplit(".", 1)[0].replace("_", " "))
        pdf = (figures / name).with_suffix(".pdf")
        where = f"`{source}/{name}`"
        if pdf.exists():
            where += f", `{source}/{pdf.name}`"
        parts.append(f"### {title}\n\n![{title}]({site_folder}/{name})\n\n{where}\n")
    return "\n".join(parts)


# -- what the site publishes ------------------------------------------------------------------

ILLUSTRATIONS = ("rollout_dcp.gif", "rollout_dbm.gif", "dcp_scene.png", "dbm_scene.png")
"""Committed figures named by no preset (scenes and rollouts) that the site shows."""

PUBLISHED_SUFFIXES = (".md", ".png", ".gif")
"""The result files the site shows: Markdown tables and figures (CSV, LaTeX and PDF stay in
the repository, linked by name)."""


def shipped_presets() -> tuple[str, ...]:
    """Every preset this checkout ships (``distgprl/presets/*.yaml``)."""
    return tuple(sorted(path.stem for path in (PACKAGE / "presets").glob("*.yaml")))


def reference_presets() -> tuple[str, ...]:
    """The presets whose outputs the site publishes: ``paper`` (Table I) and every member
    preset of a study read beside it (`distgprl.studies.studies_of`); never ``ci`` or any
    other preset (a reduced-size run is a check of the code, not a result)."""
    from distgprl.studies import studies_of

    presets = ["paper"]
    for study in studies_of("paper"):
        presets += study.presets
    return tuple(dict.fromkeys(presets))


def archived_presets(figures: Path) -> tuple[str, ...] | None:
    """The presets of an archived environment whose ``paper_figures/`` is ``figures``: its
    run folders beside it (``results/archive/env-vN/<preset>/``; not ``ci``), which may name
    presets no longer shipped; None for outputs that are not an archive's."""
    runs = figures.parent
    if not (runs / "paper").is_dir():
        return None
    skip = {figures.name, "hardware", "ci"}
    return tuple(sorted(p.name for p in runs.iterdir() if p.is_dir() and p.name not in skip))


def is_published(name: str, reference: tuple[str, ...] | None = None) -> bool:
    """Whether the output file ``name`` (of a ``paper_figures/`` folder) is on the site: a
    Markdown table or a figure whose name is ``<kind>_<preset>[_<more>]`` for a reference
    preset (`reference_presets`, or an archive's ``reference``) and names no other shipped
    preset, or a listed illustration (`ILLUSTRATIONS`). ``table1_ci.md``,
    ``all_methods_ci.png`` and files named by no preset are not published."""
    if not name.endswith(PUBLISHED_SUFFIXES):
        return False
    if name in ILLUSTRATIONS:
        return True
    tokens = set(name.split(".", 1)[0].split("_"))
    presets = set(reference_presets() if reference is None else reference)
    others = set(shipped_presets()) - presets
    return bool(tokens & presets) and not tokens & others


def published_files(figures: Path, pattern: str) -> list[Path]:
    """The files of ``figures`` matching ``pattern`` that the site publishes, by name (an
    archive's by its own presets, `archived_presets`); the ones left out are logged (mkdocs'
    info level: shown, never a failure of --strict)."""
    reference = archived_presets(figures)
    found = sorted(figures.glob(pattern))
    kept = [path for path in found if is_published(path.name, reference)]
    left_out = [path.name for path in found if path not in kept]
    if left_out:
        LOG.info("not published (no reference preset's output): %s", ", ".join(left_out))
    return kept


# -- the results page's first screen ----------------------------------------------------------

TASK_TITLES = {"dcp": "DCP: push a cube", "dbm": "DBM: lift a bar"}
"""Each task's heading in the compact Table I (the tasks of `distgprl.data.TASK_NAMES`)."""

PLAIN_VERDICTS = {
    "inconclusive (no runs)": "awaiting runs",
    "inconclusive (fewer than 2 seeds)": "awaiting a second seed",
}
"""The verdicts of `distgprl.report.claims` said plainly where they mean "not yet"; every
other verdict (reproduced, refuted, inconclusive, on a task or not) is shown as it is."""

AWAITING = frozenset(PLAIN_VERDICTS.values())
"""The plain verdicts of a claim that still waits for runs (no deciding number yet)."""

GLOSSES = {
    "PoI": "probability of improvement: the chance that a Dist-GPRL run beats a run of the "
    "method compared (0.5: a tie); decided where its 95 % interval excludes 0.5",
    "IQM": "interquartile mean over seeds (the mean of their middle half), 95 % bootstrap "
    "interval in brackets",
    "TCs": "task configurations: the objects' start poses and speeds",
}
"""Each abbreviation the first screen uses, glossed where it appears (a tooltip) and in the
legend under it."""


def glossed(text: str) -> str:
    """``text`` HTML-escaped, each abbreviation of `GLOSSES` in it an ``<abbr>`` with its
    gloss."""
    text = html.escape(text)
    for word, gloss in GLOSSES.items():
        text = re.sub(rf"\b{word}\b", f'<abbr title="{html.escape(gloss)}">{word}</abbr>', text)
    return text


def read_rows(path: Path) -> list[dict[str, str]]:
    """A committed CSV's rows (an absent file: none)."""
    if not path.exists():
        return []
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def committed_runs(
    root: Path = RESULTS, preset: str = "paper"
) -> dict[tuple[str, str], tuple[int, int]]:
    """{(task, method): (finished runs, planned runs)} of the ``preset`` sweep under ``root``
    (`distgprl.experiments.sweep.plan_jobs`, finished: `is_complete`)."""
    from distgprl.experiments.sweep import is_complete, plan_jobs

    counts: dict[tuple[str, str], list[int]] = {}
    for job in plan_jobs(preset, root=root):
        count = counts.setdefault((job.task, job.method), [0, 0])
        count[0] += int(is_complete(job))
        count[1] += 1
    return {key: (done, planned) for key, (done, planned) in counts.items()}


def _number(value: str) -> str:
    return f"{float(value):.2f}"


def _rate_cell(row: dict[str, str] | None, task: str, metric: str) -> str:
    """One compact Table I cell: the mean over seeds, the 95 % t-interval in small type
    where there are two or more seeds, and the untrained mark (best-policy success only)."""
    if row is None or not row.get(f"{task}_{metric}_rate_mean"):
        return '<td class="awaiting">awaiting</td>'
    text = _number(row[f"{task}_{metric}_rate_mean"])
    low, high = row.get(f"{task}_{metric}_rate_ci_low"), row.get(f"{task}_{metric}_rate_ci_high")
    if low and high:
        text += f' <span class="ci">{_number(low)}–{_number(high)}</span>'
    untrained = row.get(f"{task}_untrained_best_seeds") or "0"
    if metric == "success" and int(untrained):
        title = (
            f"at {untrained} seed(s) no trained policy beat the untrained one (untrained "
            f"curve success {_number(row[f'{task}_untrained_curve_success_mean'])})"
        )
        text += f' <span class="mark" title="{html.escape(title)}">†</span>'
    return f"<td>{text}</td>"


def compact_table(
    rows: list[dict[str, str]],
    runs: dict[tuple[str, str], tuple[int, int]] | None = None,
) -> str:
    """Table I in brief, as HTML: one row per method, per task the runs in, success and
    collision (mean, interval in small type). With ``runs`` ({(task, method): (finished,
    planned)}) every planned method has a row, its missing cells "awaiting"; without, the
    rows of the file."""
    from distgprl.data import TASK_NAMES
    from distgprl.methods import METHODS, TABLE_ORDER

    by_method = {row["method"]: row for row in rows}
    methods = [m for m in TABLE_ORDER if m in by_method or (runs and any(m == k[1] for k in runs))]
    methods += [m for m in by_method if m not in methods]
    head = "".join(f'<th colspan="3">{TASK_TITLES.get(t, t.upper())}</th>' for t in TASK_NAMES)
    runs_title = "seeds in / planned" if runs is not None else "seeds in the cell"
    metrics = "".join(
        f'<th><abbr title="{runs_title}">runs</abbr></th>'
        '<th><abbr title="share of the 100 evaluation episodes that complete the task without '
        'a collision">success</abbr></th>'
        '<th><abbr title="share of the 100 evaluation episodes with a collision">collision'
        "</abbr></th>"
        for _ in TASK_NAMES
    )
    lines = [
        '<table class="results-compact">',
        f'<thead><tr><th rowspan="2">Method</th>{head}</tr><tr>{metrics}</tr></thead>',
        "<tbody>",
    ]
    for method in methods:
        row = by_method.get(method)
        label = METHODS[method].label if method in METHODS else (row or {}).get("label", method)
        cells = [f"<td>{html.escape(label)}</td>"]
        for task in TASK_NAMES:
            seeds = int((row or {}).get(f"{task}_seeds") or 0)
            if runs is not None:
                done, planned = runs.get((task, method), (seeds, 0))
                cells.append(f'<td class="runs">{done}/{planned}</td>')
            else:
                cells.append(f'<td class="runs">{seeds}</td>')
            cells += [_rate_cell(row, task, "success"), _rate_cell(row, task, "collision")]
        lines.append(f"<tr>{''.join(cells)}</tr>")
    lines += ["</tbody>", "</table>"]
    return "\n".join(lines)


@dataclasses.dataclass(frozen=True)
class ClaimSummary:
    """One claim in plain words: its overall verdict and the number(s) that decide it.

    Attributes:
        claim: the claim as `distgprl.report.claims` words it.
        verdict: the overall verdict, said plainly (`PLAIN_VERDICTS`).
        deciding: the statistic that decides it on each task the verdict rests on (the task
            it names, else every task), e.g. ``DCP: PoI 0.88 [0.50, 1.00]``; empty while
            awaiting runs.
    """

    claim: str
    verdict: str
    deciding: str


_HIGHEST = re.compile(r"highest other: (?P<rival>.+?) (?P<estimate>\d\.\d\d(?: \[[^\]]*\])?)")
_DOMINANCE = re.compile(r"dominates (?P<dominates>[^;]+); dominated by (?P<dominated>[^;]+)")
_CONSERVATIVE = re.compile(
    r"success IQM (?P<own>[^v]+?) vs Dist-GPRL (?P<proposed>[^;]+); "
    r"collision IQM below (?P<below>\d+), above (?P<above>\d+) of (?P<others>\d+) others"
)


def _estimate(row: dict[str, str]) -> str:
    value = _number(row["value"])
    if row.get("ci_low") and row.get("ci_high"):
        value += f" [{_number(row['ci_low'])}, {_number(row['ci_high'])}]"
    return value


def deciding_number(row: dict[str, str]) -> str:
    """A task row of ``claims_<preset>.csv`` as the statistic that decides its verdict, in
    words, short enough for one line per claim: a PoI with its interval; for a ranking claim
    the method's IQM interval against the highest other's; for the balance claim who
    dominates Dist-GPRL, else how many it dominates; for the conservative claim how many
    others ProMP-RRL's collisions exceed and its success against Dist-GPRL's (IQMs).
    A detail in no known form is shown as it is."""
    if not row.get("value"):
        return ""
    detail = row.get("detail", "")
    if row["test"].startswith("PoI"):
        return f"PoI {_estimate(row)}"
    if match := _HIGHEST.search(detail):
        return f"IQM {_estimate(row)} vs {match['rival']} {match['estimate']}"
    if match := _DOMINANCE.search(detail):
        if match["dominated"] != "none":
            return f"dominated by {match['dominated']}"
        beaten = [name for name in match["dominates"].split(", ") if name != "none"]
        return f"dominated by none, dominates {len(beaten)}"
    if match := _CONSERVATIVE.search(detail):
        own, proposed = (match[key].split(" [")[0] for key in ("own", "proposed"))
        return (
            f"collisions above {match['above']} of {match['others']} others; "
            f"success {own} vs Dist-GPRL {proposed}"
        )
    return detail


def claim_summaries(path: Path) -> list[ClaimSummary]:
    """Every claim of a committed ``claims_<preset>.csv`` in plain words (`ClaimSummary`),
    in the file's order."""
    from distgprl.data import TASK_NAMES

    rows = read_rows(path)
    summaries = []
    for claim in dict.fromkeys(row["claim"] for row in rows):
        own = [row for row in rows if row["claim"] == claim]
        overall = next(row["verdict"] for row in own if row["task"] == "all")
        verdict = PLAIN_VERDICTS.get(overall, overall)
        named = [t for t in TASK_NAMES if overall.endswith(f" on {t.upper()}")]
        parts = []
        if verdict not in AWAITING:
            for row in own:
                if row["task"] in (named or TASK_NAMES) and (text := deciding_number(row)):
                    parts.append(f"{row['task'].upper()}: {text}")
        summaries.append(ClaimSummary(claim, verdict, " · ".join(parts)))
    return summaries


def _verdict_cell(summary: ClaimSummary | None, with_number: bool = True) -> str:
    """A claims cell: the verdict in bold, and (``with_number``) the number that decides it."""
    if summary is None:
        return '<td class="awaiting">no table</td>'
    word = summary.verdict.split()[0]
    verdict = f'<strong class="verdict verdict-{word}">{html.escape(summary.verdict)}</strong>'
    if summary.deciding and with_number:
        verdict += f' <span class="deciding">{glossed(summary.deciding)}</span>'
    return f"<td>{verdict}</td>"


def claims_summary(current: Path, archived: Path, heading: str) -> str:
    """The claims in brief, as HTML: each claim with the current environment's verdict (from
    its ``claims_paper.csv``) and, beside it, the archived one's; the number that decides it
    is the current environment's once its verdict is in, the archived one's while it awaits
    runs (one number per claim and task, so that each claim stays on about one line).
    ``heading`` heads the current environment's column."""
    now = {s.claim: s for s in claim_summaries(current)}
    before = {s.claim: s for s in claim_summaries(archived)}
    lines = [
        '<table class="results-compact results-claims">',
        f"<thead><tr><th>The paper's claim</th><th>{html.escape(heading)}</th>"
        f"<th>Environment v{ARCHIVE_VERSION} (complete, archived)</th></tr></thead>",
        "<tbody>",
    ]
    for claim in dict.fromkeys([*now, *before]):
        decided = claim in now and now[claim].verdict not in AWAITING
        lines.append(
            f"<tr><td>{html.escape(claim)}</td>{_verdict_cell(now.get(claim))}"
            f"{_verdict_cell(before.get(claim), with_number=not decided)}</tr>"
        )
    lines += ["</tbody>", "</table>"]
    return "\n".join(lines)


def sweep_shape() -> str:
    """The ``paper`` sweep's runs in words (`distgprl.experiments.sweep.plan_jobs`' layout:
    every trained method of Table I at every sweep seed on every task, each untrained
    reference once per task)."""
    from distgprl.data import TASK_NAMES
    from distgprl.identity import SWEEP_SEEDS
    from distgprl.methods import METHODS, TABLE_ORDER

    trained = sum(METHODS[m].trainable for m in TABLE_ORDER)
    return (
        f"the <code>paper</code> sweep: {trained} methods × {len(TASK_NAMES)} tasks × "
        f"{len(SWEEP_SEEDS)} seeds, and {len(TABLE_ORDER) - trained} untrained references "
        "once per task"
    )


def archived_runs(archive: Path = ARCHIVE) -> int:
    """The archived environment's Table I runs (``paper/<task>/<method>/seed<k>`` folders
    holding a ``summary.json``)."""
    return len(list((archive / "paper").glob("*/*/seed*/summary.json")))


def _environment_version() -> int:
    from distgprl.config_types import ENVIRONMENT_VERSION

    return ENVIRONMENT_VERSION


def _figure(figures: Path, site_folder: str) -> str:
    """The learning-curve figure of ``figures`` as an HTML figure (its site path under
    ``site_folder``, relative to the results page), or a note that there is none yet."""
    name = "all_methods_paper.png"
    if not (figures / name).exists():
        return '<p class="awaiting">No learning curve yet: <code>make tables</code> draws it.</p>'
    caption = glossed("Learning curves: mean over seeds, 95 % band, on the 50 curve TCs")
    return (
        f'<figure class="results-curves"><a href="{site_folder}/{name}">'
        f'<img src="{site_folder}/{name}" alt="Learning curves of every method with runs"></a>'
        f"<figcaption>{caption}</figcaption>"
        "</figure>"
    )


def results_summary(
    figures: Path = FIGURES, archived: Path = ARCHIVE_FIGURES, root: Path = RESULTS
) -> str:
    """The results page's first screen, as HTML from the committed files: where the sweep
    stands (runs in of runs planned), Table I in brief (`compact_table`: every planned
    method, "awaiting" where no run is in), the learning curves and the claims in brief
    (`claims_summary`: the current environment's verdicts beside the archived one's), with
    a line glossing every symbol they use."""
    version = _environment_version()
    runs = committed_runs(root)
    done = sum(d for d, _ in runs.values())
    planned = sum(p for _, p in runs.values())
    rows = read_rows(figures / "table1_paper.csv")
    marked = any(
        int(row.get(f"{t}_untrained_best_seeds") or 0) for row in rows for t in TASK_TITLES
    )
    progress = (
        f"{done} of {planned} runs in</strong> ({sweep_shape()}); the other {planned - done} "
        "are training or queued, so the cells and claims without runs say <em>awaiting</em>"
        if done < planned
        else f"all {planned} runs in</strong> ({sweep_shape()})"
    )
    status = (
        f'<p class="results-status"><strong>Environment v{version}: {progress}. Environment '
        f"v{ARCHIVE_VERSION}'s {archived_runs()} runs are complete and archived: their "
        "verdicts stand beside (the two are not comparable number for number: "
        '<a href="../findings/environment-v8/">what v8 changed</a>).</p>'
    )
    legend = (
        '<p class="results-legend"><em>success</em>: share of the 100 evaluation episodes '
        "(one per fixed task configuration, TC) completed without a collision; "
        "<em>collision</em>: share with one; best learning-curve policy, mean over seeds (95 % "
        "t-interval in small type); <em>runs</em>: seeds in / planned"
        + ("; †: no trained policy beat the untrained one at that many seeds" if marked else "")
        + ". "
        + glossed("PoI")
        + ": the chance that a Dist-GPRL run beats a run of the "
        "method compared (0.5: a tie), decided where its 95 % interval excludes 0.5; "
        + glossed("IQM")
        + ": the mean of the middle half of the seeds.</p>"
    )
    return "\n".join(
        [
            '<div class="results-first-screen">',
            status,
            '<div class="results-grid">',
            '<div class="results-table">',
            compact_table(rows, runs),
            legend,
            "</div>",
            _figure(figures, FIGURE_SITE_FOLDER),
            "</div>",
            claims_summary(
                figures / "claims_paper.csv",
                archived / "claims_paper.csv",
                f"Environment v{version} ({'training' if done < planned else 'complete'})",
            ),
            "</div>",
        ]
    )


# -- benchmarks -------------------------------------------------------------------------------


def _bench_markdown() -> Callable[[dict[str, Any]], str]:
    """`distgprl.experiments.bench.markdown.markdown_table`, loaded from its file alone (the
    bench package's __init__ imports torch, which the table does not need)."""
    path = PACKAGE / "experiments" / "bench" / "markdown.py"
    spec = importlib.util.spec_from_file_location("_bench_markdown", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.markdown_table


def benchmark_tables(bench: Path = BENCH) -> str:
    """The committed full benchmark (``results/bench/bench_full.json``) as its tables."""
    document = json.loads((bench / "bench_full.json").read_text())
    return _bench_markdown()(document).strip() + "\n"


# -- the configuration reference --------------------------------------------------------------


def attribute_docs(cls: type) -> dict[str, str]:
    """The Google-style ``Attributes:`` section of ``cls``'s docstring, by field name (an
    entry ``a, b: text`` documents both)."""
    doc = inspect.cleandoc(cls.__doc__ or "")
    if "\nAttributes:\n" not in doc:
        return {}
    entries: dict[str, str] = {}
    names: list[str] = []
    for line in doc.split("\nAttributes:\n", 1)[1].splitlines():
        if line and not line.startswith(" "):
            break  # the next section
        match = re.match(r"^ {4}([a-z_][a-z0-9_, ]*):\s*(.*)$", line)
        if match:
            names = [n.strip() for n in match.group(1).split(",")]
            for name in names:
                entries[name] = match.group(2).strip()
        elif names and line.strip():
            for name in names:
                entries[name] += " " + line.strip()
    return entries


def config_classes() -> list[type]:
    """The configuration's frozen dataclasses, in the order a preset file lists them."""
    from distgprl import config_types

    return [
        config_types.Config,
        config_types.EnvConfig,
        config_types.SACConfig,
        config_types.RunConfig,
    ]


SECTIONS = {"Config": "", "EnvConfig": "env", "SACConfig": "sac", "RunConfig": "run"}
"""The preset file's section of each dataclass (`Config` is the file itself)."""


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _default(field: dataclasses.Field[Any]) -> str:
    if field.default is not dataclasses.MISSING:
        return repr(field.default)
    if field.default_factory is not dataclasses.MISSING:
        if dataclasses.is_dataclass(field.default_factory):
            return f"{field.default_factory.__name__}() (below)"
        return repr(field.default_factory())
    return "(required)"


def config_reference() -> str:
    """One table per configuration dataclass: every field's preset key, type, default and
    its documented meaning (units included: m, rad, s, steps, ...)."""
    parts = []
    for cls in config_classes():
        docs = attribute_docs(cls)
        section = SECTIONS[cls.__name__]
        summary = (cls.__doc__ or "").strip().split("\n\n", 1)[0].replace("\n", " ")
        prefix = f"{section}." if section else ""
        rows = [
            f"| `{prefix}{f.name}` | `{_cell(str(f.type))}` | `{_cell(_default(f))}` | "
            f"{_cell(docs.get(f.name, ''))} |"
            for f in dataclasses.fields(cls)
        ]
        title = f"`{section}`: `{cls.__name__}`" if section else f"The whole file: `{cls.__name__}`"
        parts.append(
            f"### {title}\n\n{summary}\n\n"
            "| key | type | default | meaning and unit |\n|---|---|---|---|\n"
            + "\n".join(rows)
            + "\n"
        )
    return "\n".join(parts)


def preset_files() -> str:
    """Every shipped preset's YAML file, verbatim (the values it sets over the defaults)."""
    parts = []
    for path in sorted((PACKAGE / "presets").glob("*.yaml")):
        parts.append(
            f"### `{path.stem}`\n\n`distgprl/presets/{path.name}`\n\n```yaml\n"
            f"{path.read_text().rstrip()}\n```\n"
        )
    return "\n".join(parts)


# -- the result schema ------------------------------------------------------------------------

SCHEMA_COLUMNS = (
    "PROGRESS_FIELDS",
    "EVALUATION_FIELDS",
    "REPAIR_EVALUATION_FIELDS",
    "TRIAL_FIELDS",
)
"""The column lists of ``distgprl/schema.py`` the schema page shows."""


def module_constants(path: Path) -> dict[str, tuple[Any, str]]:
    """A module's top-level constants: name -> (value, the docstring under its assignment),
    read from the source (the module is not imported)."""
    tree = ast.parse(path.read_text())
    out: dict[str, tuple[Any, str]] = {}
    body = tree.body
    for index, node in enumerate(body):
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            target = node.targets[0]
            if not isinstance(target, ast.Name):
                continue
            try:
                value = ast.literal_eval(node.value)
            except ValueError:
                continue
            doc = ""
            following = body[index + 1] if index + 1 < len(body) else None
            if (
                isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)
            ):
                doc = following.value.value
            out[target.id] = (value, doc)
    return out


def _plain(doc: str) -> str:
    """A docstring's reStructuredText roles as Markdown code (``:data:`X``` -> ``X``)."""
    doc = re.sub(r":[a-z]+:`([^`]+)`", r"`\1`", doc)
    return " ".join(doc.split()).replace("``", "`")


def schema_columns() -> str:
    """The column lists of every result CSV, each with its documentation."""
    constants = module_constants(PACKAGE / "schema.py")
    parts = []
    for name in SCHEMA_COLUMNS:
        columns, doc = constants[name]
        listed = ", ".join(f"`{column}`" for column in columns)
        parts.append(f"### `{name}`\n\n{listed}\n\n{_plain(doc)}\n")
    for name in ("SCHEMA_VERSION", "N_WINDOWS", "EVALUATION_SEED", "TRAINING_CURVE_SEED"):
        value, doc = constants[name]
        parts.append(f"- `{name} = {value!r}`" + (f": {_plain(doc)}" if doc else ""))
    return "\n".join(parts) + "\n"


# -- the Python API pages ---------------------------------------------------------------------

API_PAGES: dict[str, str] = {
    "api": "The CLI's commands as functions, for notebooks and scripts.",
    "skill": "The GP via-point skill, its operator S and the ProMP.",
    "safety": "The Euclidean distance field, the HAP safe subspace and its loss L_hap.",
    "adaptation": "The adaptation core: action layout, windows, the plan state.",
    "sim": "The PyBullet simulation: robot, tasks, control loop, rendering.",
    "envs": "The gymnasium environments: the adaptation MDP and ProMP-RRL's residual RL.",
    "agents": "SAC with the regularised actor loss (L_sim, L_hap).",
    "safety_layer": "The safety layer: pre-flight check, retiming, via-point push, the gates.",
    "hardware": "Hardware trials: UR5e and digital-twin backends, perception, the watchdog.",
    "experiments": "Training, evaluation, sweeps, run state, Table II's twin trials, the bench.",
    "report": "Tables, claims, learning curves and the mechanism table, from results only.",
}
"""One reference page per subpackage (and ``distgprl.api``), with its one-line summary."""

CORE_MODULES = (
    "config",
    "config_checks",
    "config_types",
    "reward_scale",
    "trial_protocol",
    "methods",
    "studies",
    "identity",
    "schema",
    "runstate",
    "limits",
    "errors",
    "io",
    "data",
    "machine",
    "version",
)
"""The ground floor's modules (DESIGN §1), on the "Core modules" page."""


def package_modules(package: str) -> list[str]:
    """Every public module of ``distgprl.<package>`` on disk, the package itself first."""
    root = PACKAGE / package
    if not root.is_dir():
        return [f"distgprl.{package}"]
    names = []
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(PACKAGE).with_suffix("")
        parts = list(relative.parts)
        if parts[-1] == "__main__" or any(p.startswith("_") and p != "__init__" for p in parts):
            continue
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names.append(".".join(["distgprl", *parts]))
    return sorted(names, key=lambda name: (name.count("."), name))


def api_page(package: str) -> str:
    """The reference page of ``distgprl.<package>``: one mkdocstrings block per module."""
    modules = package_modules(package)
    blocks = "\n".join(f"::: {module}\n" for module in modules)
    return f"# `distgprl.{package}`\n\n{API_PAGES[package]}\n\n{blocks}"


def core_page() -> str:
    """The reference page of the ground floor's modules."""
    blocks = "\n".join(f"::: distgprl.{name}\n" for name in CORE_MODULES)
    return (
        "# Core modules\n\nThe package's ground floor (DESIGN §1): configuration, methods, "
        "run identity, the results schema, and what every layer above shares. None imports "
        f"the simulator, the learner or an environment.\n\n{blocks}"
    )


# -- the changelog ----------------------------------------------------------------------------


def changelog() -> str:
    """``CHANGELOG.md`` as the site's changelog page."""
    return (REPOSITORY / "CHANGELOG.md").read_text()


# -- the build --------------------------------------------------------------------------------

GENERATORS: dict[str, Callable[[], str]] = {
    "results-summary": results_summary,
    "results-tables": results_tables,
    "results-figures": result_figures,
    "archived-table": lambda: compact_table(read_rows(ARCHIVE_FIGURES / "table1_paper.csv")),
    "archived-tables": lambda: results_tables(ARCHIVE_FIGURES),
    "archived-figures": lambda: result_figures(ARCHIVE_FIGURES, f"{FIGURE_SITE_FOLDER}/env-v7"),
    "benchmark-tables": benchmark_tables,
    "config-reference": config_reference,
    "preset-files": preset_files,
    "schema-columns": schema_columns,
}
"""What a ``<!-- generated: NAME -->`` line of a hand-written page is replaced with."""


def expand(text: str) -> str:
    """A hand-written page with each generated-content line replaced (an unknown name is an
    error, so a typo fails the build)."""

    def replace(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in GENERATORS:
            raise KeyError(f"unknown generated content {name!r}; known: {sorted(GENERATORS)}")
        return GENERATORS[name]().rstrip()

    return MARKER.sub(replace, text)


def generated_pages() -> dict[str, str]:
    """Every page the build writes, by path under the site's sources: the hand-written pages
    with markers, expanded, and the wholly generated ones."""
    pages = {}
    for path in sorted(DOCS.rglob("*.md")):
        text = path.read_text()
        if MARKER.search(text):
            pages[path.relative_to(DOCS).as_posix()] = expand(text)
    for package in API_PAGES:
        pages[f"reference/api/{package}.md"] = api_page(package)
    pages["reference/api/core.md"] = core_page()
    pages["changelog.md"] = changelog()
    return pages


def figure_files(figures: Path = FIGURES, archived: Path = ARCHIVE_FIGURES) -> dict[str, Path]:
    """The figures the site shows, by their path in the site -> the committed file: the
    published ones (`is_published`) of ``figures`` and of the archived environment's
    ``archived``, and the benchmark figure."""
    files = {}
    for folder, site in ((figures, FIGURE_DIR), (archived, ARCHIVE_FIGURE_DIR)):
        for pattern in ("*.png", "*.gif"):
            for path in published_files(folder, pattern):
                files[f"{site}/{path.name}"] = path
    files[f"{FIGURE_DIR}/bench_full.png"] = BENCH / "bench_full.png"
    return files


def main() -> None:
    """Write the generated pages and copy the figures into the site (mkdocs-gen-files)."""
    import mkdocs_gen_files

    for name, text in generated_pages().items():
        with mkdocs_gen_files.open(name, "w") as handle:
            handle.write(text)
    for name, source in figure_files().items():
        with mkdocs_gen_files.open(name, "wb") as handle, source.open("rb") as data:
            shutil.copyfileobj(data, handle)


if __name__ in {"__main__", "<run_path>"}:
    main()
