"""Every notebook runs top to bottom in a fresh kernel, as a reader would run it, and its assert
cells check its numbers against their analytical or independent references."""

import asyncio
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.ipynb"))
#: a guard against a hung kernel, not a measure: on the project's two cores each notebook runs in
#: under a minute once the numba kernels are cached, and the first one compiles them (minutes)
NOTEBOOK_TIMEOUT = 900.0


def test_every_notebook_is_found():
    assert {"quickstart", "tour", "vibrating_bar", "cantilever", "box_impact", "cost_accuracy"} <= {
        path.stem for path in NOTEBOOKS}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_is_committed_without_outputs_and_checks_a_number(path):
    notebook = nbformat.read(path, as_version=4)
    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert all(not cell.outputs and cell.execution_count is None for cell in code), "clear the outputs"
    assert any(line.startswith("assert ") for cell in code for line in cell.source.splitlines())


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path, monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")  # the kernel inherits it: no window, figures inline
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(notebook, timeout=NOTEBOOK_TIMEOUT, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})  # the kernel's working directory
    # a failing cell raises nbclient's CellExecutionError with the cell and its traceback
    asyncio.run(asyncio.wait_for(client.async_execute(), NOTEBOOK_TIMEOUT))
