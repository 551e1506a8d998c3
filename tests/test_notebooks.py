"""Every notebook in notebooks/ runs from top to bottom without an error, at a small size.

Each notebook has a code cell tagged ``parameters`` (sizes); a cell injected right after it sets the
small sizes of SMALL_PARAMETERS (the names a notebook does not use are harmless).  The notebooks run
in one ``python3`` kernel of the Python running the tests (ipykernel in the same environment), one
after the other: each starts with a fresh namespace (``%reset -f``) in its own temporary folder, as
if it were alone, while the kernel's start and imports are paid once.
"""

from __future__ import annotations

import pathlib

import nbclient  # noqa: E402
import nbformat  # noqa: E402
import pytest
from nbclient.util import run_sync  # noqa: E402


REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((REPOSITORY / "notebooks").glob("*.ipynb"))
# N_SAMPLES: the drawing sizes.  FIT_SETTINGS: notebooks/lightcurve.ipynb's inversion with a small
# search (one period cell, 8 starts, 2 refined, rounds only on a misfit) and the ellipsoid model (the
# convex model's final solve, the largest of its programs, left out: tests/test_lightcurve_fit.py runs
# it), so that every cell runs, the shape cells on the ellipsoid's facets; the inversion's quality is
# measured there too.
# CHAINS, WARMUP, DRAWS: notebooks/posterior.ipynb's sampler (2 chains of 150 + 150 steps).
SMALL_PARAMETERS = """N_SAMPLES = 2000
FIT_SETTINGS = dict(shape="ellipsoid", convex_subdivisions=1, period_grid=(1, 1), starts_per_period=8, n_refine=2,
                    stop_at_noise=True)
CHAINS, WARMUP, DRAWS = 2, 150, 150
"""
TIMEOUT = 300


def with_small_parameters(notebook, folder):
    """The notebook with SMALL_PARAMETERS after its ``parameters`` cell, and a first cell that empties
    the kernel's namespace and enters ``folder``."""
    for index, cell in enumerate(notebook.cells):
        if "parameters" in cell.get("metadata", {}).get("tags", []):
            notebook.cells.insert(index + 1, nbformat.v4.new_code_cell(SMALL_PARAMETERS))
            break
    else:
        raise AssertionError("no code cell tagged 'parameters'")
    notebook.cells.insert(0, nbformat.v4.new_code_cell(f"%reset -f\nimport os\nos.chdir({str(folder)!r})\ndel os"))
    return notebook


@pytest.fixture(scope="module")
def kernel():
    """One started python3 kernel, shut down after the last notebook."""
    manager = nbclient.NotebookClient(nbformat.v4.new_notebook(), kernel_name="python3").create_kernel_manager()
    run_sync(manager.start_kernel)()
    yield manager
    run_sync(manager.shutdown_kernel)(now=True)


# Notebooks over a minute at their small sizes (CPU seconds measured in the shared kernel): slow.
SLOW_NOTEBOOKS = {
    # 80 s: the inversion's programs (search, windows of the continuation, covariance) compile.
    "lightcurve": "fit_lightcurve compiles its search and refinement programs (about 60 s of its 80 s)",
}


@pytest.mark.parametrize(
    "path",
    [
        pytest.param(path, id=path.stem, marks=pytest.mark.slow(reason=SLOW_NOTEBOOKS[path.stem]))
        if path.stem in SLOW_NOTEBOOKS
        else pytest.param(path, id=path.stem)
        for path in NOTEBOOKS
    ],
)
def test_notebook_runs(path, tmp_path, kernel):
    notebook = nbformat.read(path, as_version=4)
    assert all(not cell.get("outputs") for cell in notebook.cells if cell.cell_type == "code"), (
        f"{path.name} is committed with outputs; clear them"
    )
    client = nbclient.NotebookClient(
        with_small_parameters(notebook, tmp_path), km=kernel, timeout=TIMEOUT, kernel_name="python3"
    )
    try:
        client.execute()  # raises CellExecutionError, naming the cell, on any error
    finally:
        if client.kc is not None:
            client.kc.stop_channels()
    errors = [
        output
        for cell in notebook.cells
        if cell.cell_type == "code"
        for output in cell.get("outputs", [])
        if output.get("output_type") == "error"
    ]
    assert not errors


def test_there_are_notebooks():
    assert NOTEBOOKS, "no notebook found in notebooks/"
