"""The committed tables under ``paper_figures/`` are exactly what ``make tables`` makes from
the committed ``results/``: no table in the repository (nor the README's short Table I, nor
the documentation site's results page, which copies them) is stale or edited by hand, and
none is left that the results no longer make. Before a preset has any evaluated run (e.g. a
new environment's, its predecessor's runs archived under ``results/archive/``) ``make
tables`` makes none of its tables, so none may be committed, and the README must point to
the archive instead of showing a Table I."""

from __future__ import annotations

import re
from pathlib import Path

from _scripts import load_script

from distgprl.experiments.mechanisms import reach_rows
from distgprl.report.mechanisms import write_mechanisms
from distgprl.report.tables import write_tables

REPOSITORY = Path(__file__).resolve().parents[2]
RESULTS, FIGURES = REPOSITORY / "results", REPOSITORY / "paper_figures"

MAKE_TABLES = {"paper": None}  # v7's reward-unit study is archived with its tables
"""The ``distgprl tables --preset P [--against Q]`` calls of ``make tables`` (P: Q)."""

MAKE_MECHANISMS = ("paper",)
"""The ``distgprl mechanisms --preset P`` calls of ``make tables``."""


def site_table(table: str) -> str:
    """A committed table as the results page shows it (`docs_pages.site_table`)."""
    text: str = load_script("docs_pages").site_table(table)
    return text


def results_page() -> str:
    """The documentation site's results pages as the build writes them (scripts/docs_pages.py
    copies the committed tables of paper_figures/ into them), one text."""
    pages = load_script("docs_pages").generated_pages()
    return "\n".join(text for name, text in sorted(pages.items()) if name.startswith("results/"))


def has_runs(preset: str) -> bool:
    """Whether ``results/<preset>`` holds an evaluated run (else its tables are pending)."""
    return any((RESULTS / preset).glob("*/*/seed*/summary.json"))


NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
"""A number as the tables write it (the mechanism table's CSV: 6 significant digits)."""


def same_up_to_last_digit(made: str, committed: str) -> bool:
    """Whether two texts are the same but for numbers that differ by at most one unit in
    their last written digit (or 1e-5 relative, for numbers written without decimals)."""
    if NUMBER.sub("#", made) != NUMBER.sub("#", committed):
        return False
    for new, old in zip(NUMBER.findall(made), NUMBER.findall(committed), strict=True):
        if new == old:
            continue
        mantissa = old.lower().split("e")[0]
        unit = 10.0 ** -len(mantissa.split(".")[1]) if "." in mantissa else 0.0
        if "e" in old.lower():
            unit *= 10.0 ** int(old.lower().split("e")[1])
        if abs(float(new) - float(old)) > max(1.01 * unit, 1e-5 * abs(float(old))):
            return False
    return True


def test_the_last_digit_comparison_allows_a_rounding_flip_and_nothing_more():
    assert same_up_to_last_digit("reach,0.0794997,yes", "reach,0.0794998,yes")
    assert same_up_to_last_digit("x 2.38499e-05 m", "x 2.38500e-05 m")
    assert not same_up_to_last_digit("reach,0.0794997,yes", "reach,0.0795007,yes")
    assert not same_up_to_last_digit("14 of 14 pairs", "13 of 14 pairs")
    assert not same_up_to_last_digit("reach,0.0794997,yes", "reach,0.0794997,no")


def test_committed_tables_are_regenerated_byte_for_byte(tmp_path):
    """Every table made from results/ is committed unchanged, and every committed table is
    made: with no evaluated run yet (the v6 runs pending), paper_figures/ holds no table.

    Across machines: the tables read the committed result files only and are byte-identical
    on any CPU; the mechanism table's reach rows are recomputed (each method's environment
    and its fitted skill), whose floating point differs between CPUs (BLAS kernels, the
    likelihood fit's optimiser path), so its files may differ by one unit in a number's last
    written digit and nothing else."""
    made = []
    for preset, against in MAKE_TABLES.items():
        if has_runs(preset):  # without runs `distgprl tables` refuses: nothing is made
            made += write_tables(RESULTS, preset, tmp_path, against)
    recomputed: set[str] = set()
    for preset in MAKE_MECHANISMS:
        if has_runs(preset):  # the reach rows are recomputed (docstring: across machines)
            written = write_mechanisms(RESULTS, preset, tmp_path, reach_rows(RESULTS, preset))[0]
            made += written
            recomputed |= {path.name for path in written}
    for path in made:
        committed = FIGURES / path.name
        assert committed.exists(), f"{path.name} is made from results/ but not committed"
        if path.name in recomputed and path.read_bytes() != committed.read_bytes():
            same = same_up_to_last_digit(path.read_text(), committed.read_text())
            assert same, f"{path.name} is stale"
            continue
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
    for preset in MAKE_MECHANISMS:
        assert f"distgprl mechanisms --preset {preset}\n" in makefile


def test_the_readme_shows_the_committed_table_one():
    """The README's short Table I (success and collision per method and task) is made from
    the committed one (the best policy's, Algorithm 1's output) by scripts/readme_results.py,
    and the site's results page shows the committed table itself; before the paper preset has
    runs there is none, and the README points to the archived environments' tables instead."""
    readme = (REPOSITORY / "README.md").read_text()
    table = FIGURES / "table1_paper.md"
    assert table.exists() == has_runs("paper")
    short = load_script("readme_results").short_table()
    start, end = "<!-- results:start -->\n", "<!-- results:end -->"
    assert f"{start}{short}{end}" in readme, "README's Table I is stale: scripts/readme_results.py"
    if table.exists():
        assert site_table(table.read_text()) in results_page()
    else:
        assert "results/archive/env-v7" in readme


def test_the_short_table_is_table_one_in_brief(tmp_path):
    """Each row of the README's short table is the method's success (with its seeds) and
    collision per task, as the committed Table I's Markdown shows them."""
    csv_text = (
        "method,label,dcp_seeds,dcp_success_rate_mean,dcp_collision_rate_mean,dbm_seeds,"
        "dbm_success_rate_mean,dbm_collision_rate_mean\n"
        "gprl,GPRL,2,0.465,0.1,0,,\n"
    )
    (tmp_path / "table1_paper.csv").write_text(csv_text)
    short = load_script("readme_results").short_table(tmp_path)
    assert "| GPRL | 0.47 [2] | 0.10 | – | – |" in short
    assert "No Table I" in load_script("readme_results").short_table(tmp_path / "none")


def test_the_readme_shows_the_committed_claims_per_reading():
    """The README's claims table (each claim's verdict under Table I and across every reading)
    is made from the committed claims_robustness_paper.csv by scripts/readme_results.py."""
    readme = (REPOSITORY / "README.md").read_text()
    claims = load_script("readme_results").claims_table()
    start, end = "<!-- claims:start -->\n", "<!-- claims:end -->"
    assert f"{start}{claims}{end}" in readme, "README's claims are stale: scripts/readme_results.py"


def test_the_claims_table_is_table_one_beside_every_reading(tmp_path):
    """Each row of the README's claims table is a claim, its Table I verdict (the `paper`
    preset's row) and its verdict across every reading (the `across` row), in the file's order;
    a study reading's own row and the per-study columns are left to the full file."""
    csv_text = (
        "claim,reading,preset,verdict,detail\n"
        "B claim,zero-mean GP (Table I),paper,refuted on DCP,\n"
        "B claim,unit variance (v4),operator-unit,reproduced,\n"
        "B claim,across operators,,reading-dependent: operators only,\n"
        "B claim,across,,reading-dependent: refuted on DCP under zero-mean GP,\n"
        "A claim,zero-mean GP (Table I),paper,inconclusive,\n"
        "A claim,across,,inconclusive under every reading,\n"
    )
    (tmp_path / "claims_robustness_paper.csv").write_text(csv_text)
    table = load_script("readme_results").claims_table(tmp_path)
    rows = [line for line in table.splitlines() if line.startswith("| ") and "claim |" in line]
    assert rows == [
        "| B claim | refuted on DCP | reading-dependent: refuted on DCP under zero-mean GP |",
        "| A claim | inconclusive | inconclusive under every reading |",
    ]
    assert "operators only" not in table
    assert "No claims" in load_script("readme_results").claims_table(tmp_path / "none")


def test_the_claims_table_names_the_readings_without_runs_and_how_to_train_them(tmp_path):
    """A study reading under which no claim has runs (each verdict "not run under this
    reading" or "not tested by this study") is named under the table with its study's sweep
    command; a reading with a verdict of its own is not, and without such readings nothing is
    added."""
    header = "claim,reading,preset,verdict,detail\n"
    rows = (
        "A claim,zero-mean GP (Table I),paper,reproduced,\n"
        "A claim,unit variance (v4),operator-unit,not run under this reading,\n"
        "B claim,unit variance (v4),operator-unit,not tested by this study,\n"
        "A claim,correlation only,operator-correlation,reproduced,\n"
        "A claim,across,,incomplete: awaiting unit variance (v4),\n"
    )
    (tmp_path / "claims_robustness_paper.csv").write_text(header + rows)
    table = load_script("readme_results").claims_table(tmp_path)
    assert table.endswith(
        "\nNo runs yet under the operators study's unit variance (v4) "
        "(`distgprl sweep --preset operators`).\n"
    )
    (tmp_path / "claims_robustness_paper.csv").write_text(
        header + rows.replace("not run under this reading", "refuted")
    )
    assert "No runs yet" not in load_script("readme_results").claims_table(tmp_path)


def test_the_site_shows_the_committed_hardware_and_repair_tables():
    """The site's copies of Table II, the twin robustness table and Table I + repair are the
    committed ones (where they exist)."""
    page = results_page()
    for name in ("table2_paper.md", "table2_noise_paper.md", "table1_repair_paper.md"):
        if (FIGURES / name).exists():
            assert site_table((FIGURES / name).read_text()) in page, f"the site's {name} is stale"


def test_the_site_shows_the_committed_claims_table():
    """The claims table the site shows is the committed one, so its verdicts cannot go stale:
    the results page's for the current environment's runs once they exist, and the archived
    environment-v7 README's for the archived v7 runs (always)."""
    archive = REPOSITORY / "results" / "archive" / "env-v7"
    archived = (archive / "paper_figures" / "claims_paper.md").read_text().strip()
    assert archived in (archive / "README.md").read_text()
    current = FIGURES / "claims_paper.md"
    if current.exists():
        assert site_table(current.read_text()) in results_page()
    else:
        assert "results/archive/env-v7/README.md" in (REPOSITORY / "README.md").read_text()
