"""The tutorial notebook runs from top to bottom on tracer's API as it is now, so it never rots."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK = ROOT / "notebooks" / "tutorial.ipynb"


def test_tutorial_notebook_runs(tmp_path, monkeypatch):
    """Every cell of a fresh copy (stored outputs cleared) runs without an error in a Jupyter
    kernel; the cells that show pictures show them (images, error maps, the convergence chart,
    the stability case), and the results table lists every strategy with a finite relMSE.

    The kernel imports the same copy of tracer as these tests (conftest.py sets PYTHONPATH), so
    it loads the kernels they compiled instead of compiling its own."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    for cell in notebook.cells:
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    # A kernel spec of this interpreter, found first (JUPYTER_PATH leads the search): a user's
    # or the system's own "python3" spec may name another Python, without tracer.
    spec = tmp_path / "jupyter" / "kernels" / "tracer-tests"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "tracer tests", "language": "python"}))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))
    client = nbclient.NotebookClient(notebook, timeout=600, kernel_name="tracer-tests",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError, naming the cell, if any cell fails

    pictures = sum("image/png" in output.get("data", {}) for cell in notebook.cells
                   if cell.cell_type == "code" for output in cell.outputs)
    assert pictures == 5  # reference, strategies, error maps, convergence, the stability case
    text = "".join(output.get("text", "") for cell in notebook.cells if cell.cell_type == "code"
                   for output in cell.outputs if output.get("output_type") == "stream")
    lines = text.splitlines()
    head = next(i for i, line in enumerate(lines) if line.split()[:2] == ["strategy", "relMSE"])
    table = lines[head + 1:head + 6]
    assert [line.split()[0] for line in table] == ["uniform", "cosine", "bsdf", "light", "mis"]
    assert all(float(line.split()[1]) > 0.0 for line in table)
    assert "nan" not in text.lower()
