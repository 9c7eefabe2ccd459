"""The Python API notebook (docs/guides/python-api-notebook.ipynb) runs from the committed
results of a fresh clone (no training, nothing downloaded) and ships with the outputs the
site shows."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

REPOSITORY = Path(__file__).resolve().parents[1]
NOTEBOOK = REPOSITORY / "docs" / "guides" / "python-api-notebook.ipynb"
PAGE = REPOSITORY / "site" / "guides" / "python-api-notebook" / "index.html"
"""The notebook's page in the built site (make docs)."""
MACHINE_DEPENDENT = "machine-dependent"
"""The tag of the cells whose outputs are a rollout on this machine: bit-exact only where the
numerics are the run's (docs/findings/reproducibility.md), so never compared with the stored."""
REFRESH = "make notebook (make tables runs it: the outputs read the committed results)"


def _code_cells(notebook) -> list:
    return [cell for cell in notebook.cells if cell.cell_type == "code"]


def _shown_text(cell) -> list[str]:
    """What a code cell shows as text: its stdout and its results' plain text (stderr, which
    carries library banners, and images, which depend on the matplotlib version, left out)."""
    return [
        str(output.get("text", ""))
        if output.output_type == "stream"
        else str(output.get("data", {}).get("text/plain", ""))
        for output in cell.outputs
        if output.output_type != "stream" or output.get("name") == "stdout"
    ]


def test_the_committed_notebook_carries_the_outputs_the_site_renders():
    """The site renders the stored outputs (mkdocs-jupyter, execute: false): every code cell
    has them, the learning curve is a PNG, and none is an error."""
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    cells = _code_cells(notebook)
    assert cells and all(cell.outputs for cell in cells)
    kinds = {kind for cell in cells for output in cell.outputs for kind in output.get("data", {})}
    assert "image/png" in kinds
    assert not [o for cell in cells for o in cell.outputs if o.output_type == "error"]


def test_the_notebook_runs_from_the_committed_results(tmp_path):
    """Executed top to bottom in a fresh kernel (from the repository root, as a user runs it):
    no cell raises, the rollout and the shipped run's files give outputs again, and every cell
    that reads the committed results shows what the site shows (a re-run or regenerated result
    the notebook reads leaves its stored outputs stale: refresh them)."""
    shipped = REPOSITORY / "results" / "paper" / "dbm" / "dist-gprl" / "seed0" / "policy_best.pt"
    if not shipped.exists():  # a new environment version, its runs not committed yet
        pytest.skip(f"{shipped}: no shipped policy of this environment version yet")
    stored = nbformat.read(NOTEBOOK, as_version=4)
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    for cell in _code_cells(notebook):
        cell.outputs = []
    client = nbclient.NotebookClient(
        notebook,
        timeout=300,
        kernel_name="python3",
        resources={"metadata": {"path": str(REPOSITORY)}},
    )
    client.execute()  # raises CellExecutionError on the first failing cell
    cells = _code_cells(notebook)
    assert all(cell.outputs for cell in cells)
    text = "".join(
        str(output.get("text", "")) + str(output.get("data", {}).get("text/plain", ""))
        for cell in cells
        for output in cell.outputs
    )
    assert "policy_step" in text and "100 episodes" in text
    compared = [
        (index, before, after)
        for index, (before, after) in enumerate(zip(_code_cells(stored), cells, strict=True))
        if MACHINE_DEPENDENT not in before.metadata.get("tags", [])
    ]
    assert len(compared) >= len(cells) - 2, "only the two rollout cells go uncompared"
    stale = [
        index for index, before, after in compared if _shown_text(before) != _shown_text(after)
    ]
    assert not stale, f"stored outputs of code cells {stale} are stale: {REFRESH}"


@pytest.mark.skipif(not PAGE.exists(), reason="site/ not built: make docs")
def test_the_rendered_notebooks_links_reach_pages_of_the_site():
    """mkdocs-jupyter leaves a Markdown cell's link to another page as written ("python-api.md",
    a source the site does not have); scripts/docs_hooks.py makes it that page's URL. Every
    relative link of the built page reaches a file of the site."""
    links = set(re.findall(r'<a\s[^>]*?href="([^"#:?]+)(?:#[^"]*)?"', PAGE.read_text()))
    assert {"../python-api/", "../results-files/", "../../reference/schema/"} <= links
    targets = {href: PAGE.parent / href for href in links}
    missing = sorted(
        href
        for href, target in targets.items()
        if not (target / "index.html" if target.is_dir() else target).is_file()
    )
    assert not missing, f"links to no file of the site: {missing}"
