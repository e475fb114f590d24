"""Device files (issue 40): a device in TOML, its units and refusals, --model FILE.toml, and identify's checked
start against what the data read directly."""

import math
import re

import equinox as eqx
import jax
import numpy as np
import pytest

import gyrojax as gj
from gyrojax._describe import describe, write_toml
from gyrojax._device.check import check_start, checked_start
from gyrojax._device.file import read_device_file
from gyrojax.cli import main


def _hex_leaves(gyro):
    return [tuple(float(v).hex() for v in np.asarray(x, dtype=float).ravel()) for x in jax.tree.leaves(gyro)]


def _edit(text, section, key, new):
    """The file with `key = ...` of `[section]` replaced by `key = new` (as a user edits it)."""
    head = f"[{section}]\n"
    i = text.index(head) + len(head)
    j = text.find("\n[", i)
    j = len(text) if j < 0 else j
    body, n = re.subn(rf"^{key} = .*$", f"{key} = {new}", text[i:j], count=1, flags=re.M)
    assert n == 1, (section, key)
    return text[:i] + body + text[j:]


@pytest.fixture(scope="module")
def qmg_text(tmp_path_factory):
    path = tmp_path_factory.mktemp("device") / "qmg.toml"
    write_toml("paper-qmg", path)
    return path.read_text()


def _write(tmp_path, text, name="my_gyro.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("preset", ["paper-qmg", "vcf-2018"])
def test_both_presets_round_trip_through_toml_bit_for_bit(tmp_path, preset):
    out = tmp_path / f"{preset}.toml"
    assert main(["describe", "--model", preset, "--toml", str(out)]) == 0
    back = gj.load_device(out)
    g = gj.preset(preset)
    assert jax.tree.structure(back) == jax.tree.structure(g)  # statics too: name, bits, demod_order, kind
    assert _hex_leaves(back) == _hex_leaves(g)
    # the file carries the preset's provenance and the default free parameters; describe reads them back
    text = out.read_text()
    assert 'unit = "rad/s"' in text and "free = true" in text
    records = {r.path: r for r in describe(str(out))}
    assert records == {r.path: r for r in describe(preset)}
    free = read_device_file(out).free
    assert set(free) == {"k_vf", "vcf_gain", "dac_gain_error", "omega_y", "q_y"} if preset == "paper-qmg" else \
        {"sense_gain", "vcf_gain", "omega_y", "q_y"}


def test_units_are_checked_and_converted(tmp_path, qmg_text):
    text = _edit(qmg_text, "resonator", "omega_x", '{ value = 9.268, unit = "kHz", provenance = "FEM rev C" }')
    text = _edit(text, "feedback_electrode", "gap", '{ value = 3.5, unit = "um" }')
    text = _edit(text, "resonator", "mass", '{ value = 2.0, unit = "mg" }')
    text = _edit(text, "resonator", "tcf", '{ value = -31.0, unit = "ppm/K" }')
    text = _edit(text, "resonator", "q_x", "5.1e5")  # a dimensionless value may be a bare number
    text = text.replace('name = "paper-qmg"', 'name = "my-gyro"')
    f = read_device_file(_write(tmp_path, text))
    g = f.device
    assert float(g.resonator.omega_x) == pytest.approx(2 * math.pi * 9268.0, rel=1e-15)
    assert float(g.feedback_electrode.gap) == pytest.approx(3.5e-6, rel=1e-15)
    assert float(g.resonator.mass) == pytest.approx(2.0e-6, rel=1e-15)
    assert float(g.resonator.tcf) == pytest.approx(-31e-6, rel=1e-15)
    assert float(g.resonator.q_x) == 5.1e5 and g.name == "my-gyro"
    assert f.provenance["resonator.omega_x"] == "FEM rev C"
    # --model FILE.toml on describe: the file's provenance, not the preset's
    assert {r.path: r for r in describe(str(f.path))}["resonator.omega_x"].provenance == "FEM rev C"


@pytest.mark.parametrize("section, key, new, match", [
    ("resonator", "omega_x", '{ value = -4634.0, unit = "Hz" }',
     r"\[resonator\] omega_x: -4634.0 Hz is impossible: a frequency is > 0"),
    ("resonator", "q_y", "0.0", r"\[resonator\] q_y: 0.0 is impossible: a quality factor is > 0"),
    ("drive_loop", "amplitude_setpoint", '{ value = 0.0, unit = "LSB" }',
     r"\[drive_loop\] amplitude_setpoint: 0.0 LSB is impossible: the AGC set-point .* holds the drive at rest"),
    ("resonator", "omega_x", '{ value = 4634.0, unit = "m" }',
     r"\[resonator\] omega_x: unit 'm' is not a unit of this leaf's quantity \(angular frequency\); accepted: "
     r"'rad/s', 'Hz'"),
    ("resonator", "mass", "1.56e-6", r"\[resonator\] mass: no unit: a value of mass needs one"),
    ("resonator", "omega_x", '{ value = 4634.0, units = "Hz" }',
     r"\[resonator\] omega_x: unknown key 'units' in the value's table; did you mean 'unit'\?"),
    ("drive_loop", "demod_order", "4.0", r"\[drive_loop\] demod_order: is a setting, not a parameter"),
    ("drive_loop", "pll_ki", '{ value = 0.0, unit = "1/s^2" }',
     r"\[drive_loop\] pll_ki: 0.0 1/s\^2 is impossible: a PI gain of a loop is > 0"),
    ("drive_loop", "center_frequency", '{ value = 4634.0, unit = "Hz", free = true }',
     r"\[drive_loop\] center_frequency: free = true on a leaf that is not a parameter a fit can free; the leaves "
     r"that can be: .*resonator.omega_x"),
])
def test_impossible_values_and_bad_entries_are_refused_by_file_section_and_key(tmp_path, qmg_text, section, key,
                                                                               new, match):
    path = _write(tmp_path, _edit(qmg_text, section, key, new))
    with pytest.raises(ValueError, match=re.escape(str(path)) + ": " + match):
        gj.load_device(path)


def test_unknown_keys_and_sections_are_refused_with_the_nearest_name(tmp_path, qmg_text):
    path = _write(tmp_path, qmg_text.replace("\nomega_x = ", "\nomgea_x = ", 1))
    with pytest.raises(ValueError, match=r"\[resonator\]: unknown key 'omgea_x'; did you mean 'omega_x'\?"):
        gj.load_device(path)
    path = _write(tmp_path, qmg_text.replace("[resonator]", "[resonater]"))
    with pytest.raises(ValueError, match=r"top level: unknown key or section 'resonater'; did you mean 'resonator'\?"):
        gj.load_device(path)
    path = _write(tmp_path, qmg_text + '\n[readout]\ndemod_cutoff = { value = 1000.0, unit = "Hz" }\n')
    with pytest.raises(ValueError, match=r"give exactly one of \[rebalance_loop\] .* or \[readout\] .*, not both"):
        gj.load_device(path)
    path = _write(tmp_path, qmg_text.replace("q_x = {", "q_x = {", 1).replace("[resonator]\n", "[resonator\n", 1))
    with pytest.raises(ValueError, match="not a valid TOML file"):
        gj.load_device(path)


def test_a_loop_that_cannot_lock_is_refused_naming_the_loop_and_why(tmp_path, qmg_text):
    g = gj.preset("paper-qmg")
    kp, ki = float(g.rebalance_loop.kp) * 10, float(g.rebalance_loop.ki) * 100  # 1 kHz natural frequency
    text = _edit(qmg_text, "rebalance_loop", "kp", f'{{ value = {kp!r}, unit = "1" }}')
    text = _edit(text, "rebalance_loop", "ki", f'{{ value = {ki!r}, unit = "1/s" }}')
    with pytest.raises(ValueError, match=r"loops: the rebalance loop \(rate and quadrature channels\) cannot lock: "
                                         r"with kp = 623.1 and ki = 2.796e\+06 behind its demodulator's 4 first-order "
                                         r"low-pass stage\(s\) at 1000 Hz, its closed loop has a pole at .* Hz that "
                                         r"grows .*natural frequency, 1000 Hz, is too close"):
        gj.load_device(_write(tmp_path, text))
    # the drive PLL likewise, behind its own demodulator
    text = _edit(qmg_text, "drive_loop", "demod_cutoff", '{ value = 30.0, unit = "Hz" }')
    with pytest.raises(ValueError, match=r"the drive PLL cannot lock"):
        gj.load_device(_write(tmp_path, text))


def test_model_takes_a_preset_or_an_existing_device_file_on_every_command(tmp_path, qmg_text, capsys):
    for command in (["describe"], ["identify", "x.csv"], ["diagnose", "x.csv"], ["plan", "x.csv"]):
        assert main(command + ["--model", "qmg"]) == 2
        err = capsys.readouterr().err
        assert "expected a preset (paper-qmg, vcf-2018) or a device file FILE.toml, got 'qmg'" in err
        assert main(command + ["--model", str(tmp_path / "none.toml")]) == 2
        assert "no device file" in capsys.readouterr().err
    assert main(["simulate", "--preset", str(tmp_path / "none.toml"), "--out", str(tmp_path / "o.csv")]) == 2
    path = _write(tmp_path, _edit(qmg_text, "resonator", "q_x", "-1.0"))
    assert main(["describe", "--model", str(path)]) == 2
    assert "q_x: -1.0 is impossible: a quality factor is > 0" in capsys.readouterr().err
    assert main(["describe", "--model", str(_write(tmp_path, qmg_text, "ok.toml"))]) == 0
    assert "resonator.omega_x" in capsys.readouterr().out


def _table(f_drive_hz, sf_lsb_per_dps, dac_volts_per_word, devices=2):
    """A hand-made table with what the checked start reads: rate tables with their PLL frequency, DAC sweeps."""
    rates = np.linspace(-200.0, 200.0, 9)
    words = np.linspace(-3e6, 3e6, 7)
    cols = {k: [] for k in ("device", "run", "sweep", "input", "output", "drive_freq_hz", "temperature_c")}
    for d in range(devices):
        for x, y, f, sweep in [(rates, -sf_lsb_per_dps * rates, f_drive_hz, "rate_table"),
                               (words, dac_volts_per_word * words, np.nan, "dac")]:
            cols["device"] += [f"d{d}"] * len(x)
            cols["run"] += [0] * len(x)
            cols["sweep"] += [sweep] * len(x)
            cols["input"] += list(x)
            cols["output"] += list(y * (1 + 1e-3 * d))
            cols["drive_freq_hz"] += [f * (1 + 1e-3 * d)] * len(x)
            cols["temperature_c"] += [25.0 if sweep == "rate_table" else np.nan] * len(x)
    return gj.Table.from_columns({k: np.asarray(v) for k, v in cols.items()})


def test_the_checked_start_names_a_design_far_from_the_data_and_moves_it(capsys):
    g = gj.preset("paper-qmg")
    sf = abs(float(g.ideal_scale_factor())) * math.pi / 180
    # data from a design with the drive resonance at 2x and a 2.5 V DAC: SF 4x (2 Ag m a w / (K_vf V per word))
    table = _table(2 * 4634.0, 4 * sf, 2.5 / 2**23 * float(g.excitation.dac.hold(2 * g.resonator.omega_x)[0]))
    readings, moved = check_start(g, table)
    by = {r.quantity: r for r in readings}
    assert by["drive resonance"].far and by["drive resonance"].text.startswith(
        "the file's drive resonance 4634 Hz, the data's 9272.6 Hz")
    assert by["DAC full scale"].far and "the file's DAC full scale 5 V, the data's 2.501 V" in by["DAC full scale"].text
    # the scale factor agrees once the drive resonance moved: not reported again
    assert not by["scale factor"].far and "the file's scale factor 13710 LSB/(deg/s) (54845 with the numbers " \
        "above moved to the data's), the data's 54867" in by["scale factor"].text
    assert float(moved.resonator.omega_x) == pytest.approx(2 * math.pi * 9272.6, rel=1e-4)
    assert float(moved.drive_loop.center_frequency) == float(moved.resonator.omega_x)
    assert float(moved.excitation.dac.full_scale) == pytest.approx(2.5, rel=2e-3)
    assert checked_start(g, table, move=False, label="gyrojax identify") is g
    err = capsys.readouterr().err
    assert "gyrojax identify: warning: the file's drive resonance 4634 Hz, the data's 9272.6 Hz" in err
    assert "--start-from-data moves resonator.omega_x, resonator.omega_y, drive_loop.center_frequency, " \
           "rebalance_loop.carrier_phase there" in err
    assert checked_start(g, table, move=True, label="gyrojax identify") is not g
    assert "moved excitation.dac.full_scale to the data's before the fit" in capsys.readouterr().err
    # a design that agrees gives no line; an open-loop file against closed-loop data is named
    assert checked_start(g, _table(4634.0, sf, 5.0 / 2**23 * 0.99998), move=False, label="x") is g
    assert capsys.readouterr().err == ""
    readings, _ = check_start(gj.preset("vcf-2018"), table)
    texts = " ".join(r.text for r in readings if r.far)
    assert "the data have a dac sweep" in texts and "the file's drive resonance 1803.2 Hz" in texts


def test_a_saved_fit_of_a_device_file_reads_back(tmp_path, qmg_text):
    path = _write(tmp_path, qmg_text.replace('name = "paper-qmg"', 'name = "my-gyro"'))
    table = gj.simulate_table(gj.load_device(path), devices=1, runs=1, seed=1, progress=False)
    fit = gj.identify(str(path), table)
    gj.save_fit(fit, tmp_path / "f.fit")  # no preset has its structure (its name): the header holds the file
    back = gj.load_fit(tmp_path / "f.fit")
    assert back.model.device.name == "my-gyro"
    assert jax.tree.structure(back) == jax.tree.structure(fit)
    assert all(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
               for a, b in zip(jax.tree.leaves(back), jax.tree.leaves(fit)))


@pytest.mark.slow
def test_a_lot_from_a_device_file_far_from_both_presets_is_diagnosed_from_it(tmp_path, qmg_text, capsys):
    # drive resonance 2x paper-qmg's (5.1x vcf-2018's), both Q 0.5x; a hidden DAC INL at its typical size
    text = qmg_text.replace('name = "paper-qmg"', 'name = "my-gyro"')
    text = _edit(text, "resonator", "omega_x", '{ value = 9268.0, unit = "Hz", provenance = "FEM rev C" }')
    text = _edit(text, "resonator", "omega_y", '{ value = 9270.0, unit = "Hz" }')
    text = _edit(text, "resonator", "q_x", '{ value = 5.1e5, unit = "1" }')
    text = _edit(text, "resonator", "q_y", '{ value = 1.7e5, unit = "1", free = true }')
    text = _edit(text, "drive_loop", "center_frequency", '{ value = 9268.0, unit = "Hz" }')
    device, lot, out = _write(tmp_path, text), tmp_path / "lot.csv", tmp_path / "diag.json"
    assert main(["simulate", "--preset", str(device), "--devices", "3", "--runs", "2", "--sweeps",
                 "rate_table,vcf_static,dac", "--effect", "dac_inl", "--seed", "5", "--out", str(lot), "--quiet"]) == 0
    assert main(["diagnose", str(lot), "--model", str(device), "--json", str(out), "--quiet"]) == 0
    diag = __import__("json").loads(out.read_text())
    assert diag["verdict"] == "explained" and diag["selected"] == ["dac_inl"]
    assert 0.8 < diag["final"]["chi2_red"] < 1.25
    capsys.readouterr()
    # from the wrong preset the checked start names the mismatch, and --start-from-data moves it before the fit
    table = gj.read_table(lot)
    readings, _ = check_start(gj.preset("paper-qmg"), table)
    drive = {r.quantity: r for r in readings}["drive resonance"]
    assert drive.far and drive.text.startswith("the file's drive resonance 4633.7 Hz, the data's 92")
    assert main(["identify", str(lot), "--model", "paper-qmg", "--effect", "dac_inl", "--start-from-data"]) == 0
    captured = capsys.readouterr()
    assert "gyrojax identify: the file's drive resonance 4633.7 Hz, the data's 92" in captured.err
    assert "moved resonator.omega_x, resonator.omega_y, drive_loop.center_frequency" in captured.err
    assert "ok: chi2_red" in captured.out and "MODEL REJECTED" not in captured.out


def test_an_open_loop_file_a_warmup_history_and_what_a_file_cannot_hold(tmp_path):
    from gyrojax._device.file import write_device_file

    g = eqx.tree_at(lambda g: g.temperature, gj.preset("vcf-2018"),
                    gj.temperature.WarmupTemperature(ambient=22.0, rise=3.5, time_constant=90.0))
    path = tmp_path / "open.toml"
    write_device_file(g, path)
    back = gj.load_device(path)
    assert jax.tree.structure(back) == jax.tree.structure(g) and _hex_leaves(back) == _hex_leaves(g)
    assert float(back.temperature.rise) == 3.5 and '[temperature]\nkind = "warmup"' in path.read_text()
    # a transimpedance front end's gain is in V/A: V/C is refused
    text = path.read_text().replace('kind = "charge"', 'kind = "transimpedance"', 1)
    path.write_text(text)
    with pytest.raises(ValueError, match=r"\[drive_frontend\] gain: unit 'V/C' is not a unit of this leaf's "
                                         r"quantity \(transimpedance\); accepted: 'V/A', 'V/uA'"):
        gj.load_device(path)
    # an open-loop file with feedback combs is refused; a device with terms cannot be written
    path.write_text(path.read_text().replace("[readout]", '[feedback_electrode]\nv_dc = { value = 5.0, unit = "V" }'
                                             '\n\n[readout]'))
    with pytest.raises(ValueError, match=r"\[feedback_electrode\]: an open-loop device \(with \[readout\]\) has no "
                                         "feedback combs"):
        gj.load_device(path)
    with_term = gj.preset("paper-qmg").with_term(gj.TemperatureCoefficient("excitation.dac.full_scale", 1e-5))
    with pytest.raises(ValueError, match=r"carries 1 term\(s\) \(TemperatureCoefficient\): a term is code"):
        write_device_file(with_term, tmp_path / "t.toml")

