"""Rough edges of the command line met by a new user and by hostile inputs (issue 36): a user effect that
gives NaN as a diagnose candidate, and names from data files that carry newlines or terminal escapes."""

import textwrap

import pytest

import gyrojax as gj
from gyrojax._effects import plugins as _plugins
from gyrojax._text import safe_name, safe_text
from gyrojax.cli import main


NAN_EFFECT = textwrap.dedent('''
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import gyrojax as gj


    class NanGain(gj.AbstractEffect):
        gain: jax.Array = eqx.field(converter=lambda v: jnp.asarray(v, dtype=float))

        name = "nan_gain"
        description = "a DAC gain error written with a bug: NaN at every size"
        plugs_into = "excitation.dac.gain_error"

        @classmethod
        def supports(cls, gyro):
            return gyro.closed_loop

        def apply(self, gyro):
            return eqx.tree_at(lambda g: g.excitation.dac.gain_error, gyro, self.gain * jnp.inf * 0.0)

        @classmethod
        def typical(cls, scale=1.0):
            return cls(scale * 5e-4)
''')

RATES = (-200, -100, -50, -20, -10, 0, 10, 20, 50, 100, 200)


def rate_table(path, names=("A", "B")):
    rows = ["device,run,sweep,input,output"]
    for i, d in enumerate(names):
        rows += [f'"{d}",0,rate_table,{x},{(13771.0 - 50 * i) * x + 2e-3 * x**3 + 4.0}' for x in RATES]
    path.write_text("\n".join(rows) + "\n")


@pytest.fixture
def registry():
    effects, files = dict(gj.EFFECTS), dict(_plugins._loaded_files)
    sources, origins = dict(_plugins._sources), dict(_plugins._origins)
    yield
    for name in set(gj.EFFECTS) - set(effects):
        del gj.EFFECTS[name]
    _plugins._loaded_files.clear()
    _plugins._loaded_files.update(files)
    _plugins._sources.clear()
    _plugins._sources.update(sources)
    _plugins._origins.clear()
    _plugins._origins.update(origins)


@pytest.mark.slow
def test_diagnose_drops_a_candidate_giving_nan_with_a_note(tmp_path, capsys, registry):
    fx = tmp_path / "nan_fx.py"
    fx.write_text(NAN_EFFECT)
    rate_table(tmp_path / "d.csv")
    assert main(["diagnose", str(tmp_path / "d.csv"), "--effects-module", str(fx), "--quiet"]) in (0, 1)
    printed = capsys.readouterr().out
    assert (f"nan_gain: effect 'nan_gain' (class NanGain in {fx}) gives the device a non-finite value at zero: "
            "excitation.dac.gain_error = nan: dropped from the candidates") in printed
    assert "verdict: " in printed  # the diagnosis went on without it


def test_safe_name_and_text_escape_controls_and_keep_the_rest():
    assert safe_name("A\nverdict: explained\x1b[2J\u202e") == "A\\nverdict: explained\\x1b[2J\\u202e"
    assert safe_name("Gyro-7 ü µ") == "Gyro-7 ü µ"
    text = "device A\nB: ok\nnext \x1b[31mred"
    assert safe_text(text, ["A\nB", "C"]) == "device A\\nB: ok\nnext \\x1b[31mred"
    assert safe_text("one\ntwo", ["\n"]) == "one\ntwo"  # a name of newlines only leaves the lines alone


HOSTILE = ('"A\ngyrojax metrics: 2 sweep(s) passed (fake)"', '"B\x1b[2J\u202e"')


def test_metrics_prints_device_names_with_newlines_and_escapes_escaped(tmp_path, capsys):
    rates = (-10, -5, 0, 5, 10)
    rows = ["device,run,sweep,input,output"]
    for d in HOSTILE:
        rows += [f"{d},0,rate_table,{x},{13771.0 * x + 1e-3 * x**3}" for x in rates]
    (tmp_path / "names.csv").write_text("\n".join(rows) + "\n")
    assert main(["metrics", str(tmp_path / "names.csv")]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert len(lines) == 2 and not any(ln.startswith("gyrojax metrics") for ln in lines)
    assert "\x1b" not in out and "\u202e" not in out
    assert lines[0].startswith("A\\ngyrojax metrics: 2 sweep(s) passed (fake) run 0")
    assert lines[1].lstrip().startswith("B\\x1b[2J\\u202e run 0")
