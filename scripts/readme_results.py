"""Write the README's short results tables from the committed Table I and claims.

``python scripts/readme_results.py`` replaces what lies between ``<!-- results:start -->`` and
``<!-- results:end -->`` in README.md with `short_table`: each method's success and collision
rates per task from ``paper_figures/table1_paper.csv`` (what `make tables` made), with links to
the full tables; and what lies between ``<!-- claims:start -->`` and ``<!-- claims:end -->``
with `claims_table`: each claim's verdict under Table I's readings and across every reading,
from ``paper_figures/claims_robustness_paper.csv``. The full tables, the claims, Table II and
the figures are on the documentation site's results page, which copies them from
``paper_figures/`` at build time (``scripts/docs_pages.py``). The committed-tables tests check
that the README's blocks are `short_table` and `claims_table` of the committed files, so run
this after `make tables`.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))  # this checkout's package, imported where it is needed
START, END = "<!-- results:start -->", "<!-- results:end -->"
CLAIMS_START, CLAIMS_END = "<!-- claims:start -->", "<!-- claims:end -->"
TABLE_ONE_READING = "paper"
"""The ``preset`` of the robustness rows that hold Table I's verdicts."""
ACROSS_EVERY_READING = "across"
"""The ``reading`` of the robustness rows that judge every reading together."""
TASKS = ("dcp", "dbm")


def _environment_version() -> int:
    from distgprl.config_types import ENVIRONMENT_VERSION

    return ENVIRONMENT_VERSION


def _rate(row: dict[str, str], task: str, metric: str) -> str:
    value = row.get(f"{task}_{metric}_rate_mean", "")
    return "–" if value in ("", None) else f"{float(value):.2f}"


def short_table(figures: Path = REPOSITORY / "paper_figures") -> str:
    """The README's results block: Table I's success and collision per method and task (the
    seeds behind each cell in brackets), or a note that no Table I is committed yet."""
    version = _environment_version()
    path = figures / "table1_paper.csv"
    links = (
        "the full table with its intervals, MinCl, completion and kinematic retention is "
        "[`paper_figures/table1_paper.md`](paper_figures/table1_paper.md); Table II, the claims "
        "and the learning curves are on the site's [results page](docs/results/index.md)"
    )
    if not path.exists():
        return (
            f"No Table I of environment v{version} yet: its runs are pending. The archived "
            "environments' tables and readings are in `results/archive/` (e.g. "
            "`results/archive/env-v7/README.md`: Table I v7 at five seeds and its studies).\n"
        )
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    lines = [
        f"**Table I v{version}** (`paper` preset, Algorithm 1's best policy, 100 "
        "evaluation TCs): success and collision rates, mean over seeds (their number in "
        f"brackets); {links}.",
        "",
        "| Method | DCP success | DCP collision | DBM success | DBM collision |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        cells = []
        for task in TASKS:
            seeds = row.get(f"{task}_seeds") or "0"
            success = _rate(row, task, "success")
            cells += [
                success + (f" [{seeds}]" if success != "–" else ""),
                _rate(row, task, "collision"),
            ]
        lines.append(f"| {row['label']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def claims_table(figures: Path = REPOSITORY / "paper_figures") -> str:
    """The README's claims block: each claim's verdict under Table I's readings and across
    every reading of the studies (``claims_robustness_paper.csv``, what `make tables` made),
    or a note that no claims per reading are committed yet."""
    path = figures / "claims_robustness_paper.csv"
    link = "[`claims_robustness_paper.md`](paper_figures/claims_robustness_paper.md)"
    if not path.exists():
        return "No claims per reading yet: Table I's runs or the studies' are pending.\n"
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    claims = list(dict.fromkeys(row["claim"] for row in rows))
    table_one = {row["claim"]: row["verdict"] for row in rows if row["preset"] == TABLE_ONE_READING}
    across = {
        row["claim"]: row["verdict"] for row in rows if row["reading"] == ACROSS_EVERY_READING
    }
    lines = [
        "**The claims per reading** (every reading and its runs: "
        f"{link}; rules: `distgprl.report.claims`, `distgprl.report.robustness`): a claim counts "
        "as reproduced only where every reading reproduces it; one whose verdict changes with "
        "the reading is reading-dependent, with the readings named; one ending 'at unequal "
        "seeds' compares readings with different numbers of runs (a study still training).",
        "",
        "| Claim | Table I | Across every reading |",
        "|---|---|---|",
    ]
    for claim in claims:
        lines.append(f"| {claim} | {table_one.get(claim, '–')} | {across.get(claim, '–')} |")
    lines += ["", line] if (line := readings_without_runs(rows)) else []
    return "\n".join(lines) + "\n"


def readings_without_runs(rows: list[dict[str, str]]) -> str:
    """A sentence naming the study readings (not Table I's, not an across row) under which no
    claim has runs (every verdict `NOT_RUN` or `OUTSIDE`), by study, with the command that
    trains them; "" where every reading has runs."""
    from distgprl.report.robustness import NOT_RUN, OUTSIDE
    from distgprl.studies import study_of_reading

    verdicts: dict[tuple[str, str], set[str]] = {}
    for row in rows:
        if row["preset"] and row["preset"] != TABLE_ONE_READING:
            verdicts.setdefault((row["reading"], row["preset"]), set()).add(row["verdict"])
    by_study: dict[str, list[str]] = {}
    for (label, preset), seen in verdicts.items():
        if seen <= {NOT_RUN, OUTSIDE}:
            study = study_of_reading(preset)
            by_study.setdefault(study.name if study else preset, []).append(label)
    parts = [
        f"the {name} study's {', '.join(labels)} (`distgprl sweep --preset {name}`)"
        for name, labels in by_study.items()
    ]
    return f"No runs yet under {'; '.join(parts)}." if parts else ""


def _replace_block(text: str, start: str, end: str, block: str) -> str | None:
    """``text`` with what lies between ``start`` and ``end`` replaced by ``block``, or None
    where ``text`` has no such block."""
    if start not in text or end not in text:
        return None
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{start}\n{block}{end}{tail}"


def main() -> int:
    readme = REPOSITORY / "README.md"
    text = readme.read_text()
    for start, end, block in (
        (START, END, short_table()),
        (CLAIMS_START, CLAIMS_END, claims_table()),
    ):
        replaced = _replace_block(text, start, end, block)
        if replaced is None:
            print(f"README.md has no {start} ... {end} block", file=sys.stderr)
            return 2
        text = replaced
    readme.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
