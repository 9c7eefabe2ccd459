"""The committed tables under ``paper_figures/`` are exactly what ``make tables`` makes from
the committed ``results/``: no table in the repository (or the README's copy of Table I) is
stale or edited by hand, and none is left that the results no longer make. Before a preset
has any evaluated run (environment v6: the v5 runs are archived in ``results/archive/env-v5``
and the v6 runs pending) ``make tables`` makes none of its tables, so none may be committed,
and the README must point to the archive instead of showing a Table I."""

from __future__ import annotations

from pathlib import Path

from distgprl.report.tables import write_tables

REPOSITORY = Path(__file__).resolve().parents[2]
RESULTS, FIGURES = REPOSITORY / "results", REPOSITORY / "paper_figures"

MAKE_TABLES = {"paper": None, "reward-unit-10": None}  # the reward-unit study's own Table I
"""The ``distgprl tables --preset P [--against Q]`` calls of ``make tables`` (P: Q)."""


def has_runs(preset: str) -> bool:
    """Whether ``results/<preset>`` holds an evaluated run (else its tables are pending)."""
    return any((RESULTS / preset).glob("*/*/seed*/summary.json"))


def test_committed_tables_are_regenerated_byte_for_byte(tmp_path):
    """Every table made from results/ is committed unchanged, and every committed table is
    made: with no evaluated run yet (the v6 runs pending), paper_figures/ holds no table."""
    made = []
    for preset, against in MAKE_TABLES.items():
        if has_runs(preset):  # without runs `distgprl tables` refuses: nothing is made
            made += write_tables(RESULTS, preset, tmp_path, against)
    for path in made:
        committed = FIGURES / path.name
        assert committed.exists(), f"{path.name} is made from results/ but not committed"
        assert path.read_bytes() == committed.read_bytes(), f"{path.name} is stale"
    committed = {
        p.name for p in FIGURES.iterdir() if p.name.endswith((".csv", ".md", ".tex", ".meta.json"))
    }
    left = committed - {path.name for path in made}
    assert not left, f"committed tables no longer made from results/: {sorted(left)}"


def test_the_makefile_makes_these_tables():
    makefile = (REPOSITORY / "Makefile").read_text()
    for preset, against in MAKE_TABLES.items():
        call = f"distgprl tables --preset {preset}" + (f" --against {against}" if against else "")
        assert f"{call}\n" in makefile


def test_the_readme_shows_the_committed_table_one():
    """The README's Table I is the committed one (the best policy's, Algorithm 1's output);
    before the paper preset has runs, there is none, and the README points to the archived
    environment-v5 tables instead."""
    readme = (REPOSITORY / "README.md").read_text()
    table = FIGURES / "table1_paper.md"
    assert table.exists() == has_runs("paper")
    if table.exists():
        assert table.read_text().strip() in readme
    else:
        assert "results/archive/env-v5" in readme


def test_the_readme_shows_the_committed_hardware_and_repair_tables():
    """The README's copies of Table II, the twin robustness table and Table I + repair are
    the committed ones (where they exist)."""
    readme = (REPOSITORY / "README.md").read_text()
    for name in ("table2_paper.md", "table2_noise_paper.md", "table1_repair_paper.md"):
        if (FIGURES / name).exists():
            assert (FIGURES / name).read_text().strip() in readme, f"README's {name} is stale"


def test_the_readme_shows_the_committed_claims_table():
    """The claims table a README shows is the committed one, so its verdicts cannot go stale:
    the README's for the current environment's runs once they exist, and the archived
    environment-v5 README's for the archived v5 runs (always)."""
    archive = REPOSITORY / "results" / "archive" / "env-v5"
    archived = (archive / "paper_figures" / "claims_paper.md").read_text().strip()
    assert archived in (archive / "README.md").read_text()
    current = FIGURES / "claims_paper.md"
    if current.exists():
        assert current.read_text().strip() in (REPOSITORY / "README.md").read_text()
    else:
        assert "results/archive/env-v5/README.md" in (REPOSITORY / "README.md").read_text()
