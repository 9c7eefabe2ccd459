"""The documentation site's generated pages, made at build time (mkdocs-gen-files runs this
file as a script during ``make docs``), so that none of them can go stale:

- the **results page** (``results/index.md``): its hand-written prose, with every table
  ``make tables`` committed under ``paper_figures/`` and every figure copied in at build time;
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
import dataclasses
import importlib.util
import inspect
import json
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
BENCH = REPOSITORY / "results" / "bench"

if str(REPOSITORY) not in sys.path:  # mkdocs runs this file with its own sys.path
    sys.path.insert(0, str(REPOSITORY))

MARKER = re.compile(r"^<!-- generated: ([a-z0-9-]+) -->$", re.MULTILINE)
"""The line a hand-written page puts where a generator's Markdown goes."""

FIGURE_DIR = "results/figures"
"""Where the site holds the copied figures (``paper_figures/*.png``, the benchmark figure)."""

# -- the results page -------------------------------------------------------------------------

RESULT_TABLES: tuple[tuple[str, str], ...] = (
    ("table1_paper.md", "Table I"),
    ("table1_final_paper.md", "Table I of the final policy"),
    ("table1_paper_per_seed.md", "Table I per run"),
    ("table1_final_paper_per_seed.md", "Table I of the final policy, per run"),
    ("aggregates_paper.md", "Aggregates over seeds (IQM)"),
    ("table1_repair_paper.md", "Table I + repair: the safety layer in the loop"),
    ("table2_paper.md", "Table II: hardware trials (digital twin)"),
    ("table2_noise_paper.md", "The twin's robustness to perception error"),
    ("claims_paper.md", "The claims"),
    ("claims_robustness_paper.md", "The claims per reading (operator and reward-unit studies)"),
    ("onsets_operators_paper.md", "When each run learns: the operator study and its control"),
    ("onsets_reward-unit_paper.md", "When each run learns: the reward-unit study"),
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
    ("curves_reward-unit_paper.png", "The reward-unit study: learning curves, seed by seed"),
    ("onsets_operators_paper.png", "The operator study: when each run first reaches 0.5 success"),
    ("onsets_reward-unit_paper.png", "The reward-unit study: when each run first reaches 0.5"),
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


def results_tables(figures: Path = FIGURES) -> str:
    """Every committed Markdown table of ``paper_figures/``, each under a heading that names
    its file: the listed ones (`RESULT_TABLES`) first, then any other."""
    present = {path.name for path in figures.glob("*.md")}
    parts = []
    for name, title in RESULT_TABLES:
        if name in present:
            text = (figures / name).read_text()
            parts.append(f"### {title}\n\n`paper_figures/{name}`\n\n{_demote(text)}")
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


def result_figures(figures: Path = FIGURES) -> str:
    """Every PNG figure and GIF rollout of ``paper_figures/`` (copied into the site by
    `main`), the listed ones (`RESULT_FIGURES`) first, each with its PDF's path where one is
    committed."""
    present = {path.name for pattern in ("*.png", "*.gif") for path in figures.glob(pattern)}
    order = [name for name, _ in RESULT_FIGURES if name in present]
    order += sorted(present - set(order))
    titles = dict(RESULT_FIGURES)
    parts = []
    for name in order:
        title = titles.get(name, name.rsplit(".", 1)[0].replace("_", " "))
        pdf = (figures / name).with_suffix(".pdf")
        source = f"`paper_figures/{name}`"
        if pdf.exists():
            source += f", `paper_figures/{pdf.name}`"
        parts.append(f"### {title}\n\n![{title}](figures/{name})\n\n{source}\n")
    return "\n".join(parts)


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
    "experiments": "Training, evaluation, sweeps, run state and the benchmarks.",
    "hardware": "Hardware trials: UR5e and digital-twin backends, perception, the safety layer.",
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
    "results-tables": results_tables,
    "results-figures": result_figures,
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


def figure_files() -> dict[str, Path]:
    """The figures the site shows, by their path in the site -> the committed file."""
    files = {
        f"{FIGURE_DIR}/{path.name}": path
        for pattern in ("*.png", "*.gif")
        for path in sorted(FIGURES.glob(pattern))
    }
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
