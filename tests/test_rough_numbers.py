"""Numbers that are not measurements (issue 36): metrics that do not apply to a sweep kind, a sign check that
refuses what a library effect can do, one rule for a dead output, scale-invariant noise estimates, diagnose's
undetermined figures, effect sizes and verdict text."""

import re

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._fitdata import fit_data
from gyrojax._identify.plausibility import check_signs


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
    report = gj.metrics_report(gj.Table.from_records(_revealing_rows(), source="rev.csv"))
    points = {(p["sweep"], p["run"]): p for p in report["points"]}
    rate = points["rate_table", 0]
    assert rate["scale_factor"] == pytest.approx(13771.0) and rate["nonlinearity_max_ppm"] is not None
    assert rate["not_applicable"] == {} and rate["undetermined"] == []
    freq = points["drive_frequency", 0]
    for key in ("scale_factor", "bias", "nonlinearity_max_ppm", "nonlinearity_rms_ppm", "asymmetry_ppm"):
        assert freq[key] is None and key in freq["not_applicable"]
    assert freq["not_applicable"]["scale_factor"].startswith("not a measurement on a drive_frequency sweep: the "
                                                             "frequency changes with the set-point only by a cubic")
    assert freq["not_applicable"]["nonlinearity_max_ppm"] == ("not a measurement on a drive_frequency sweep (see "
                                                              "scale_factor)")
    assert freq["undetermined"] == []
    ratio = points["branch_ratio", 1]
    assert ratio["bias"] == pytest.approx(1.00002, rel=1e-5)  # the branches' mismatch: a measurement
    assert ratio["scale_factor"] is None and ratio["nonlinearity_max_ppm"] is None
    devices = {d["sweep"]: d for d in report["devices"]}
    assert devices["rate_table"]["repeatability_ppm"] is not None
    assert devices["drive_frequency"]["repeatability_ppm"] is None
    assert "not a measurement on a drive_frequency sweep" in devices["drive_frequency"]["not_applicable"][
        "repeatability_ppm"]
    kinds = {name: gj.sweep_kind(name).applicable_metrics() for name in gj.SWEEP_KINDS}
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
    for call in (gj.metrics_report, gj.compensate):
        with pytest.raises(gj.DataError, match=message.replace(r" \(line 7\)", "")):  # a table has no lines
            call(table)
