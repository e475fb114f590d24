"""User effects from a file (`load_effects_module`) and from installed packages (the `gyrojax.effects` entry
points), registered like the built-in ones; registered effects are global, so every test removes its own."""

import importlib.metadata
import os
import sys
import textwrap
import warnings

import pytest

import gyrojax as gj
from gyrojax import load_effects_module
from gyrojax._effects import plugins as _plugins
from gyrojax._effects.plugins import ENTRY_POINT_GROUP
from gyrojax._model.parameters import zero_effect
from gyrojax.effects import load_effect_entry_points


EFFECT = textwrap.dedent('''
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import gyrojax as gj


    class {cls}(gj.AbstractEffect):
        gain: jax.Array = eqx.field(converter=lambda v: jnp.asarray(v, dtype=float))

        name = "{name}"
        description = "a DAC reference gain error"
        plugs_into = "excitation.dac.gain_error"

        @classmethod
        def supports(cls, gyro):
            return gyro.closed_loop

        def apply(self, gyro):
            return eqx.tree_at(lambda g: g.excitation.dac.gain_error, gyro,
                               gyro.excitation.dac.gain_error + self.gain)

        @classmethod
        def typical(cls, scale=1.0):
            return cls(scale * {size})
''')


def effect_source(cls="UserGain", name="user_gain", size="5e-4"):
    return EFFECT.format(cls=cls, name=name, size=size)


@pytest.fixture(autouse=True)
def clean_registry(monkeypatch):
    effects, files, modules = dict(gj.EFFECTS), dict(_plugins._loaded_files), set(sys.modules)
    monkeypatch.setattr(_plugins, "_entry_points_loaded", False)
    monkeypatch.setattr(_plugins, "_sources", {})
    monkeypatch.setattr(_plugins, "_origins", {})
    yield
    for name in set(gj.EFFECTS) - set(effects):
        del gj.EFFECTS[name]
    _plugins._loaded_files.clear()
    _plugins._loaded_files.update(files)
    for name in set(sys.modules) - modules:
        if name.startswith(("gyrojax_user_effects_", "gjtest_")) or name.startswith("gjhelper"):
            del sys.modules[name]


def test_a_file_defining_classes_registers_them(tmp_path):
    path = tmp_path / "fx.py"
    path.write_text(effect_source() + textwrap.dedent('''
        from gyrojax.effects import DacInl  # imported: not this file's, not registered again

        class AbstractUserThing(gj.AbstractEffect):  # abstract: a base for others, skipped
            pass

        with open(__file__ + ".runs", "a") as f:
            f.write("ran\\n")
    '''))
    (cls,) = load_effects_module(path)
    assert gj.EFFECTS["user_gain"] is cls and cls.__name__ == "UserGain"
    assert "user_gain" in gj.supported_effects(gj.paper_qmg())
    assert load_effects_module(str(path)) == (cls,)  # loaded once: the file ran once
    assert (tmp_path / "fx.py.runs").read_text() == "ran\n"
    assert gj.add_effect(gj.paper_qmg(), "user_gain", 2.0).excitation.dac.gain_error == pytest.approx(
        float(gj.paper_qmg().excitation.dac.gain_error) + 1e-3)


def test_a_file_may_register_its_effect_itself(tmp_path):
    path = tmp_path / "self_registering.py"
    path.write_text(effect_source() + "\ngj.effects.register_effect(UserGain)\n")
    (cls,) = load_effects_module(path)
    assert gj.EFFECTS["user_gain"] is cls


def test_all_or_none(tmp_path):
    path = tmp_path / "mixed.py"
    path.write_text(effect_source("GoodOne", "good_one") + effect_source("BadOne", "bad_one", "5e-4 + 1.0")
                    .split("import gyrojax as gj", 1)[1])
    with pytest.raises(ValueError, match=f"{path}: effect class BadOne cannot be registered: .*typical\\(0.0\\)"):
        load_effects_module(path)
    assert "good_one" not in gj.EFFECTS and "bad_one" not in gj.EFFECTS


@pytest.mark.parametrize("name, text, message", [
    ("missing.py", None, "{p}: no such file"),
    ("notpython.txt", "x = 1\n", "{p}: not a .py file"),
    ("syntax.py", "x = 1\nclass (:\n", "{p}: line 2: syntax error"),
    ("raises.py", "import os\n\nos.environ['GJ_NOPE_' + 1]\n", "{p}: line 3: importing it failed: TypeError"),
])
def test_load_errors_name_the_file(tmp_path, name, text, message):
    path = tmp_path / name
    if text is not None:
        path.write_text(text)
    with pytest.raises(ValueError, match=message.format(p=path)):
        load_effects_module(path)
    assert not [m for m in sys.modules if m.startswith("gyrojax_user_effects_")]  # no half-imported module


def test_entry_points_load_classes_and_modules_once_and_warn_on_broken_ones(tmp_path, monkeypatch):
    (tmp_path / "gjtest_ep_class.py").write_text(effect_source("EpClass", "ep_class") + "\nNOT_AN_EFFECT = 3\n")
    (tmp_path / "gjtest_ep_module.py").write_text(effect_source("EpModule", "ep_module"))
    monkeypatch.syspath_prepend(str(tmp_path))
    eps = [importlib.metadata.EntryPoint("one", "gjtest_ep_class:EpClass", ENTRY_POINT_GROUP),
           importlib.metadata.EntryPoint("two", "gjtest_ep_module", ENTRY_POINT_GROUP),
           importlib.metadata.EntryPoint("broken", "gjtest_not_installed:Effect", ENTRY_POINT_GROUP),
           importlib.metadata.EntryPoint("wrong", "gjtest_ep_class:NOT_AN_EFFECT", ENTRY_POINT_GROUP)]
    calls = []

    def entry_points(*, group):
        calls.append(group)
        return eps

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    with pytest.warns(UserWarning) as caught:
        added = load_effect_entry_points()
    assert set(added) == {"ep_class", "ep_module"}
    messages = [str(w.message) for w in caught]
    assert any("entry point 'broken' = 'gjtest_not_installed:Effect' in group 'gyrojax.effects' was skipped: "
               "ModuleNotFoundError" in m for m in messages)
    assert any("entry point 'wrong'" in m and "neither an effect class nor a module" in m for m in messages)
    assert load_effect_entry_points() == () and calls == [ENTRY_POINT_GROUP]  # once


def test_the_cli_reports_a_broken_entry_point_as_a_warning(tmp_path, monkeypatch, capsys):
    from gyrojax.cli import main

    broken = importlib.metadata.EntryPoint("broken", "gjtest_not_installed:Effect", ENTRY_POINT_GROUP)
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda *, group: [broken])
    rates = (-200, -100, -50, -10, 0, 10, 50, 100, 200)
    data = tmp_path / "d.csv"
    data.write_text("\n".join(["device,run,sweep,input,output",
                               *(f"A,0,rate_table,{x},{x * 13771.0 + 1e-3 * x**3}" for x in rates)]) + "\n")
    assert main(["compensate", str(data), "--method", "polynomial"]) == 0
    err = capsys.readouterr().err
    assert "gyrojax compensate: warning: gyrojax: entry point 'broken'" in err and "was skipped" in err


@pytest.mark.parametrize("method, text, message", [
    ("apply", "def apply(self):\n    return None",
     "method apply\\(self\\): does not match AbstractEffect.apply\\(self, gyro"),
    ("typical", "@classmethod\ndef typical(cls, scale, extra):\n    return cls(0.0)",
     "method typical\\(cls, scale, extra\\): does not match AbstractEffect.typical"),
    ("supports", "def supports(self, gyro):\n    return True", "method supports: must be a classmethod"),
])
def test_a_wrong_method_signature_is_refused_naming_file_class_and_method(tmp_path, method, text, message):
    path = tmp_path / "wrong.py"
    body = textwrap.indent(text, "    ")
    path.write_text(effect_source("Base", "base_gain") + f"\n\nclass Wrong(Base):\n    name = 'wrong_sig'\n\n{body}\n")
    with pytest.raises(ValueError, match=f"{path}: effect class Wrong, {message}"):
        load_effects_module(path)
    assert "wrong_sig" not in gj.EFFECTS and "base_gain" not in gj.EFFECTS


def test_sys_exit_while_importing_is_a_clear_error(tmp_path):
    path = tmp_path / "exits.py"
    path.write_text("import sys\n\nsys.exit(3)\n")
    with pytest.raises(ValueError, match=f"{path}: line 3: the file called sys.exit\\(3\\) while being imported"):
        load_effects_module(path)


def test_a_file_that_registers_nothing_warns(tmp_path):
    path = tmp_path / "empty.py"
    path.write_text("import math\n\nX = math.pi\n")
    with pytest.warns(UserWarning, match=f"{path}: defines no effect class .*nothing was registered"):
        assert load_effects_module(path) == ()


NAN_APPLY = ("gyro.excitation.dac.gain_error + self.gain)",
             "gyro.excitation.dac.gain_error + self.gain * jnp.inf * 0.0)")


def test_an_effect_giving_nan_is_named(tmp_path):
    path = tmp_path / "nan_fx.py"
    path.write_text(effect_source("NanGain", "nan_gain").replace(*NAN_APPLY))
    load_effects_module(path)
    why = _plugins.nonfinite_effect("nan_gain", gj.paper_qmg())
    assert why == (f"effect 'nan_gain' (class NanGain in {path}) gives the device a non-finite value at zero: "
                   "excitation.dac.gain_error = nan")
    assert _plugins.nonfinite_effect("dac_inl", gj.paper_qmg()) is None


@pytest.mark.parametrize("argv", [
    ["simulate", "--preset", "paper-qmg", "--effect", "nan_gain=2", "--out", "o.csv"],
    ["identify", "d.csv", "--effect", "nan_gain"],
])
def test_the_cli_refuses_an_effect_giving_nan_by_name(tmp_path, monkeypatch, capsys, argv):
    from gyrojax.cli import main

    path = tmp_path / "nan_fx.py"
    path.write_text(effect_source("NanGain", "nan_gain").replace(*NAN_APPLY))
    rates = (-200, -100, -50, -10, 0, 10, 50, 100, 200)
    (tmp_path / "d.csv").write_text("\n".join(["device,run,sweep,input,output",
                                               *(f"A,0,rate_table,{x},{x * 13771.0}" for x in rates)]) + "\n")
    monkeypatch.chdir(tmp_path)
    assert main([*argv, "--effects-module", str(path)]) == 1
    err = capsys.readouterr().err
    assert (f"failed: effect 'nan_gain' (class NanGain in {path}) gives the device a non-finite value at zero: "
            "excitation.dac.gain_error = nan; an effect must give finite parameters") in err
    assert not (tmp_path / "o.csv").exists()


def test_the_user_code_digest_follows_the_modules_an_effect_imports(tmp_path, monkeypatch):
    from gyrojax._compile import export as _export, program_key as _program_key
    # gyrojax's own files are hashed into the key too: held fixed, so that only the user code varies
    monkeypatch.setattr(_program_key, "_gyrojax_files_hash", lambda: "gyrojax")
    helper = tmp_path / "gjhelper_sign.py"
    helper.write_text("SIGN = 1.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    path = tmp_path / "signed.py"
    path.write_text(effect_source().replace("import gyrojax as gj", "import gyrojax as gj\nfrom gjhelper_sign import "
                                            "SIGN").replace("+ self.gain)", "+ SIGN * self.gain)"))
    assert _plugins.user_code_digest() == ""
    key_without = _export.program_key("p", ())
    load_effects_module(path)
    first, key_first = _plugins.user_code_digest(), _export.program_key("p", ())
    assert first and key_first != key_without
    recorded = _plugins.user_effect_code(["user_gain", "dac_inl"])
    assert list(recorded) == ["user_gain"] and recorded["user_gain"]["module"] == str(path)

    # The helper is edited; a later process (here: the module loaded afresh) imports the new one.
    helper.write_text("SIGN = -1.0\n")
    del gj.EFFECTS["user_gain"]
    _plugins._loaded_files.clear()
    _plugins._sources.clear()
    for name in [m for m in sys.modules if m.startswith(("gyrojax_user_effects_", "gjhelper"))]:
        del sys.modules[name]
    load_effects_module(path)
    assert _plugins.user_code_digest() != first
    assert _export.program_key("p", ()) != key_first  # the exported program of the old helper is not served
    changes = _plugins.user_code_changes(recorded, ["user_gain"])
    assert changes == [f"effect 'user_gain': the code of its module {path} (or of a module it imports) differs "
                       f"from that of {path} when the fit was made"]


@pytest.mark.slow
def test_a_saved_fit_records_its_user_code_and_warns_when_loaded_with_other_code(tmp_path, monkeypatch):
    helper = tmp_path / "gjhelper_fit.py"
    helper.write_text("SIGN = 1.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    path = tmp_path / "fitted.py"
    path.write_text(effect_source().replace("import gyrojax as gj", "import gyrojax as gj\nfrom gjhelper_fit import "
                                            "SIGN").replace("+ self.gain)", "+ SIGN * self.gain)"))
    load_effects_module(path)
    table = gj.simulate_table(gj.paper_qmg(), devices=1, runs=1, sweeps=("rate_table",), seed=1, progress=False)
    model = gj.Model(gj.paper_qmg(), (zero_effect("user_gain"),))
    fit = gj.identify(model, table, free=("k_vf",), progress=False)
    saved = tmp_path / "u.fit"
    gj.save_fit(fit, saved)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the same code: no warning
        gj.load_fit(saved)
    helper.write_text("SIGN = -1.0\n")  # edited, and loaded afresh (as a later process would)
    del gj.EFFECTS["user_gain"]
    _plugins._loaded_files.clear()
    _plugins._sources.clear()
    for name in [m for m in sys.modules if m.startswith(("gyrojax_user_effects_", "gjhelper"))]:
        del sys.modules[name]
    load_effects_module(path)
    with pytest.warns(UserWarning, match=f"u.fit: effect 'user_gain': the code of its module {path} .*differs"):
        gj.load_fit(saved)


def test_the_exported_program_key_hashes_every_file_of_the_package():
    # an edit anywhere in gyrojax (a residual, a solver) must not be served an exported program of the old code
    from gyrojax._compile import program_key

    relative = {r.replace(os.sep, "/") for r, *_ in program_key._gyrojax_files()}
    assert {"__init__.py", "_identify/identify.py", "_diagnose/diagnose.py", "_compile/export.py"} <= relative
