"""Numbers that are not measurements (issue 36): metrics that do not apply to a sweep kind, a sign check that
refuses what a library effect can do, one rule for a dead output, scale-invariant noise estimates, diagnose's
undetermined figures, effect sizes and verdict text."""

import re

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._identify.plausibility import check_signs
from gyrojax._model.fitdata import fit_data


# ---------------------------------------------------------------------------------------------------------------
# The sign check allows what a library effect at its typical size does (the planner's revealing path).


@pytest.mark.slow
def test_sign_check_allows_a_typical_duffing_drive_on_the_drive_frequency():
    """The revealing lot of `gyrojax simulate --preset paper-qmg --sweeps rate_table,...,drive_frequency --effect
    duffing_drive --seed 13`: a cubic drive spring of typical size turns the drive frequency's slope against the
    set-point over (5.6e-8 against the design's -2.1e-8 Hz/LSB). Its sign is the effect's, not a convention's, so
    the check lets it through; a rate table read with the opposite polarity is still refused."""
    gyro = gj.add_effect(gj.preset("paper-qmg"), "duffing_drive")
    sweeps = ("rate_table", "drive_frequency")
    data = gj.simulate_table(gyro, devices=2, runs=2, sweeps=sweeps, seed=13, progress=False)
    model = gj.simulate_table(gj.preset("paper-qmg"), devices=2, runs=2, sweeps=sweeps, seed=13, noise_free=True,
                              progress=False)
    fd, predictions = fit_data(data), {s: np.asarray(model.to_arrays(s).outputs) for s in sweeps}
    check_signs(fd, predictions, "paper-qmg")
    flipped = {"rate_table": -predictions["rate_table"], "drive_frequency": predictions["drive_frequency"]}
    with pytest.raises(ValueError, match=r"opposite sign of the model 'paper-qmg'.*sweep 'rate_table', device "):
        check_signs(fd, flipped, "paper-qmg")


# ---------------------------------------------------------------------------------------------------------------
# Metrics: each sweep kind says which apply.


SETPOINTS = (2.0e6, 2.5e6, 3.0e6, 3.5e6, 4.0e6)


def _revealing_rows():
    rng = np.random.default_rng(3)
    rows = []
    for run in (0, 1):
        rows += [{"device": "A", "run": run, "sweep": "rate_table", "input": x, "output": 13771.0 * x + 5.0}
                 for x in (-100.0, -10.0, 0.0, 10.0, 100.0)]
        # the drive frequency: constant but for 1 ppm of noise; the branch ratio: 1 but for 1 ppm of noise
        rows += [{"device": "A", "run": run, "sweep": "drive_frequency", "input": x,
                  "output": 4633.9 * (1 + 1e-6 * rng.standard_normal())} for x in SETPOINTS]
        rows += [{"device": "A", "run": run, "sweep": "branch_ratio", "input": x,
                  "output": 1.00002 * (1 + 1e-6 * rng.standard_normal())} for x in (-100.0, -10.0, 10.0, 100.0)]
    return rows


def test_metrics_that_do_not_apply_to_a_sweep_kind_are_null_with_the_reason():
    """A straight line through the drive frequency against the set-point, or the branch ratio against the rate,
    measures noise (the issue's NL 34,732,882 ppm, SF -4.87e-9 Hz/LSB): null, with the kind's reason, and not
    counted as a number the data failed to give; the rate table's metrics are unchanged."""
    report = gj.metrics.metrics_report(gj.Table.from_records(_revealing_rows(), source="rev.csv"))
    points = {(p.sweep, p.run): p for p in report.points}
    rate = points["rate_table", 0]
    assert rate.scale_factor == pytest.approx(13771.0) and rate.nonlinearity_max_ppm is not None
    assert rate.not_applicable == {} and rate.undetermined == ()
    freq = points["drive_frequency", 0]
    for key in ("scale_factor", "bias", "nonlinearity_max_ppm", "nonlinearity_rms_ppm", "asymmetry_ppm"):
        assert getattr(freq, key) is None and key in freq.not_applicable
    assert freq.not_applicable["scale_factor"].startswith("not a measurement on a drive_frequency sweep: the "
                                                             "frequency changes with the set-point only by a cubic")
    assert freq.not_applicable["nonlinearity_max_ppm"] == ("not a measurement on a drive_frequency sweep (see "
                                                              "scale_factor)")
    assert freq.undetermined == ()
    ratio = points["branch_ratio", 1]
    assert ratio.bias == pytest.approx(1.00002, rel=1e-5)  # the branches' mismatch: a measurement
    assert ratio.scale_factor is None and ratio.nonlinearity_max_ppm is None
    devices = {d.sweep: d for d in report.devices}
    assert devices["rate_table"].repeatability_ppm is not None
    assert devices["drive_frequency"].repeatability_ppm is None
    assert "not a measurement on a drive_frequency sweep" in devices["drive_frequency"].not_applicable[
        "repeatability_ppm"]
    kinds = {name: gj.sweeps.sweep_kind(name).applicable_metrics() for name in gj.sweeps.SWEEP_KINDS}
    assert kinds["rate_table"] == kinds["dac"] == kinds["vcf_static"] == kinds["drive_amplitude"] == (
        "scale_factor", "bias", "nonlinearity", "asymmetry", "repeatability")
    assert kinds["vcf_dynamic"] == ("bandwidth",) and kinds["drive_frequency"] == ()


def test_metrics_command_prints_the_reason_and_exits_0_for_metrics_that_do_not_apply(tmp_path, capsys):
    from gyrojax._data.files import write_table
    from gyrojax.cli import main

    path = tmp_path / "rev.csv"
    write_table(gj.Table.from_records(_revealing_rows(), source="rev.csv"), path)
    assert main(["metrics", str(path)]) == 0
    out, err = capsys.readouterr()
    assert "drive_frequency SF n/a (not a measurement on a drive_frequency sweep: " in out
    assert "NL max" not in out.split("drive_frequency", 1)[1].split("\n", 1)[0]
    assert "gave no nonlinearity" not in err


# ---------------------------------------------------------------------------------------------------------------
# A dead output: one rule for metrics and compensate.


def test_a_constant_output_is_one_data_error_for_metrics_and_compensate(tmp_path, capsys):
    """Outputs that do not change with the rate (a disconnected or saturated output): both commands refuse the
    file with the same message and exit 2, naming the file, row, device and run."""
    from gyrojax._data.files import write_table
    from gyrojax.cli import main

    rows = [{"device": "A", "run": r, "sweep": "rate_table", "input": x, "output": 7.0 if r == 1 else 13771.0 * x,
             "drive_freq_hz": 4633.9} for r in (0, 1) for x in (-100.0, -10.0, 0.0, 10.0, 100.0)]
    path = tmp_path / "dead.csv"
    write_table(gj.Table.from_records(rows, source="dead.csv"), path)
    message = (r"dead.csv: data row 6 \(line 7\), column 'output': device 'A', run 1: the rate_table outputs are "
               r"all 7.0, the same at every rate: there is no scale factor to measure or compensate")
    errors = []
    for command in ("metrics", "compensate"):
        assert main([command, str(path), *(["--quiet"] if command == "compensate" else [])]) == 2
        errors.append(capsys.readouterr().err)
    assert re.search(message, errors[0]) and re.search(message, errors[1])
    assert errors[0].split("error: ", 1)[1] == errors[1].split("error: ", 1)[1]
    table = gj.Table.from_records(rows, source="dead.csv")
    for call in (gj.metrics.metrics_report, gj.compensate):
        with pytest.raises(gj.DataError, match=message.replace(r" \(line 7\)", "")):  # a table has no lines
            call(table)


# ---------------------------------------------------------------------------------------------------------------
# diagnose: verdict text that does not contradict its numbers (a synthetic diagnosis).


def _synthetic_diagnosis(chi2, points, share, flagged=True, verdict="partly explained"):
    from types import SimpleNamespace

    from gyrojax._diagnose.compare import Finding
    from gyrojax._diagnose.discrepancy import Discrepancy
    from gyrojax._diagnose.solution import Diagnosis, Step
    from gyrojax._numerics.stats import chi2_sf

    p = chi2_sf(chi2, points)
    finding = Finding("rate_table", "even bow", 40.0, 1, 1e-9, True, "an even (quadratic) shape: a bow")
    comparison = SimpleNamespace(chi2=chi2, points=points, p_value=p, fails=p < 0.01,
                                 flagged=(finding,) if flagged else (), to_json=dict)
    left = Discrepancy("offset_per_run", "run", "an offset that changes from run to run", (("dac", 1.0),), 40.0, 3,
                       share, 1e-9, True, 5.6e-6, 9.8e-6, "output unit", np.zeros(1))
    step = Step("dac_inl", 900.0, 0.0, 900.0, 4, 0.0, -850.0, 0.9, 2.0, (), (), None)
    fit = SimpleNamespace(chi2_total=1e6, dof_total=2e5, chi2_red_total=5.0, residuals={}, devices=("d",),
                          warnings=((),))
    final = SimpleNamespace(chi2_total=chi2, dof_total=points)
    return Diagnosis(baseline=fit, final=final, fits=(fit, final), ranking=(), steps=(step,), ambiguous=(),
                     untestable=(), rejected=(), alpha=0.01, baseline_nonlinearity_ppm=1.0,
                     comparisons=(comparison, comparison), discrepancy=(left,), verdict=verdict)


def test_verdict_text_does_not_call_a_chi2_at_the_noise_level_a_failure_nor_present_0_percent():
    """The issue's 200k-row lot: "model still fails (p = 1) ... 0 % of the misfit". At p = 1 the chi2 is no
    failure (the verdict rests on structure in the residuals, which it names), and a share that rounds to 0 % is
    not presented as where the misfit lives."""
    text = _synthetic_diagnosis(1.9e5, 200_000, 0.0).verdict_text()
    assert "fails" not in text and "0 % of the misfit" not in text
    assert "the residuals keep structure (rate_table even bow: p = 1e-09" in text
    assert "though the chi2 is at the noise level (chi2 1.9e+05 over 200000 points, p = 1)" in text
    assert "what is left: an offset that changes from run to run (dac 100 %): about 5.6e-06 output unit" in text
    assert "significant but below 1 % of the misfit" in text
    # a failing model whose leading remaining shape takes under 1 % of the misfit: not "what is left"
    text = _synthetic_diagnosis(2.7e7, 438, 0.001).verdict_text()
    assert "but the model still fails (chi2 2.7e+07 over 438 points, p = 0)" in text
    assert "no generic shape takes 1 % of what is left (the most significant: an offset" in text
    assert "0 % of the misfit" not in text
    # a share that is a finding stays one
    text = _synthetic_diagnosis(2.7e7, 438, 0.4, verdict="unexplained").verdict_text()
    assert "no library effect is confirmed and the model fails" in text
    assert "what is left: 40 % of the misfit is an offset that changes from run to run" in text


# ---------------------------------------------------------------------------------------------------------------
# diagnose of data that do not determine the scale factor: null with the reason, not NaN.


def test_diagnosis_without_a_rate_table_writes_null_nonlinearity_with_the_reason():
    """VCF rows only: no rate-table nonlinearity exists. The summary says n/a and why (was "nan ppm"), the JSON
    holds null and the reason (was NaN, which the CLI refused: exit 1)."""
    import json
    from types import SimpleNamespace

    from gyrojax._diagnose.solution import nonlinearity_not_determined

    diag = _synthetic_diagnosis(42.4, 44, 0.0, flagged=False, verdict="explained")
    fit = SimpleNamespace(chi2_red_total=1.06, chi2_total=42.4, dof_total=40, residuals={"vcf_static": np.zeros(3)},
                          scale_factor=np.array([np.nan, np.nan]), devices=("d",), warnings=((),))
    comparison = SimpleNamespace(chi2=42.4, points=44, p_value=0.54, fails=False, flagged=(), to_json=lambda: {})
    diag = type(diag)(**{**diag.__dict__, "baseline": fit, "final": fit, "fits": (fit,), "steps": (),
                         "baseline_nonlinearity_ppm": float("nan"), "comparisons": (comparison,)})
    why = "no rate_table sweep: the nonlinearity is that of the rate-table points"
    assert f"model-vs-measurement nonlinearity n/a ({why}" in diag.summary(comparisons=False)
    assert "nan" not in diag.summary(comparisons=False)
    out = json.loads(json.dumps(diag.to_json(), allow_nan=False))
    for part in ("baseline", "final"):
        assert out[part]["nonlinearity_ppm"] is None
        assert out[part]["not_determined"]["nonlinearity_ppm"].startswith(why)
    fit.residuals["rate_table"] = np.zeros(3)  # a rate table, but the scale factor is not determined
    assert nonlinearity_not_determined(fit).startswith("the data do not determine the scale factor")


@pytest.mark.slow
def test_diagnose_cli_of_vcf_rows_only_writes_json_and_report(tmp_path, capsys):
    """The issue's case end to end: `diagnose --json --report` of a VCF-only lot exits 0 (was 1 for the JSON and
    2, naming a temporary path, for the report) and writes null with the reason."""
    import json

    from gyrojax._data.files import write_table
    from gyrojax.cli import main

    table = gj.simulate_table(gj.preset("paper-qmg"), devices=2, runs=1, sweeps=("vcf_static",), seed=4,
                              progress=False)
    write_table(table, tmp_path / "vcf.csv")
    js, rep = tmp_path / "d.json", tmp_path / "rep"
    assert main(["diagnose", str(tmp_path / "vcf.csv"), "--quiet", "--json", str(js), "--report", str(rep)]) == 0
    out = capsys.readouterr().out
    assert "nonlinearity n/a (no rate_table sweep" in out and "nan" not in out
    report = json.loads(js.read_text())
    assert report["baseline"]["nonlinearity_ppm"] is None and "no rate_table" in report["baseline"]["not_determined"][
        "nonlinearity_ppm"]
    assert "| 0 | baseline | 1.0" in (rep / "diagnosis.md").read_text()
    assert "n/a (no rate_table sweep" in (rep / "diagnosis.md").read_text()


# ---------------------------------------------------------------------------------------------------------------
# diagnose: fitted effect sizes per device, with standard errors from the fit's covariance.


def test_diagnosis_gives_each_devices_fitted_effect_size_with_its_standard_error():
    """Was: "fitted at 3.1x its typical size", the largest device's value and no standard error. Now every
    device's value of every parameter of the effect, +/- its standard error, in the JSON and the summary."""
    from types import SimpleNamespace

    from gyrojax._diagnose.solution import effect_sizes

    names = ("k_vf", "dac_inl.c[0]", "dac_inl.c[1]")
    cov = np.zeros((2, 3, 3))
    cov[:, 1, 1], cov[:, 2, 2] = [0.04**2, 0.05**2], [0.1**2, 0.2**2]
    final = SimpleNamespace(
        names=names, devices=("A", "B"), free=np.array([True, True, False]), covariance=cov,
        u=np.array([[0.01, 0.98, -0.3], [0.02, 3.1, 0.1]]),
        values=np.array([[1.0, 9.8e-6, -3e-6], [1.0, 3.1e-5, 1e-6]]),
        stderr=np.array([[1e-3, 4e-7, 1e-6], [1e-3, 5e-7, 2e-6]]), chi2_total=430.0, dof_total=438,
        chi2_red_total=0.98, residuals={})
    diag = _synthetic_diagnosis(430.0, 438, 0.0, flagged=False, verdict="explained")
    diag = type(diag)(**{**diag.__dict__, "final": final, "fits": (diag.baseline, final)})
    sizes = effect_sizes(final, "dac_inl")
    assert [(s["device"], s["parameter"]) for s in sizes] == [("A", "dac_inl.c[0]"), ("A", "dac_inl.c[1]"),
                                                              ("B", "dac_inl.c[0]"), ("B", "dac_inl.c[1]")]
    assert sizes[2]["value"] == 3.1e-5 and sizes[2]["stderr"] == 5e-7
    assert sizes[2]["typical_multiple"] == 3.1 and sizes[2]["typical_multiple_stderr"] == pytest.approx(0.05)
    text = diag.summary(comparisons=False)
    assert ("  fitted, A: dac_inl.c[0] = 9.8e-06 +/- 4e-07 (0.98 +/- 0.04 x typical); held, no standard error: "
            "dac_inl.c[1]\n") in text
    assert sizes[1]["stderr"] is None and sizes[1]["typical_multiple_stderr"] is None  # held
    assert "  fitted, B: dac_inl.c[0] = 3.1e-05 +/- 5e-07 (3.1 +/- 0.05 x typical)" in text
    (step,) = diag.to_json()["steps"]
    assert step["sizes"] == sizes


# ---------------------------------------------------------------------------------------------------------------
# identify: the noise-estimated p-value does not depend on the unit of the outputs; a fit astronomically far
# from its data says so, with the scale of the outputs against the model's.


def _rate_lot(factor, keep_sigma, devices=1):
    table = gj.simulate_table(gj.preset("paper-qmg"), devices=devices, runs=2, sweeps=("rate_table",), seed=5,
                              progress=False)
    cols = {c: np.asarray(table[c]) for c in table.column_names if keep_sigma or c != "output_sigma"}
    cols["output"] = cols["output"] * factor
    return gj.Table.from_columns(cols, source=f"x{factor:g}.csv")


@pytest.mark.slow
def test_noise_estimated_p_value_does_not_depend_on_the_unit_of_the_outputs():
    """No output_sigma: outputs x1 and x100 (e.g. another LSB width) gave p = 0.34 and 7.5e-99 (device 0: the
    first fit's unit weights on outputs 100x the model's stopped it at 0.035 x k_vf's design, far from the 0.01
    the data want, and the noise estimated from its residuals came out 4.3x too large). Now the same fit, noise
    and p."""
    one, hundred = (gj.identify("paper-qmg", _rate_lot(f, keep_sigma=False, devices=2), progress=False)
                    for f in (1.0, 100.0))
    np.testing.assert_allclose(np.asarray(hundred.p_value), np.asarray(one.p_value), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(hundred.chi2), np.asarray(one.chi2), rtol=1e-6)
    assert np.all(np.asarray(one.p_value) > 0.01)
    noise = [float(re.search(r"rate_table ([0-9.e+]+) output units", " ".join(f.warnings[0])).group(1))
             for f in (one, hundred)]
    assert noise[1] == pytest.approx(100 * noise[0], rel=1e-2)  # printed to 3 digits
    assert "within 5 % of 10^-2: a unit or scaling error" in " ".join(hundred.warnings[0])


@pytest.mark.slow
def test_a_fit_astronomically_far_from_its_data_says_so_and_names_the_scale():
    """Outputs x1000 with the old output_sigma: device 0's solve stays at the design k_vf with chi2 8.5e18 and
    was reported "converged" without a word on units."""
    fit = gj.identify("paper-qmg", _rate_lot(1000.0, keep_sigma=True, devices=2), progress=False)
    assert fit.status[0] == "model rejected"
    assert "but far from the data (chi2_red" in fit.result_message[0]
    text = " ".join(fit.warnings[0])
    assert re.search(r"chi2_red [0-9.e+]+: the solve stopped .* standard errors per point from the data: this is no "
                     r"fit of them; the rate_table outputs are ~[0-9.]+x the model's: check the unit of output and "
                     r"output_sigma", text), text
    assert re.search(r"outputs are ~9[0-9]{2}x the model's", text)  # the design k_vf: ~1000x its outputs
