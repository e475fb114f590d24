"""The command line in-process: simulate -> tidy file -> metrics JSON, output paths checked before any work,
n/a instead of crashes, writes through links with the usual modes, user effects (--effects-module)."""

import json
import re

import numpy as np
import pytest

import gyrojax as gj
from gyrojax.cli import main


def test_simulate_then_metrics(tmp_path, capsys):
    out = tmp_path / "lot.csv"
    rc = main(["simulate", "--preset", "paper-qmg", "--devices", "2", "--runs", "2", "--sweeps",
               "rate_table,dac", "--effect", "dac_inl=1", "--seed", "7", "--out", str(out)])
    assert rc == 0
    table = gj.read_table(out)
    assert len(table) == 2 * 2 * 22 * 2
    assert set(table["sweep"]) == {"rate_table", "dac"}
    js = tmp_path / "m.json"
    assert main(["metrics", str(out), "--json", str(js)]) == 0
    report = json.loads(js.read_text())
    rate = [p for p in report["points"] if p["sweep"] == "rate_table"]
    assert len(rate) == 4
    # the dac_inl effect at scale 1 gives ~460 ppm of closed-loop nonlinearity (seed 000 §3.3's DAC share)
    assert all(440 < p["nonlinearity_max_ppm"] < 480 for p in rate)
    assert all(13_500 < abs(p["scale_factor"]) < 13_950 for p in rate)
    dac = [p for p in report["points"] if p["sweep"] == "dac"]
    assert all("nonlinearity_rms_ppm_vs_rate" in p for p in dac)
    assert {d["sweep"] for d in report["devices"]} >= {"rate_table"}


@pytest.mark.slow
def test_simulate_tiers_agree(tmp_path):
    a, b = tmp_path / "a.parquet", tmp_path / "b.csv"
    assert main(["simulate", "--preset", "paper-qmg", "--noise-free", "--out", str(a)]) == 0
    assert main(["simulate", "--preset", "paper-qmg", "--noise-free", "--tier", "averaged", "--out", str(b)]) == 0
    ya, yb = gj.read_table(a)["output"], gj.read_table(b)["output"]
    assert np.max(np.abs(ya - yb)) / np.max(np.abs(ya)) < 1e-6


@pytest.mark.slow
def test_simulate_is_reproducible_byte_for_byte(tmp_path):
    argv = ["simulate", "--preset", "paper-qmg", "--seed", "5"]  # with noise: the seed fixes it
    first, second, other = tmp_path / "1.csv", tmp_path / "2.csv", tmp_path / "3.csv"
    assert main([*argv, "--out", str(first)]) == 0
    assert main([*argv, "--out", str(second)]) == 0
    assert first.read_bytes() == second.read_bytes()
    assert main(["simulate", "--preset", "paper-qmg", "--seed", "6", "--out", str(other)]) == 0
    assert other.read_bytes() != first.read_bytes()  # the comparison can fail: the seed matters


def test_simulate_a_revealing_sweep(tmp_path):
    """`--sweeps drive_amplitude`: the AGC's pick-off amplitude against its set-point; with a leaky AGC integrator
    the metrics' scale factor (LSB/LSB) is 1 / (1 + beta), 13.7 ppm short of 1 on paper-qmg, within the 1 ppm
    readings' noise."""
    out = tmp_path / "agc.csv"
    assert main(["simulate", "--preset", "paper-qmg", "--sweeps", "drive_amplitude", "--effect",
                 "agc_finite_gain=1", "--seed", "2", "--out", str(out)]) == 0
    table = gj.read_table(out)
    assert set(table["sweep"]) == {"drive_amplitude"} and len(table) == len(gj.sweeps.SETPOINT_RATIOS)
    js = tmp_path / "m.json"
    assert main(["metrics", str(out), "--json", str(js)]) == 0
    (point,) = json.loads(js.read_text())["points"]
    assert (point["scale_factor"] - 1.0) * 1e6 == pytest.approx(-13.7, abs=3.0)


@pytest.mark.parametrize("argv,message", [
    (["simulate", "--preset", "paper-qmg", "--effect", "nope", "--out", "x.csv"], "unknown effect 'nope'"),
    (["simulate", "--preset", "vcf-2018", "--sweeps", "dac", "--out", "x.csv"], "needs a closed-loop device"),
    (["simulate", "--preset", "vcf-2018", "--sweeps", "branch_ratio", "--out", "x.csv"],
     "a branch_ratio sweep needs a closed-loop device"),
    (["simulate", "--preset", "paper-qmg", "--sweeps", "vcf_teleport", "--out", "x.csv"], "cannot simulate sweep"),
    (["simulate", "--preset", "paper-qmg", "--out", "x.txt"], "--out: cannot tell the format of 'x.txt'"),
    (["simulate", "--preset", "paper-qmg", "--devices", "0", "--out", "x.csv"], "--devices expects a whole number"),
    (["metrics", "does-not-exist.csv"], "does-not-exist.csv: No such file or directory"),
])
def test_user_errors_exit_2(tmp_path, monkeypatch, capsys, argv, message):
    # In-process: exit code and message. That no traceback is printed is checked in test_cli_subprocess.py.
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert not (tmp_path / "x.csv").exists()


# ---------------------------------------------------------------------------------------------------------------
# Output paths are checked before any data is read or any work is done.


@pytest.fixture
def no_work(monkeypatch):
    """Make reading data, simulating, diagnosing and the demo fail the test if they are reached."""
    def reached(*args, **kwargs):
        raise AssertionError("work was started before the output paths were checked")

    from gyrojax import _diagnose
    from gyrojax._cli import demo_job as _demo
    from gyrojax._data import files as data_files
    from gyrojax._lots import campaign as _campaign
    monkeypatch.setattr(data_files, "read_table", reached)
    monkeypatch.setattr(_campaign, "simulate_table", reached)
    monkeypatch.setattr(_diagnose, "diagnose", reached)
    monkeypatch.setattr(_demo, "run_demo", reached)


@pytest.mark.parametrize("argv, message", [
    (["simulate", "--preset", "paper-qmg", "--out", "nodir/o.csv"], "--out nodir/o.csv: the folder {t}/nodir does "
                                                                     "not exist; create it first."),
    (["simulate", "--preset", "paper-qmg", "--out", "adir.csv"], "--out adir.csv: is an existing folder"),
    (["metrics", "data.csv", "--json", "nodir/m.json"], "--json nodir/m.json: the folder {t}/nodir does not exist"),
    (["compensate", "data.csv", "--json", "adir.csv"], "--json adir.csv: is an existing folder; give a file path."),
    (["identify", "data.csv", "--save", "nodir/f.fit"], "--save nodir/f.fit: the folder {t}/nodir does not exist"),
    (["identify", "data.csv", "--json", "same", "--save", "same"], "--save same: --json writes the same path"),
    (["diagnose", "data.csv", "--report", "afile"], "--report afile: is an existing file, not a folder"),
    (["diagnose", "data.csv", "--report", "foreign"], "--report foreign: is an existing folder that gyrojax did not "
                                                      "write"),
    (["diagnose", "data.csv", "--json", "nodir/d.json"], "--json nodir/d.json: the folder {t}/nodir does not exist"),
    (["demo", "--out", "afile"], "--out afile: is an existing file, not a folder"),
])
def test_output_paths_are_checked_first(tmp_path, monkeypatch, capsys, no_work, argv, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "adir.csv").mkdir()
    (tmp_path / "afile").write_text("not a folder")
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "thesis.tex").write_text("precious")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"gyrojax {argv[0]}: error: " + message.format(t=tmp_path) in err
    assert (tmp_path / "foreign" / "thesis.tex").read_text() == "precious"
    assert (tmp_path / "afile").read_text() == "not a folder"


@pytest.mark.parametrize("alpha", ["5", "0", "-0.1", "0.51", "nan", "x"])
def test_alpha_outside_0_to_half_is_refused(tmp_path, capsys, no_work, alpha):
    assert main(["diagnose", str(tmp_path / "data.csv"), "--alpha", alpha]) == 2
    err = capsys.readouterr().err
    assert "argument --alpha: --alpha" in err and "(0, 0.5]" in err


# ---------------------------------------------------------------------------------------------------------------
# Numbers that are not applicable are printed as n/a with the reason, never as a crash.


def _write_csv(path, rows):
    path.write_text("\n".join(["device,run,sweep,input,output,drive_freq_hz",
                               *(",".join(map(str, r)) for r in rows)]) + "\n")
    return path


RATES = (-200, -150, -100, -50, -20, -10, 0, 10, 20, 50, 100, 150, 200)


def test_metrics_on_constant_outputs_is_a_data_error(tmp_path, capsys):
    """A rate table whose outputs do not change (a dead output): refused by name, exit 2, as compensate does."""
    data = _write_csv(tmp_path / "flat.csv", [("A", r, "rate_table", x, 0.0, 4000.0) for r in (0, 1) for x in RATES])
    js = tmp_path / "m.json"
    assert main(["metrics", str(data), "--json", str(js)]) == 2
    err = capsys.readouterr().err
    assert ("flat.csv: data row 1 (line 2), column 'output': device 'A', run 0: the rate_table outputs are all 0.0"
        in err)
    assert not js.exists()


@pytest.mark.parametrize("method", ["polynomial", "composite"])
def test_compensate_refuses_a_dead_run_by_name(tmp_path, capsys, method):
    """A run whose outputs do not change with the rate has no scale factor to compensate: refused before any
    fit (exit 2), naming the file, row, device and run, rather than reporting a compensated figure from
    round-off; nothing is written."""
    rows = [("A", 0, "rate_table", x, x * 13771.0 + 1e-3 * x**3, 4000.0 + 1e-4 * x) for x in RATES]
    rows += [("A", 1, "rate_table", x, 7.0, 4000.0) for x in RATES]  # a dead run: nothing changes
    data = _write_csv(tmp_path / "dead.csv", rows)
    js = tmp_path / "c.json"
    assert main(["compensate", str(data), "--method", method, "--json", str(js)]) == 2
    err = capsys.readouterr().err
    assert re.search(r"dead.csv: data row \d+ \(line \d+\), column 'output': device 'A', run 1: the rate_table "
                     r"outputs are all 7.0, the same at every rate", err)
    assert "Traceback" not in err and not js.exists()


# ---------------------------------------------------------------------------------------------------------------
# Well-behaved writes through the command line.


def _good_csv(tmp_path):
    return _write_csv(tmp_path / "good.csv", [("A", r, "rate_table", x, x * (13771.0 + r) + 1e-3 * x**3, 4000.0)
                                              for r in (0, 1) for x in RATES])


def test_json_through_a_symlink_and_file_modes(tmp_path, capsys):
    from gyrojax._data import io as _io
    data = _good_csv(tmp_path)
    target = tmp_path / "kept.json"
    target.write_text("{}")
    target.chmod(0o640)
    link = tmp_path / "link.json"
    link.symlink_to("kept.json")
    assert main(["metrics", str(data), "--json", str(link)]) == 0
    assert link.is_symlink() and len(json.loads(target.read_text())["points"]) == 2
    assert target.stat().st_mode & 0o777 == 0o640  # a replaced file keeps its mode
    new = tmp_path / "new.json"
    assert main(["metrics", str(data), "--json", str(new)]) == 0
    assert new.stat().st_mode & 0o777 == 0o666 & ~_io._UMASK  # was 0600
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.csv", "kept.json", "link.json", "new.json"]


# ---------------------------------------------------------------------------------------------------------------
# User effects: --effects-module FILE.py.


USER_EFFECT = """
import equinox as eqx
import jax
import jax.numpy as jnp

import gyrojax as gj


class UserDacGain(gj.AbstractEffect):
    gain: jax.Array = eqx.field(converter=lambda v: jnp.asarray(v, dtype=float))

    name = "user_dac_gain"
    description = "gain error of the FTR DAC's voltage reference, relative"
    plugs_into = "excitation.dac.gain_error"

    @classmethod
    def supports(cls, gyro):
        return gyro.closed_loop

    def apply(self, gyro):
        return eqx.tree_at(lambda g: g.excitation.dac.gain_error, gyro, gyro.excitation.dac.gain_error + self.gain)

    @classmethod
    def typical(cls, scale=1.0):
        return cls(scale * 5e-4)
"""


@pytest.fixture
def user_effects():
    """Registered effects are global: remove what a test added."""
    import sys

    from gyrojax._effects import plugins as _plugins

    effects, files, modules = dict(gj.EFFECTS), dict(_plugins._loaded_files), set(sys.modules)
    yield
    for name in set(gj.EFFECTS) - set(effects):
        del gj.EFFECTS[name]
    _plugins._loaded_files.clear()
    _plugins._loaded_files.update(files)
    for name in set(sys.modules) - modules:
        if name.startswith("gyrojax_user_effects_"):
            del sys.modules[name]


def test_effects_module_end_to_end(tmp_path, user_effects):
    module = tmp_path / "my_effects.py"
    module.write_text(USER_EFFECT)
    base, shifted = tmp_path / "base.csv", tmp_path / "shifted.csv"
    assert main(["simulate", "--preset", "paper-qmg", "--noise-free", "--out", str(base)]) == 0
    assert main(["simulate", "--preset", "paper-qmg", "--noise-free", "--effects-module", str(module),
                 "--effect", "user_dac_gain=2", "--out", str(shifted)]) == 0
    y0, y1 = gj.read_table(base)["output"], gj.read_table(shifted)["output"]
    big = np.abs(y0) > 1e3
    np.testing.assert_allclose(y1[big] / y0[big], 1 / (1 + 2 * 5e-4), rtol=1e-7)  # the documented fingerprint
    assert "user_dac_gain" in gj.supported_effects(gj.paper_qmg())  # a diagnose candidate now
    assert "user_dac_gain" not in gj.supported_effects(gj.vcf_2018())  # open loop: supports says no
    from gyrojax._model.parameters import zero_effect

    assert zero_effect("user_dac_gain").name == "user_dac_gain"  # what identify --effect builds


@pytest.mark.parametrize("text, message", [
    (None, "{f}: no such file"),
    ("def broken(:\n", "{f}: line 1: syntax error"),
    ("import gyrojax\n\nx = 1\nraise RuntimeError('no DAC here')\n",
     "{f}: line 4: importing it failed: RuntimeError: no DAC here"),
    (USER_EFFECT.replace("cls(scale * 5e-4)", "cls(scale * 5e-4 + 1.0)"),
     "{f}: effect class UserDacGain cannot be registered: effect class UserDacGain: typical(0.0) must be"),
    (USER_EFFECT.replace('name = "user_dac_gain"', 'name = "dac_inl"'),
     "{f}: effect class UserDacGain cannot be registered: effect name 'dac_inl' is already registered"),
])
def test_effects_module_errors_name_the_file(tmp_path, capsys, user_effects, no_work, text, message):
    module = tmp_path / "fx.py"
    if text is not None:
        module.write_text(text)
    argv = ["simulate", "--preset", "paper-qmg", "--effects-module", str(module), "--out", str(tmp_path / "o.csv")]
    assert main(argv) == 2
    assert f"gyrojax simulate: error: {message.format(f=module)}" in capsys.readouterr().err
    assert gj.EFFECTS["dac_inl"].__module__.startswith("gyrojax.")  # a built-in is never replaced


@pytest.mark.slow
def test_demo_writes_its_report(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--no-full"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]  # built aside, renamed into place whole
    summary = json.loads((out / "summary.json").read_text())
    assert summary["table2"]["rate"]["rms_ppm"] == pytest.approx(465.3, abs=0.5)
    tiers = summary["tiers"]
    assert abs(tiers["averaged"]["scale_factor_lsb_per_dps"] / tiers["steady"]["scale_factor_lsb_per_dps"] - 1) < 1e-6
    assert summary["seed003"]["bandwidth_model_hz"] == pytest.approx(96.8, abs=0.5)
    # the main job: the hidden effect is found and the error falls to the noise
    assert summary["diagnosis"]["found"] is True
    assert summary["diagnosis"]["selected"] == ["dac_inl"]
    assert 0.7 <= summary["diagnosis"]["final"]["chi2_red"] <= 1.4
    assert (out / "diagnosis" / "diagnosis.md").stat().st_size > 0
    for name in ("report.md", "nonlinearity_tiers.png", "vcf2018_rate_response.png"):
        assert (out / name).stat().st_size > 0
