"""Re-execute notebooks at full size and write them back, as they are committed:

    python notebooks/execute.py notebooks/03_find_a_hidden_effect.ipynb   # one notebook
    python notebooks/execute.py                                           # every notebook

Each notebook runs top to bottom in a fresh kernel from its own folder (at full size: GYROJAX_NOTEBOOK_SMALL is
unset), and the execution timestamps nbclient records in the cell metadata are removed, so that a re-run
changes only what the code prints. `tests/test_notebooks.py::test_committed_outputs_are_current` compares the
committed text outputs with a fresh execution. A notebook that raises is not written.
"""

import os
import pathlib
import sys
import time

import nbformat
from nbclient import NotebookClient


HERE = pathlib.Path(__file__).resolve().parent


def execute(path: pathlib.Path, *, small: bool = False, timeout: int = 1800) -> nbformat.NotebookNode:
    """`path` executed in a fresh kernel (in memory; not written), at full size unless `small`."""
    env_small = os.environ.pop("GYROJAX_NOTEBOOK_SMALL", None)
    env_backend = os.environ.pop("MPLBACKEND", None)  # the kernel's inline backend embeds the figures
    if small:
        os.environ["GYROJAX_NOTEBOOK_SMALL"] = "1"
    try:
        nb = nbformat.read(path, as_version=4)
        NotebookClient(nb, timeout=timeout, kernel_name="python3",
                       resources={"metadata": {"path": str(path.parent)}}).execute()
    finally:
        os.environ.pop("GYROJAX_NOTEBOOK_SMALL", None)
        if env_small is not None:
            os.environ["GYROJAX_NOTEBOOK_SMALL"] = env_small
        if env_backend is not None:
            os.environ["MPLBACKEND"] = env_backend
    for cell in nb.cells:
        cell.metadata.pop("execution", None)
    return nb


def main(argv) -> int:
    paths = [pathlib.Path(a) for a in argv] or sorted(HERE.glob("*.ipynb"))
    for path in paths:
        if path.suffix != ".ipynb" or not path.is_file():
            print(f"{path}: not a notebook file (.ipynb)", file=sys.stderr)
            return 2
    for path in paths:
        t = time.perf_counter()
        nb = execute(path)
        nbformat.write(nb, path)
        print(f"{path}: executed at full size and written ({time.perf_counter() - t:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
