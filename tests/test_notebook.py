"""The Python API notebook (docs/guides/python-api-notebook.ipynb) runs from the committed
results of a fresh clone (no training, nothing downloaded) and ships with the outputs the
site shows."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

REPOSITORY = Path(__file__).resolve().parents[1]
NOTEBOOK = REPOSITORY / "docs" / "guides" / "python-api-notebook.ipynb"


def _code_cells(notebook) -> list:
    return [cell for cell in notebook.cells if cell.cell_type == "code"]


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
    no cell raises, and the rollout and the shipped run's files give outputs again."""
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
