"""Sweep kinds travel with the data: each `SweepArrays` carries its kind, `FitData.kind(sweep)` gives it, and a
sweep's name is turned into a kind (`gyrojax.sweeps.sweep_kind`) only where names come in: files, the CLI, the
arrays' construction, a user's argument (read from the source with `ast`)."""

import ast
import pathlib

import jax
import numpy as np
import pytest

import gyrojax as gj
from gyrojax._identify.fitio import _skeleton_block
from gyrojax._model.fitdata import FitData, fit_data
from gyrojax.io import SweepArrays
from gyrojax.sweeps import Dac, RateTable, VcfStatic


ROOT = pathlib.Path(__file__).parent.parent
PACKAGE = ROOT / "gyrojax"

BOUNDARY = ("gyrojax/_sweeps/", "gyrojax/_data/", "gyrojax/_cli/", "gyrojax/cli.py", "gyrojax/io.py")
"""Where a sweep's name may become its kind: the kinds' own wing, the data files and their arrays, the CLI."""

NAMED_BY_USER = {
    "gyrojax/_lots/campaign.py::_sweep_kinds": "simulate_table's `sweeps` argument: names or kinds",
    "gyrojax/_plan/experiment.py::CandidateExperiment.__init__": "its `sweep` argument: a name or a kind",
    "gyrojax/_metrics/result.py::MetricsReport.summary": "a JSON document's records, which name their sweep",
    "gyrojax/_metrics/result.py::MetricsReport.undetermined": "a JSON document's records, which name their sweep",
}
"""Functions outside `BOUNDARY` that turn a name a user (or a document) gives into a kind; the list only shrinks."""


def _calls(tree: ast.AST, prefix: str = ""):
    """(qualified function name, line) of every call of `sweep_kind` in `tree`."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            yield from _calls(node, prefix + node.name + ".")
            continue
        if isinstance(node, ast.Call):
            f = node.func
            if (isinstance(f, ast.Name) and f.id == "sweep_kind") or (isinstance(f, ast.Attribute)
                                                                      and f.attr == "sweep_kind"):
                yield prefix.rstrip("."), node.lineno
        yield from _calls(node, prefix)


def _lookups():
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(BOUNDARY):
            continue
        out += [(f"{rel}::{name}", line) for name, line in _calls(ast.parse(path.read_text()))]
    return out


def test_names_become_kinds_only_at_the_boundary():
    """Code that reads data asks the data's kind (`SweepArrays.kind`, `FitData.kind(sweep)`, `Table.kinds()`),
    not the registry by the name that keys it."""
    tree = ast.parse("class A:\n    def f(self, s):\n        return sweep_kind(s)\n"
                     "def g(s):\n    return registry.sweep_kind(s).biased\n")
    assert list(_calls(tree)) == [("A.f", 3), ("g", 5)]  # the finder sees methods and module attributes
    found = _lookups()
    inside = [f"{where} (line {line})" for where, line in found if where not in NAMED_BY_USER]
    assert not inside, "sweep_kind(name) on a data key; ask the data's kind instead:\n" + "\n".join(inside)
    stale = sorted(set(NAMED_BY_USER) - {where for where, _ in found})
    assert not stale, f"no longer call sweep_kind: remove them from NAMED_BY_USER: {stale}"


@pytest.fixture(scope="module")
def table():
    cols = {"device": [], "run": [], "sweep": [], "input": [], "output": [], "output_sigma": [],
            "temperature_c": [], "time_s": []}
    for dev in ("a", "b"):
        for sweep, xs in (("rate_table", (-10.0, 0.0, 10.0)), ("dac", (-1000.0, 1000.0, 2000.0))):
            for i, x in enumerate(xs):
                for c, v in (("device", dev), ("run", 0), ("sweep", sweep), ("input", x), ("output", 2 * x + 1),
                             ("output_sigma", 0.1), ("temperature_c", 25.0), ("time_s", 60.0 * i)):
                    cols[c].append(v)
    return gj.Table.from_columns(cols, source="<two sweeps>")


def test_the_arrays_carry_their_kind(table):
    arrays = table.to_arrays("dac")
    assert arrays.kind == Dac() and arrays.sweep == "dac"
    assert list(table.kinds()) == ["rate_table", "dac"] and table.kinds()["rate_table"] == RateTable()
    data = fit_data(table)
    assert data.kind("rate_table") == RateTable() and data.kinds == {"rate_table": RateTable(), "dac": Dac()}
    # the compiled fit's form keeps the kinds (what it predicts with), and one slice of the lot too
    assert data.unlabelled().kind("dac") == Dac() and data.device_slice(1).kind("dac") == Dac()
    # a fit file's arrays get theirs from the names it stores
    assert _skeleton_block("vcf_static", ("inputs", "outputs", "mask"), (("a", (0,)),)).kind == VcfStatic()
    # the kind is static: lots of the same shapes and kinds have one tree structure (they share programs)
    other = gj.Table.from_columns({c: (table[c] if c != "output" else 3 * table[c]) for c in table.column_names})
    assert jax.tree.structure(fit_data(table).unlabelled()) == jax.tree.structure(fit_data(other).unlabelled())


def test_blocks_are_keyed_by_their_kind_name(table):
    data = fit_data(table)
    with pytest.raises(ValueError, match=r"FitData.blocks\['dac'\] holds the arrays of sweep 'rate_table'"):
        FitData({"dac": data.blocks["rate_table"]}, True)
    with pytest.raises(ValueError, match="unknown sweep 'rate_tabel'.*did you mean 'rate_table'"):
        SweepArrays(
            **{f: getattr(data.blocks["rate_table"], f) for f in ("inputs", "outputs", "sigmas", "temperatures",
                                                                   "mask")}, kind="rate_tabel")
    assert np.asarray(data.blocks["rate_table"].mask).sum() == 6
