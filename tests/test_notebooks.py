"""The research notebooks run end to end at small sizes."""

import pathlib

import nbformat
import pytest
from nbclient import NotebookClient

from conftest import SOLVER_TESTS


NOTEBOOKS = sorted((pathlib.Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))


def test_there_are_notebooks():
    assert NOTEBOOKS


# Notebooks that run identify's solve are opt-in like the other solver tests (see conftest.py).
_SOLVER_NOTEBOOKS = {"02_identify_a_lot", "03_find_a_hidden_effect"}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, monkeypatch):
    if path.stem in _SOLVER_NOTEBOOKS and not SOLVER_TESTS:
        pytest.skip("runs identify's LM solve (can hang the jax 0.10 CPU runtime); GYROJAX_SOLVER_TESTS=1 runs it")
    monkeypatch.setenv("GYROJAX_NOTEBOOK_SMALL", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}).execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors
