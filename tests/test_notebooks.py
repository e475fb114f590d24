"""The research notebooks: committed executed at full size, with current outputs, and they still run.

The committed outputs are what the installed gyrojax prints: `test_committed_outputs_are_current` (slow: each
notebook at full size, minutes) executes every notebook afresh in memory and compares the text outputs, cell by
cell, with the committed ones: the words exactly, the numbers to within one unit of their last printed digit,
two numbers below 1e-20 being round-off (`_differences`). Cheap checks run in the fast tier (every code cell
ran, in order, without error, with the installed gyrojax and at full size, nothing machine-specific), and one
notebook is executed at small sizes in memory, never written back.

After a change to what a notebook prints, re-execute it at full size and commit it (one line; no argument: every
notebook):

    python notebooks/execute.py notebooks/03_find_a_hidden_effect.ipynb
"""

import importlib.util
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


NUMBER = re.compile(r"(?<![\w.-])[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?(?!\w|\.\d)")
"""A number as printed (a digit inside a name, such as `qmg-000` or `x10`, is part of the word)."""


def _last_digit_unit(text: str) -> float:
    """One unit of the last printed digit of the number `text`: 0.01 for '0.959', 1e+03 for '4.5e+04'."""
    mantissa, _, exponent = text.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 10.0 ** (int(exponent or 0) - decimals)


ROUNDOFF = 1e-20
"""Two printed numbers both smaller than this are round-off (the singular value of an exactly singular direction,
1.5e-30 on one machine and 3.5e-30 on another) and equal."""


def _differences(committed: str, fresh: str) -> list:
    """Where two outputs differ: the text with each number replaced by a placeholder must be the same, and each
    number the same to within one unit of the last digit printed (the coarser of the two), or both round-off
    (`ROUNDOFF`)."""
    words_a, words_b = NUMBER.sub("#", committed), NUMBER.sub("#", fresh)
    if words_a != words_b:
        lines = [(a, b) for a, b in zip(words_a.splitlines(), words_b.splitlines()) if a != b]
        first = lines[0] if lines else (words_a[-200:], words_b[-200:])
        return [f"the words differ: committed {first[0][:300]!r}, now {first[1][:300]!r}"]
    out = []
    for a, b in zip(NUMBER.findall(committed), NUMBER.findall(fresh)):
        if max(abs(float(a)), abs(float(b))) < ROUNDOFF:
            continue
        if abs(float(a) - float(b)) > max(_last_digit_unit(a), _last_digit_unit(b)) * (1 + 1e-9):
            out.append(f"{a} is now {b}")
    return out


def _execute_module():
    spec = importlib.util.spec_from_file_location("notebooks_execute", NOTEBOOKS[0].parent / "execute.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_outputs_are_compared_word_for_word_and_to_the_last_digit():
    assert _differences("chi2 353.8 over 396 points, p = 0.94", "chi2 353.9 over 396 points, p = 0.94") == []
    assert _differences("chi2 353.8 over 396 points", "chi2 354.1 over 396 points") == ["353.8 is now 354.1"]
    assert _differences("S = 1.8e+07, 4.5e+04/point", "S = 1.6e+07, 4.6e+04/point") == ["1.8e+07 is now 1.6e+07"]
    assert _differences("dac_inl explain the data", "dac_inl explains the data")[0].startswith("the words differ")
    # digits inside names are words: another device is another text, not a number off by one
    assert _differences("paper-qmg-000: 0.0501", "paper-qmg-001: 0.0501")[0].startswith("the words differ")
    assert _differences("a line", "a line\nand one more")[0].startswith("the words differ")
    assert _differences("held q_y, s = 2.8e-30", "held q_y, s = 6.8e-30") == []  # round-off
    assert _differences("s = 2.8e-30", "s = 0.032") == ["2.8e-30 is now 0.032"]
    # a number that ends a sentence is still a number
    assert _differences("leaving 2.5e-23. Revealed by", "leaving 2.7e-23. Revealed by") == []
    assert _differences("chi2 353.8. Next", "chi2 354.1. Next") == ["353.8 is now 354.1"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
@pytest.mark.slow
def test_committed_outputs_are_current(path):
    # a fresh execution at full size prints what the committed notebook shows (figures are not compared)
    before = path.read_bytes()
    committed = nbformat.read(path, as_version=4)
    fresh = _execute_module().execute(path)
    assert path.read_bytes() == before, "executing the notebook must not write into the committed file"
    old = [c for c in committed.cells if c.cell_type == "code"]
    new = [c for c in fresh.cells if c.cell_type == "code"]
    assert len(old) == len(new)
    assert not [o for c in new for o in c.get("outputs", []) if o.output_type == "error"]
    stale = []
    for i, (a, b) in enumerate(zip(old, new)):
        for why in _differences("".join(_text_outputs(a)), "".join(_text_outputs(b))):
            stale.append(f"code cell {i}: {why}")
    assert not stale, (f"{path.name}: the committed outputs are stale ({len(stale)} difference(s); re-execute: "
                       f"python notebooks/execute.py notebooks/{path.name}): " + "; ".join(stale[:5]))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_committed_notebooks_were_executed_in_order_at_full_size(path):
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


# Every notebook runs at full size above; the small sizes (GYROJAX_NOTEBOOK_SMALL, for a quick look) on the
# quickest one
@pytest.mark.parametrize("path", [p for p in NOTEBOOKS if p.stem.startswith("04_")], ids=lambda p: p.stem)
@pytest.mark.slow
def test_notebook_runs_at_small_sizes(path, monkeypatch):
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
