"""Copy the committed result tables into the README's results section.

``python scripts/readme_results.py`` replaces what lies between ``<!-- results:start -->`` and
``<!-- results:end -->`` in README.md with the current ``paper_figures/`` tables a reader of the
results section needs (Table I, Table I + repair, Table II and its noise table, the claims and
the claims per reading), each only if `make tables` made it. The committed-tables tests check
that the README's copies are the committed files, so run this after `make tables`.
"""

from __future__ import annotations

import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
START, END = "<!-- results:start -->", "<!-- results:end -->"
TABLES = (
    ("table1_paper.md", "**Table I v7 so far**"),
    ("table1_repair_paper.md", "**Table I + repair** (the hardware safety layer in the loop)"),
    ("table2_paper.md", "**Table II** (digital twin)"),
    ("table2_noise_paper.md", "**The twin's robustness to perception error**"),
    ("claims_paper.md", "**The claims**"),
    ("claims_robustness_paper.md", "**The claims per reading** (operator and reward-unit studies)"),
)


def main() -> int:
    readme = REPOSITORY / "README.md"
    text = readme.read_text()
    if START not in text or END not in text:
        print(f"README.md has no {START} ... {END} block", file=sys.stderr)
        return 2
    parts = []
    for name, title in TABLES:
        path = REPOSITORY / "paper_figures" / name
        if path.exists():
            parts.append(f"{title} (`paper_figures/{name}`):\n\n{path.read_text().strip()}\n")
    body = (
        "\n".join(parts) if parts else "No table yet: the runs of this environment are pending.\n"
    )
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    readme.write_text(f"{head}{START}\n{body}{END}{tail}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
