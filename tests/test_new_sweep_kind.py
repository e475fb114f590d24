"""A sweep kind defined here, in the test file, taken through the whole house without touching `gyrojax/`:
simulate, CSV, identify, diagnose and plan.

The kind sweeps the virtual-Coriolis *carrier* V_fc at a fixed V_ac (the static VCF sweep sweeps V_ac at a fixed
carrier): another stimulus whose scale factor is the rate path's. Everything it needs is its own: its points and
settings (fields), its random stream (a class constant), what it applies (`stimulus`); the registry adds it to
the one list of kinds.
"""

import numpy as np
import pytest

import gyrojax as gj


class VcfCarrier(gj.sweeps.AbstractSteadySweep):
    """The carrier V_fc stepped at a fixed V_ac on the virtual-Coriolis electrode, zero table rate, the settled
    rate output read."""

    carriers_v: tuple = gj.sweeps.points_field((-1.0, -0.5, 0.5, 1.0), "carrier voltages (V)")
    ac_v: float = 0.5

    name = "vcf_carrier"
    stream = 40
    title = "VCF-carrier"
    input_quantity = "carrier voltage V_fc"
    input_unit = "V"
    output_unit = "LSB"
    input_meaning = "the VCF carrier V_fc, V, at V_ac = 0.5 V and zero table rate"
    output_meaning = "the gyro's rate output, LSB"
    rate_output = True

    def inputs(self, gyro=None):
        return np.asarray(self.carriers_v)

    def n_points(self):
        return len(self.carriers_v)

    def check_device(self, gyro):
        if float(np.asarray(gyro.vcf_electrode.force_per_volt2)) == 0.0:
            raise ValueError(f"a vcf_carrier sweep needs a virtual-Coriolis electrode; {gyro.name!r} has none.")

    def stimulus(self, value, time):
        return gj.physics.Stimulus(rate=0.0 * value, vcf_ac=0.0 * value + self.ac_v, vcf_fc=value, time=time)


RATES = (-200.0, -50.0, 50.0, 200.0)


@pytest.fixture(scope="module")
def registered():
    gj.sweeps.register_sweep(VcfCarrier)
    yield VcfCarrier
    del gj.sweeps.SWEEP_KINDS[VcfCarrier.name]


@pytest.fixture(scope="module")
def lot(registered, tmp_path_factory):
    table = gj.simulate_table(gj.paper_qmg(), devices=2, runs=1, sweeps=(gj.sweeps.RateTable(RATES), registered()),
                              seed=3, progress=False)
    path = tmp_path_factory.mktemp("new_kind") / "lot.csv"
    gj.write_table(table, path)
    return table, gj.read_table(path)


@pytest.mark.slow
def test_a_kind_defined_in_a_test_goes_through_simulate_csv_identify_diagnose_and_plan(registered, lot):
    table, back = lot
    # simulate and CSV: its rows, its inputs, read back as written
    assert back.equals(table)
    rows = np.asarray(back["sweep"]) == "vcf_carrier"
    assert rows.sum() == 2 * 4 and np.asarray(back["input"])[rows].tolist() == [-1.0, -0.5, 0.5, 1.0] * 2
    # its stream is its own: the rate table's noise does not depend on it being simulated beside it
    alone = gj.simulate_table(gj.paper_qmg(), devices=2, runs=1, sweeps=(gj.sweeps.RateTable(RATES),), seed=3,
                              progress=False)
    np.testing.assert_array_equal(np.asarray(alone["output"]), np.asarray(back["output"])[~rows])
    # the virtual rate is proportional to the carrier: the output is a straight line through the run's bias
    arr = back.to_arrays("vcf_carrier")
    x, y = np.asarray(arr.inputs)[0, 0], np.asarray(arr.outputs)[0, 0]
    slope = np.polyfit(x, y, 1)[0]
    assert abs(slope) > 1e4 and np.std(y - np.polyval(np.polyfit(x, y, 1), x)) < 1e-3 * abs(slope)

    # identify fits it with the rate table: both sweeps' residuals at the noise
    fit = gj.identify("paper-qmg", back, progress=False)
    assert set(fit.residuals) == {"rate_table", "vcf_carrier"}
    assert all(s == "ok" for s in fit.status), fit.warnings
    assert 0.2 < float(np.mean(np.asarray(fit.chi2_red))) < 3.0

    # diagnose: nothing hidden, the baseline explains it
    d = gj.diagnose("paper-qmg", back, candidates=("vref_drift",), fit=fit, progress=False)
    assert d.selected == () and d.verdict == "explained"
    assert "vcf_carrier" in str(d.to_json())

    # plan: a registered kind is a default candidate experiment, its points its own, its timing the protocol's
    new = next(e for e in gj.default_experiments(gj.paper_qmg()) if e.kind == "vcf_carrier")
    assert new.inputs == (-1.0, -0.5, 0.5, 1.0) and new.biased
    assert new.minutes == pytest.approx((60 + 4 * 120) / 60)
    p = gj.plan(fit=d.baseline, candidates=("vref_drift",), experiments=(new,), max_repeats=1, scale_factor=False,
                progress=False)
    assert [e.kind for e in p.experiments] == ["vcf_carrier"]
    assert p.candidate("vref_drift").effect == "vref_drift"
