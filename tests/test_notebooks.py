"""The research notebooks: committed executed at full size, with current outputs, and they still run.

Re-executing them at full size takes too long for the suite; instead the committed outputs are checked cheaply
(every code cell ran, in order, without error, with the installed gyrojax and at full size, and nothing
machine-specific is in them), and each notebook is executed at small sizes in memory, never written back.
"""

import pathlib
import re

import nbformat
import pytest
from nbclient import NotebookClient

import gyrojax


NOTEBOOKS = sorted((pathlib.Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))
IDS = [p.stem for p in NOTEBOOKS]
MACHINE_SPECIFIC = re.compile(r"/work/|/tmp/|/home/|/root/|/Users/|site-packages")


def _text_outputs(cell):
    for o in cell.get("outputs", []):
        if o.output_type == "stream":
            yield o.text
        elif o.output_type in ("execute_result", "display_data"):
            yield o.get("data", {}).get("text/plain", "")
        elif o.output_type == "error":
            yield "\n".join(o.traceback)


def test_there_are_notebooks():
    assert NOTEBOOKS


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_committed_outputs_are_current(path):
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code
    # executed top to bottom in one kernel, every code cell with an output and none with an error
    assert [c.execution_count for c in code] == list(range(1, len(code) + 1)), "re-execute the notebook in order"
    empty = [i for i, c in enumerate(nb.cells) if c.cell_type == "code" and not c.outputs]
    assert not empty, f"code cells {empty} have no outputs: commit the notebook executed"
    assert not [o for c in code for o in c.outputs if o.output_type == "error"]
    # at full size, with the installed gyrojax (the first cell prints "gyrojax VERSION", "(small sizes)" if small)
    first = "".join(_text_outputs(code[0]))
    m = re.search(r"^gyrojax (\S+)(.*)$", first, re.M)
    assert m, "the first code cell must print the gyrojax version"
    assert m.group(1) == gyrojax.__version__, f"executed with gyrojax {m.group(1)}, installed {gyrojax.__version__}"
    assert m.group(2).strip() == "", "the committed notebook was executed at small sizes"
    # figures embedded; no machine paths, no timing metadata
    assert any("image/png" in o.get("data", {}) for c in code for o in c.outputs)
    for c in code:
        for text in _text_outputs(c):
            assert not MACHINE_SPECIFIC.search(text), f"machine-specific text in an output: {text[:200]!r}"
        assert "execution" not in c.metadata
    # the text is finished: ends with a conclusion
    assert nb.cells[-1].cell_type == "markdown" and nb.cells[-1].source.startswith("## Conclusion")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
@pytest.mark.slow
def test_notebook_runs(path, monkeypatch):
    monkeypatch.setenv("GYROJAX_NOTEBOOK_SMALL", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    before = path.read_bytes()
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}).execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors
    first = "".join(_text_outputs([c for c in nb.cells if c.cell_type == "code"][0]))
    assert "(small sizes)" in first
    assert path.read_bytes() == before, "executing the notebook must not write into the committed file"
