"""One argument order for the verbs: `identify(model, data)`, `diagnose(model, data)`, `plan(model, data)`. The
old `(data, model)` order of diagnose and plan is swapped with a DeprecationWarning; a wrong pair is a TypeError
naming the argument."""

import ast
import importlib
import pathlib
import re
import warnings

import equinox as eqx
import pytest

import gyrojax as gj


ROOT = pathlib.Path(__file__).parent.parent
candidates_module = importlib.import_module("gyrojax._diagnose.candidates")  # where diagnose and plan call identify
OLD = r"{verb}\(data, model\) is now {verb}\(model, data\): pass the model first, e.g. gj\.{verb}\('paper-qmg', table\)"


class _Stop(Exception):
    pass


@pytest.fixture(scope="module")
def small_table():
    return gj.simulate_table(gj.paper_qmg(), devices=2, runs=1, sweeps=("rate_table",), seed=0, progress=False)


def _call(verb, *args, **kwargs):
    if verb == "plan":
        kwargs.setdefault("scale_factor", False)
    return getattr(gj, verb)(*args, progress=False, **kwargs)


def _baseline_arguments(monkeypatch, verb, *args, **kwargs):
    """The (model, data) that `verb` gives its baseline fit, stopping there (no fit is made)."""
    given = []

    def stop(model, data, **_):
        given.append((model, data))
        raise _Stop

    monkeypatch.setattr(candidates_module, "identify", stop)
    with pytest.raises(_Stop):
        _call(verb, *args, **kwargs)
    (pair,) = given
    return pair


@pytest.mark.parametrize("verb", ["diagnose", "plan"])
def test_the_model_comes_first(monkeypatch, verb, small_table):
    model, data = _baseline_arguments(monkeypatch, verb, "vcf-2018", small_table)
    assert model.device.name == gj.preset("vcf-2018").name
    assert data.devices == ("paper-qmg-000", "paper-qmg-001")


@pytest.mark.parametrize("verb", ["diagnose", "plan"])
@pytest.mark.parametrize("old", [("paper-qmg",), ("vcf-2018",), ()], ids=["paper-qmg", "vcf-2018", "no-model"])
def test_the_old_order_warns_and_fits_the_same(monkeypatch, verb, old, small_table):
    """`verb(data, model)` (or `verb(data)`, the default model) is `verb(model, data)`, with the warning."""
    new = _baseline_arguments(monkeypatch, verb, *(old or ("paper-qmg",)), small_table)
    with pytest.warns(DeprecationWarning, match=OLD.format(verb=verb)):
        swapped = _baseline_arguments(monkeypatch, verb, small_table, *old)
    assert bool(eqx.tree_equal(new, swapped))


@pytest.mark.parametrize("verb", ["diagnose", "plan"])
def test_the_new_order_does_not_warn(monkeypatch, verb, small_table):
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        _baseline_arguments(monkeypatch, verb, "paper-qmg", small_table)
        _baseline_arguments(monkeypatch, verb, data=small_table)


@pytest.mark.parametrize("verb", ["diagnose", "plan"])
def test_a_wrong_pair_is_refused(verb, small_table, tmp_path):
    csv = tmp_path / "lot.csv"
    gj.write_table(small_table, csv)
    expects = (r"model must be a preset name \('paper-qmg', 'vcf-2018'\), a device file \(\.toml\), a Gyroscope or a "
               r"Model")
    with pytest.raises(TypeError, match=rf"{verb}\(model, data\): {expects}; got a Table as model and a Table as data"):
        _call(verb, small_table, small_table)
    with pytest.raises(TypeError, match=rf"{verb}\(model, data\): {expects}, and data a gyrojax.Table or FitData \(read"
                                        r" a file with gyrojax.read_table\); got a Table as model and int as data"):
        _call(verb, small_table, 3)
    with pytest.raises(TypeError, match=rf"{verb}\(model, data\): data must be a gyrojax.Table or FitData \(read a "
                                        rf"file with gyrojax.read_table\); got str '{re.escape(str(csv))}'"):
        _call(verb, "paper-qmg", str(csv))
    with pytest.raises(TypeError, match=rf"{verb}\(model, data\): data must be .*; got str 'vcf-2018'"):
        _call(verb, "paper-qmg", "vcf-2018")


def test_diagnose_needs_data():
    with pytest.raises(TypeError, match=r"diagnose\(model, data\): data must be a gyrojax.Table or FitData .*; got "
                                        r"none"):
        gj.diagnose("paper-qmg", progress=False)


@pytest.mark.slow
def test_a_diagnosis_in_the_old_order_is_the_same_diagnosis(small_table):
    """End to end (a real baseline fit and ranking, no refit): the same JSON in either order."""
    new = gj.diagnose("paper-qmg", small_table, max_effects=0, progress=False)
    with pytest.warns(DeprecationWarning, match=OLD.format(verb="diagnose")):
        old = gj.diagnose(small_table, "paper-qmg", max_effects=0, progress=False)
    assert new.to_json() == old.to_json()


# names of the model and data arguments a public function may take
MODEL_NAMES, DATA_NAMES = {"model", "gyro"}, {"data", "table"}


def _misordered(tree: ast.AST) -> list:
    """(name, line) of each public function (method or not) taking a data argument before its model."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
            names = [a.arg for a in node.args.posonlyargs + node.args.args + node.args.kwonlyargs]
            models = [i for i, n in enumerate(names) if n in MODEL_NAMES]
            data = [i for i, n in enumerate(names) if n in DATA_NAMES]
            if models and data and min(data) < min(models):
                out.append((node.name, node.lineno))
    return out


def test_the_order_checker_finds_data_before_model():
    tree = ast.parse("def diagnose(data, model='paper-qmg', *, alpha=0.01):\n    pass\n\n"
                     "def identify(model, data):\n    pass\n\ndef _private(table, gyro):\n    pass\n")
    assert _misordered(tree) == [("diagnose", 1)]


def test_every_public_function_takes_the_model_before_the_data():
    wrong = [f"{path.relative_to(ROOT)}:{line} {name}" for path in sorted((ROOT / "gyrojax").rglob("*.py"))
             for name, line in _misordered(ast.parse(path.read_text()))]
    assert not wrong, f"take (model, data), as identify does: {wrong}"
