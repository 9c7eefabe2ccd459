"""The documentation (issue 51): a short README, a CLI reference that covers every command and
cannot drift from ``--help``, generated pages that hold every configuration field and every
committed result table, findings that keep every cited title, and a built site (``make docs``,
which CI runs before the tests) whose search finds the commands.

The site's generated pages come from ``scripts/docs_pages.py`` (run by mkdocs-gen-files at
build time); these tests call its functions directly, without building the site.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from types import ModuleType

import pytest
import yaml
from _scripts import load_script
from typer.testing import CliRunner

from distgprl.cli import app

REPOSITORY = Path(__file__).resolve().parents[1]
DOCS = REPOSITORY / "docs"
SITE = REPOSITORY / "site"
WIDE = {"COLUMNS": "250", "TERMINAL_WIDTH": "250", "NO_COLOR": "1"}
COMMANDS = sorted(command.name or command.callback.__name__ for command in app.registered_commands)

README_MAX_LINES = 150

OLD_README_COMMANDS = frozenset(
    {
        "fit",
        "train",
        "evaluate",
        "sweep",
        "status",
        "mechanisms",
        "tables",
        "curves",
        "hap",
        "render",
        "hardware",
        "bench",
    }
)
"""The ``distgprl <command>`` commands the README documented before issue 51 (its commands
table, and ``bench`` under "Benchmarks"): the site must document each of them."""


@pytest.fixture(scope="module")
def pages() -> ModuleType:
    return load_script("docs_pages")


@pytest.fixture(scope="module")
def cli_docs() -> str:
    """The CLI reference's generated Markdown, exactly as the ``::: mkdocs-click`` block of
    docs/reference/cli.md renders it."""
    from mkdocs_click._docs import make_command_docs

    from distgprl.cli.reference import command

    return "\n".join(
        make_command_docs(
            "distgprl", command, depth=1, style="plain", list_subcommands=True, has_attr_list=True
        )
    )


# -- the README -------------------------------------------------------------------------------


def test_the_readme_is_short():
    lines = (REPOSITORY / "README.md").read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines"


def test_the_readme_keeps_the_two_commands_and_names_every_command():
    """The two commands a newcomer runs, verbatim, and every command of the CLI in its table."""
    readme = (REPOSITORY / "README.md").read_text()
    assert "make setup && .venv/bin/distgprl sweep" in readme
    assert "\nmake test " in readme
    table = readme.split("## Commands", 1)[1].split("\n## ", 1)[0]
    named = set(re.findall(r"`(?:distgprl )?([a-z]+)`", table))
    assert set(COMMANDS) <= named, sorted(set(COMMANDS) - named)


def test_every_readme_link_into_the_repository_exists():
    readme = (REPOSITORY / "README.md").read_text()
    targets = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", readme)
    local = [t for t in targets if "://" not in t]
    assert local, "the README links into the site's sources"
    assert [t for t in local if not (REPOSITORY / t).exists()] == []


# -- the CLI reference ------------------------------------------------------------------------


def test_the_cli_reference_page_renders_the_typer_apps_click_command():
    page = (DOCS / "reference" / "cli.md").read_text()
    assert "::: mkdocs-click" in page
    assert ":module: distgprl.cli.reference" in page
    assert ":command: command" in page
    mkdocs = (REPOSITORY / "mkdocs.yml").read_text()
    assert "- mkdocs-click" in mkdocs


def test_every_subcommand_is_in_the_generated_cli_reference(cli_docs):
    headings = set(re.findall(r"^### distgprl (\w+) \{ #distgprl-\1 ", cli_docs, flags=re.M))
    assert set(COMMANDS) <= headings, sorted(set(COMMANDS) - headings)


@pytest.mark.parametrize("name", COMMANDS)
def test_the_cli_reference_lists_every_option_of_the_help(cli_docs, name):
    """Each option ``distgprl <name> --help`` prints is in that command's section of the
    generated reference (both come from the same click command, so they cannot drift)."""
    help_text = CliRunner().invoke(app, [name, "--help"], env=WIDE).output
    options = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", help_text))
    assert "--help" in options
    section = re.split(rf"^### distgprl {name} \{{", cli_docs, flags=re.MULTILINE)[1]
    section = re.split(r"^### ", section, flags=re.MULTILINE)[0]
    missing = sorted(o for o in options if o not in section)
    assert missing == [], f"{name}: {missing}"


def test_the_site_documents_every_command_the_old_readme_did():
    """Nothing the README's commands table documented is lost: each command has its section
    in the CLI reference's "What each command does", and is a command of the app."""
    page = (DOCS / "reference" / "cli.md").read_text()
    described = set(re.findall(r"^### `distgprl ([a-z]+)`", page, flags=re.MULTILINE))
    described |= set(re.findall(r"^### `distgprl [a-z]+` and `distgprl ([a-z]+)`", page, re.M))
    assert len(re.findall(r"^### `distgprl", page, flags=re.MULTILINE)) == len(described) - 1
    assert OLD_README_COMMANDS <= described, sorted(OLD_README_COMMANDS - described)
    assert OLD_README_COMMANDS <= set(COMMANDS)


# -- the generated pages ----------------------------------------------------------------------


def test_the_configuration_reference_lists_every_field_with_its_meaning(pages):
    """Every field of the configuration's frozen dataclasses is on the page, with its default
    and a documented meaning (the dataclass docstring's ``Attributes:``)."""
    from distgprl.config_types import Config, EnvConfig, RunConfig, SACConfig

    text = pages.config_reference()
    for cls, section in (
        (Config, ""),
        (EnvConfig, "env."),
        (SACConfig, "sac."),
        (RunConfig, "run."),
    ):
        docs = pages.attribute_docs(cls)
        for field in dataclasses.fields(cls):
            assert f"| `{section}{field.name}` |" in text, field.name
            assert docs.get(field.name), f"{cls.__name__}.{field.name} has no description"
        assert set(docs) <= {f.name for f in dataclasses.fields(cls)}, sorted(docs)
    assert "| `env.sd_d_min` | `float` | `0.03` | d_min of Eq. safety_reward, m. |" in text


def test_the_configuration_reference_shows_every_shipped_preset(pages):
    text = pages.preset_files()
    for path in (REPOSITORY / "distgprl" / "presets").glob("*.yaml"):
        assert f"### `{path.stem}`" in text
        assert path.read_text().rstrip() in text
        yaml.safe_load(path.read_text())


def test_the_results_pages_hold_every_committed_table_and_figure(pages):
    """The site's tables page copies every committed table of paper_figures/ (so it cannot
    show a stale one) and every figure, the archived environment's page every table and
    figure of its archive; their hand-written sources ask for them. (Every file of both
    folders is a reference preset's output or a listed illustration: none is left out.)"""
    generated = pages.generated_pages()
    for page, figures, folder in (
        ("tables.md", REPOSITORY / "paper_figures", "figures"),
        ("env-v7.md", pages.ARCHIVE_FIGURES, "figures/env-v7"),
    ):
        source = (DOCS / "results" / page).read_text()
        assert re.search(r"<!-- generated: [a-z]+-tables -->", source)
        assert re.search(r"<!-- generated: [a-z]+-figures -->", source)
        expanded = generated[f"results/{page}"]
        for table in figures.glob("*.md"):
            assert pages.site_table(table.read_text()) in expanded, table.name
        for figure in [*figures.glob("*.png"), *figures.glob("*.gif")]:
            assert f"]({folder}/{figure.name})" in expanded, figure.name
            assert f"results/{folder}/{figure.name}" in pages.figure_files()


def _output_tree(folder: Path) -> Path:
    """A ``paper_figures/`` folder as `make tables` leaves it after the `paper` preset and
    the README's ci block: the reference outputs beside ``*_ci.*`` ones."""
    folder.mkdir()
    for name in (
        "table1_paper.md",
        "table1_paper_per_seed.md",
        "onsets_operators_paper.md",
        "table1_operator-unit.md",
        "table1_ci.md",
        "table1_ci_per_seed.md",
        "claims_ci.md",
        "notes.md",
    ):
        (folder / name).write_text(f"| {name} |\n|---|\n")
    for name in ("all_methods_paper.png", "dcp_scene.png", "all_methods_ci.png", "stray.png"):
        (folder / name).write_bytes(b"\x89PNG")
    (folder / "rollout_ci.gif").write_bytes(b"GIF89a")
    return folder


def test_only_the_reference_presets_outputs_are_published(pages, tmp_path):
    """A folder holding ci outputs beside the paper preset's (the README's ci block run into
    it): the tables page, the figures and the files copied into the site hold the `paper`
    preset's and its studies' outputs and the listed illustrations, no ``*_ci.*`` file and
    no file named by no preset."""
    figures = _output_tree(tmp_path / "paper_figures")
    archived = _output_tree(tmp_path / "archived")
    tables, shown = pages.results_tables(figures), pages.result_figures(figures)
    copied = pages.figure_files(figures, archived)
    for name in ("table1_paper.md", "table1_paper_per_seed.md", "onsets_operators_paper.md"):
        assert f"| {name} |" in tables, name
    assert "| table1_operator-unit.md |" in tables
    for name in ("all_methods_paper.png", "dcp_scene.png"):
        assert f"](figures/{name})" in shown
        assert f"results/figures/{name}" in copied and f"results/figures/env-v7/{name}" in copied
    published = tables + shown + " ".join(copied)
    for name in ("_ci.", "_ci_per_seed", "notes.md", "stray.png", "rollout_ci"):
        assert name not in published, name
    assert {path.parent for path in copied.values()} == {figures, archived, pages.BENCH}


def test_the_reference_presets_are_paper_and_its_studies_never_ci(pages):
    from distgprl.studies import studies_of

    presets = set(pages.reference_presets())
    assert "paper" in presets and "ci" not in presets
    assert {p for study in studies_of("paper") for p in study.presets} <= presets
    assert presets <= set(pages.shipped_presets())


def test_table_one_in_brief_is_the_committed_table(pages, tmp_path):
    """Table I in brief shows each method's success and collision means from the CSV, the
    interval only where the CSV has one, the untrained mark where a seed's best trained
    policy did not beat the untrained one, the runs in of those planned, and "awaiting"
    for every planned method without runs."""
    (tmp_path / "table1_paper.csv").write_text(
        "method,label,dcp_seeds,dcp_success_rate_mean,dcp_success_rate_ci_low,"
        "dcp_success_rate_ci_high,dcp_collision_rate_mean,dcp_untrained_best_seeds,"
        "dcp_untrained_curve_success_mean,dbm_seeds,dbm_success_rate_mean,"
        "dbm_collision_rate_mean\n"
        "gprl,GPRL,2,0.465,0.3,0.63,0.1,1,0.5,0,,\n"
    )
    rows = pages.read_rows(tmp_path / "table1_paper.csv")
    runs = {("dcp", "gprl"): (2, 5), ("dbm", "gprl"): (0, 5), ("dcp", "demo"): (0, 1)}
    table = pages.compact_table(rows, runs)
    gprl = next(line for line in table.splitlines() if line.startswith("<tr><td>GPRL<"))
    assert '<td class="runs">2/5</td><td>0.47 <span class="ci">0.30–0.63</span>' in gprl
    assert 'title="at 1 seed(s) no trained policy beat the untrained one' in gprl
    assert "<td>0.10</td>" in gprl
    assert gprl.count(">awaiting<") == 2
    demo = next(line for line in table.splitlines() if "Demo (no adaptation)" in line)
    assert '<td class="runs">0/1</td><td class="awaiting">awaiting</td>' in demo
    assert "<tr><td>GPRL-D<" not in table  # neither planned here nor in the file


def test_the_first_screen_counts_the_committed_runs_and_shows_their_numbers(pages):
    """The results page's first screen says how many of the `paper` sweep's runs are in
    (`plan_jobs`, finished by `is_complete`) and shows every committed Table I mean."""
    from distgprl.experiments.sweep import is_complete, plan_jobs

    jobs = plan_jobs("paper", root=pages.RESULTS)
    done = sum(is_complete(job) for job in jobs)
    summary = pages.generated_pages()["results/index.md"]
    counted = f"all {done} runs in" if done == len(jobs) else f"{done} of {len(jobs)} runs in"
    assert counted in summary
    for row in pages.read_rows(REPOSITORY / "paper_figures" / "table1_paper.csv"):
        line = next(x for x in summary.splitlines() if x.startswith(f"<tr><td>{row['label']}<"))
        for task in ("dcp", "dbm"):
            for metric in ("success", "collision"):
                if value := row[f"{task}_{metric}_rate_mean"]:
                    assert f"<td>{float(value):.2f}" in line, (row["label"], task, metric)


def test_every_decided_claim_shows_the_number_that_decides_it(pages):
    """Each claim of the committed claims files in plain words: an awaiting verdict for a
    claim without runs, otherwise the verdict with its deciding statistic in a known form
    (a PoI, an IQM against the highest other's, dominance, the conservative rule's two
    comparisons) on each task the verdict rests on, never a detail passed through."""
    known = re.compile(r"^(PoI \d|IQM \d|dominated by |collisions above \d)")
    for path in (
        REPOSITORY / "paper_figures" / "claims_paper.csv",
        pages.ARCHIVE_FIGURES / "claims_paper.csv",
    ):
        rows = pages.read_rows(path)
        summaries = pages.claim_summaries(path)
        assert [s.claim for s in summaries] == list(dict.fromkeys(r["claim"] for r in rows))
        for summary in summaries:
            overall = next(
                r["verdict"] for r in rows if r["claim"] == summary.claim and r["task"] == "all"
            )
            assert summary.verdict == pages.PLAIN_VERDICTS.get(overall, overall)
            if summary.verdict in pages.AWAITING:
                assert summary.deciding == ""
                continue
            parts = summary.deciding.split(" · ")
            tasks = [part.split(": ", 1)[0] for part in parts]
            named = overall.rsplit(" on ", 1)[1] if " on " in overall else None
            assert tasks == ([named] if named else ["DCP", "DBM"]), summary
            assert all(known.match(part.split(": ", 1)[1]) for part in parts), summary
    archived = {
        s.claim: s for s in pages.claim_summaries(pages.ARCHIVE_FIGURES / "claims_paper.csv")
    }
    assert archived["Windowed adaptation beats global"].deciding.startswith("DCP: PoI 0.88 [0.50")


COMMAND = re.compile(r"distgprl (sweep|train|evaluate|tables|curves|mechanisms|render|hardware)\b")
TRACKED_DEFAULTS = {"--root": "results", "--out-dir": "paper_figures"}
"""The output options whose defaults are tracked folders (results/<preset>/, results/hardware,
paper_figures/): a ci example must set each its command has."""


def example_commands() -> list[tuple[str, str]]:
    """Every ``distgprl`` command of the README, the getting-started page, the guides and
    .ci/run that runs the ``ci`` preset, with backslash continuations joined: (file, command)."""
    files = [
        REPOSITORY / "README.md",
        REPOSITORY / ".ci" / "run",
        DOCS / "getting-started.md",
        *sorted((DOCS / "guides").glob("*.md")),
    ]
    commands = []
    for path in files:
        text = path.read_text().replace("\\\n", " ")
        for line in text.splitlines():
            for part in re.split(r"&&|;|\|", line):
                if COMMAND.search(part) and "--preset ci" in part:
                    commands.append((path.relative_to(REPOSITORY).as_posix(), part.strip()))
    return commands


def test_every_ci_example_writes_outside_the_tracked_folders():
    """A reader who runs a documented ``--preset ci`` command (or CI, .ci/run) writes its runs
    and tables into a root of their own (``runs/``, git-ignored, or a temporary folder),
    never into ``results/`` or ``paper_figures/``, whose outputs the site publishes."""
    commands = example_commands()
    assert len(commands) >= 6
    writes = {"--root": COMMAND.pattern, "--out-dir": r"distgprl (tables|curves|mechanisms)\b"}
    for where, command in commands:
        for option, pattern in writes.items():
            if not re.search(pattern, command):
                continue
            match = re.search(rf"{option}[ =](\S+)", command)
            assert match, f"{where}: {command!r} writes to {TRACKED_DEFAULTS[option]}/"
            target = match.group(1).strip("\"'`")
            assert not target.startswith(("results", "paper_figures")), (where, command)


def test_the_benchmarks_page_is_the_committed_benchmark(pages):
    expanded = pages.generated_pages()["results/benchmarks.md"]
    document = json.loads((REPOSITORY / "results" / "bench" / "bench_full.json").read_text())
    speedup = document["adaptation"]["speedup"]["episode_vs_paper"]
    assert f"{speedup:.0f}× faster than the paper's figure" in expanded
    assert "](figures/bench_full.png)" in expanded


def test_the_schema_page_lists_every_result_column(pages):
    from distgprl import schema

    text = pages.generated_pages()["reference/schema.md"]
    for name in pages.SCHEMA_COLUMNS:
        for column in getattr(schema, name):
            assert f"`{column}`" in text, (name, column)


def test_every_module_has_an_api_page(pages):
    """Every public module of the package is rendered on one Python API page."""
    generated = pages.generated_pages()
    blocks = set()
    for name, text in generated.items():
        if name.startswith("reference/api/"):
            blocks |= set(re.findall(r"^::: (\S+)$", text, flags=re.MULTILINE))
    package = REPOSITORY / "distgprl"
    modules = set()
    for path in package.rglob("*.py"):
        parts = list(path.relative_to(REPOSITORY).with_suffix("").parts)
        if parts[-1] == "__main__" or any(p.startswith("_") and p != "__init__" for p in parts):
            continue
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules.add(".".join(parts))
    undocumented = (
        modules
        - blocks
        - {"distgprl", "distgprl.cli"}
        - {m for m in modules if m.startswith("distgprl.cli.")}
    )
    assert undocumented == set()
    for module in ("api", "skill", "safety", "envs", "agents", "experiments", "report"):
        assert f"reference/api/{module}.md" in generated


def test_every_page_in_the_nav_exists(pages):
    """The nav names only hand-written pages or pages the build generates."""
    config = yaml.load((REPOSITORY / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    paths: list[str] = []

    def walk(node: object) -> None:
        if isinstance(node, str):
            paths.append(node)
        elif isinstance(node, list):
            for item in node:
                walk(item)
        elif isinstance(node, dict):
            for value in node.values():
                walk(value)

    walk(config["nav"])
    generated = pages.generated_pages()
    missing = [p for p in paths if not (DOCS / p).exists() and p not in generated]
    assert missing == []


def test_no_marker_names_an_unknown_generator(pages):
    for path in DOCS.rglob("*.md"):
        for name in pages.MARKER.findall(path.read_text()):
            assert name in pages.GENERATORS, f"{path}: {name}"


# -- the findings -----------------------------------------------------------------------------

KNOWN_DANGLING: frozenset[str] = frozenset()
"""Titles cited before issue 51 that no findings section has (reported, not invented here)."""


def findings_titles() -> list[str]:
    """Every section title and bold paragraph lead of the findings pages."""
    titles = []
    for path in (DOCS / "findings").glob("*.md"):
        text = path.read_text()
        titles += re.findall(r"^## (.+)$", text, flags=re.MULTILINE)
        titles += re.findall(r"^\*\*([^*]+)\*\*", text, flags=re.MULTILINE)
    return [" ".join(title.split()) for title in titles]


def test_the_findings_index_names_every_section():
    """docs/FINDINGS.md (which the code cites) lists every section title of the topic pages."""
    index = (DOCS / "FINDINGS.md").read_text()
    for path in (DOCS / "findings").glob("*.md"):
        assert f"(findings/{path.name})" in index, path.name
        for title in re.findall(r"^## (.+)$", path.read_text(), flags=re.MULTILINE):
            assert title in index, title


def test_every_cited_findings_title_exists():
    """A citation of a findings title (``docs/FINDINGS.md`` followed by the title in double
    quotes) in the package, the tests, the scripts or the docs names a section (or a
    paragraph's bold lead) of a findings page."""
    titles = findings_titles()
    cited = set()
    for folder in ("distgprl", "tests", "scripts", "benchmarks", "docs"):
        for path in (REPOSITORY / folder).rglob("*"):
            if path.suffix in (".py", ".md", ".yaml") and path.is_file():
                found = re.findall(r'FINDINGS(?:\.md)?,? "([^"]+)"', path.read_text())
                cited |= {" ".join(title.split()) for title in found}
    assert cited
    unresolved = {c for c in cited if not any(t.startswith(c) for t in titles)}
    assert unresolved <= KNOWN_DANGLING, sorted(unresolved - KNOWN_DANGLING)


# -- the built site (make docs; CI builds it before the tests) --------------------------------

needs_site = pytest.mark.skipif(
    not (SITE / "search" / "search_index.json").exists(), reason="site/ not built: make docs"
)


@needs_site
def test_the_built_sites_search_finds_the_commands():
    index = json.loads((SITE / "search" / "search_index.json").read_text())
    texts = " ".join(doc["title"] + " " + doc["text"] for doc in index["docs"])
    for name in ("sweep", *COMMANDS):
        assert re.search(rf"\b{name}\b", texts), name
    assert any(doc["location"].startswith("reference/cli/") for doc in index["docs"])


@needs_site
def test_the_built_cli_reference_shows_every_subcommand():
    page = (SITE / "reference" / "cli" / "index.html").read_text()
    for name in COMMANDS:
        assert f'id="distgprl-{name}"' in page, name


def test_each_claim_shows_one_environments_deciding_numbers(pages, tmp_path):
    """The claims in brief give the current environment's deciding number once its verdict
    is in, and the archived environment's while the current one awaits runs: one set of
    numbers per claim."""
    header = "claim,test,task,value,ci_low,ci_high,seeds,pairs,verdict,detail\n"
    decided = "A claim,PoI of Dist-GPRL over X,{task},0.9,0.6,1.0,5,25,reproduced,\n"
    awaiting = "B claim,PoI of Dist-GPRL over Y,{task},,,,,,inconclusive (no runs),\n"
    archived = "B claim,PoI of Dist-GPRL over Y,{task},0.2,0.0,0.4,5,25,refuted,\n"
    for name, lines in (("now.csv", (decided, awaiting)), ("before.csv", (decided, archived))):
        text = header + "".join(
            line.format(task=t) for line in lines for t in ("dcp", "dbm", "all")
        )
        (tmp_path / name).write_text(text)
    table = pages.claims_summary(tmp_path / "now.csv", tmp_path / "before.csv", "v8")
    rows = {row.split("</td>", 1)[0]: row.split("<td>") for row in table.split("<tr><td>")[1:]}
    claim_a, claim_b = rows["A claim"], rows["B claim"]
    assert "reproduced" in claim_a[1] and "DCP: <abbr" in claim_a[1] and "PoI" not in claim_a[2]
    assert "awaiting runs" in claim_b[1] and "PoI" not in claim_b[1]
    assert "refuted" in claim_b[2] and "0.20 [0.00, 0.40]" in claim_b[2]
