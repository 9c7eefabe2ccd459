"""Write the README's short results table from the committed Table I.

``python scripts/readme_results.py`` replaces what lies between ``<!-- results:start -->`` and
``<!-- results:end -->`` in README.md with `short_table`: each method's success and collision
rates per task from ``paper_figures/table1_paper.csv`` (what `make tables` made), with links to
the full tables. The full tables, the claims, Table II and the figures are on the
documentation site's results page, which copies them from ``paper_figures/`` at build time
(``scripts/docs_pages.py``). The committed-tables tests check that the README's table is
`short_table` of the committed Table I, so run this after `make tables`.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
START, END = "<!-- results:start -->", "<!-- results:end -->"
TASKS = ("dcp", "dbm")


def _environment_version() -> int:
    sys.path.insert(0, str(REPOSITORY))
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
            "`results/archive/env-v5/README.md`, 70 runs at five seeds).\n"
        )
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    lines = [
        f"**Table I v{version} so far** (`paper` preset, Algorithm 1's best policy, 100 "
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


def main() -> int:
    readme = REPOSITORY / "README.md"
    text = readme.read_text()
    if START not in text or END not in text:
        print(f"README.md has no {START} ... {END} block", file=sys.stderr)
        return 2
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    readme.write_text(f"{head}{START}\n{short_table()}{END}{tail}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
