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
