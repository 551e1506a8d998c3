"""Every notebook in notebooks/ runs from top to bottom without an error, at a small size.

Each notebook has a code cell tagged ``parameters`` (sizes); a cell injected right after it sets the
small sizes of SMALL_PARAMETERS.  The notebooks run in the ``python3`` kernel of the Python running
the tests (ipykernel in the same environment), from a temporary folder.
"""

from __future__ import annotations

import pathlib

import pytest

import nbclient  # noqa: E402
import nbformat  # noqa: E402

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((REPOSITORY / "notebooks").glob("*.ipynb"))
SMALL_PARAMETERS = "N_SAMPLES = 2000\n"
TIMEOUT = 300


def with_small_parameters(notebook):
    """The notebook with a cell setting SMALL_PARAMETERS after its ``parameters`` cell."""
    for index, cell in enumerate(notebook.cells):
        if "parameters" in cell.get("metadata", {}).get("tags", []):
            notebook.cells.insert(index + 1, nbformat.v4.new_code_cell(SMALL_PARAMETERS))
            return notebook
    raise AssertionError("no code cell tagged 'parameters'")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[path.stem for path in NOTEBOOKS])
def test_notebook_runs(path, tmp_path):
    notebook = nbformat.read(path, as_version=4)
    assert all(not cell.get("outputs") for cell in notebook.cells if cell.cell_type == "code"), (
        f"{path.name} is committed with outputs; clear them")
    client = nbclient.NotebookClient(
        with_small_parameters(notebook), timeout=TIMEOUT, kernel_name="python3",
        resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError, naming the cell, on any error
    errors = [output for cell in notebook.cells if cell.cell_type == "code"
              for output in cell.get("outputs", []) if output.get("output_type") == "error"]
    assert not errors


def test_there_are_notebooks():
    assert NOTEBOOKS, "no notebook found in notebooks/"
