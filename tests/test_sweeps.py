"""Sweep kinds as objects: the registry, what each kind declares, and a new experiment added in one file.

The new experiment here is a rate table run with a constant virtual rate on the virtual-Coriolis electrode
(V_ac fixed, the table rate swept): it checks that the Coriolis force of a real and of a virtual rate add. It
lives in one file (`tests/_virtual_rate_sweep.py`), registers itself, and goes through the simulator, a CSV
file and the data layer.
"""

import re

import numpy as np
import pytest
from _virtual_rate_sweep import RateTableWithVirtualRate

import gyrojax as gj


@pytest.fixture
def registered():
    gj.sweeps.register_sweep(RateTableWithVirtualRate)
    yield RateTableWithVirtualRate
    del gj.sweeps.SWEEP_KINDS[RateTableWithVirtualRate.name]


def test_registry_holds_the_data_formats_kinds_in_order():
    assert tuple(gj.sweeps.SWEEP_KINDS) == (
        "rate_table", "vcf_static", "vcf_dynamic", "dac", "quadrature_injection", "drive_amplitude",
        "drive_frequency", "setpoint_zero_rate", "branch_ratio")
    for gone in ("SWEEPS", "SIMULATED_SWEEPS", "sweep_names"):  # one list of the kinds, not four
        assert not hasattr(gj, gone)
    kinds = [gj.sweeps.sweep_kind(name) for name in gj.sweeps.SWEEP_KINDS]
    assert [type(k) for k in kinds] == [gj.sweeps.RateTable, gj.sweeps.VcfStatic, gj.sweeps.VcfDynamic, gj.sweeps.Dac,
                                        gj.sweeps.QuadratureInjection, gj.sweeps.DriveAmplitude,
                                        gj.sweeps.DriveFrequency, gj.sweeps.SetpointZeroRate, gj.sweeps.BranchRatio]
    assert [k.biased for k in kinds] == [True, True, False, False, True, False, False, True, False]
    assert [k.scale_factor_unit for k in kinds] == ["LSB/(deg/s)", "LSB/V", None, "V/LSB", "LSB/V", "LSB/LSB",
                                                    "Hz/LSB", "LSB/LSB", "(V/V)/(deg/s)"]
    assert gj.sweeps.sweep_kind(kinds[1]) is kinds[1]
    # each kind's random stream is its own number (the registry's positions when streams were positions, so
    # simulated tables did not change), not where it stands in a list
    assert [k.stream for k in kinds] == list(range(9))
    assert [k.reads for k in kinds] == [(), (), ("angular_gain",)] + [()] * 3 + [("omega_x",)] + [()] * 2
    with pytest.raises(ValueError, match="unknown sweep 'rate-table' \\(did you mean 'rate_table'\\?\\)"):
        gj.sweeps.sweep_kind("rate-table")


def test_register_sweep_refuses_a_bad_class():
    with pytest.raises(ValueError, match="expects a subclass of gyrojax.AbstractSweep"):
        gj.sweeps.register_sweep(int)

    class NoTitle(RateTableWithVirtualRate):
        title = ""

    with pytest.raises(ValueError, match="class attribute 'title' must be a non-empty string"):
        gj.sweeps.register_sweep(NoTitle)

    class Taken(RateTableWithVirtualRate):
        name = "dac"

    with pytest.raises(ValueError, match="sweep name 'dac' is already registered by Dac"):
        gj.sweeps.register_sweep(Taken)

    class SameStream(RateTableWithVirtualRate):
        stream = 3

    with pytest.raises(ValueError, match="stream 3 is already the random stream of 'dac'"):
        gj.sweeps.register_sweep(SameStream)

    class NoStream(RateTableWithVirtualRate):
        stream = -1

    with pytest.raises(ValueError, match="'stream' must be a non-negative integer"):
        gj.sweeps.register_sweep(NoStream)
    assert "rate_table_vcf_offset" not in gj.sweeps.SWEEP_KINDS


def test_the_data_format_page_is_the_sweep_classes():
    """docs/data_format.md's table of what `input` and `output` mean is the classes' own text."""
    import pathlib

    page = (pathlib.Path(__file__).resolve().parents[1] / "docs" / "data_format.md").read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\| `(\w+)` \| (.+ \| .+) \|$", page, flags=re.M))
    for name in gj.sweeps.SWEEP_KINDS:
        kind = gj.sweeps.sweep_kind(name)
        assert rows[name] == f"{kind.input_meaning} | {kind.output_meaning}", name


def test_a_new_experiment_is_one_file(registered, tmp_path):
    """Register the new kind, simulate it beside the rate table, write and read the CSV, and get it back
    through the data layer: the virtual rate shows as an offset of the rate output by the rate it stands
    for, the scale factor stays the rate table's."""
    rates = (-100.0, -10.0, 10.0, 100.0)
    table = gj.simulate_table(gj.paper_qmg(), sweeps=(gj.sweeps.RateTable(rates), registered(rates_dps=rates)),
                              noise_free=True, progress=False)
    path = tmp_path / "offset.csv"
    gj.write_table(table, path)
    back = gj.read_table(path)
    assert back.equals(table)
    assert sorted(set(back["sweep"].tolist())) == ["rate_table", "rate_table_vcf_offset"]
    plain, offset = back.to_arrays("rate_table"), back.to_arrays(registered.name)
    shift = np.asarray(offset.outputs - plain.outputs)[0, 0]
    np.testing.assert_allclose(shift, shift[0], rtol=1e-4)  # the two Coriolis forces add
    assert abs(shift[0]) > 1e3
    report = gj.metrics.metrics_report(back)
    sf = {p.sweep: p.scale_factor for p in report.points}
    np.testing.assert_allclose(sf[registered.name], sf["rate_table"], rtol=1e-4)
    assert report.conventions.scale_factor_units[registered.name] == "LSB/(deg/s)"


def test_an_unregistered_name_is_refused_by_the_data_layer(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("device,run,sweep,input,output\nA,0,rate_table_vcf_offset,1,2\n", encoding="utf-8")
    with pytest.raises(gj.DataError, match="data row 1 \\(line 2\\), column 'sweep': unknown sweep "
                                           "'rate_table_vcf_offset'"):
        gj.read_table(path)


@pytest.mark.slow
def test_a_lot_of_a_nearby_size_reuses_the_compiled_settle(monkeypatch):
    """simulate_table pads a lot of up to 16 devices to the next power of two for its settle (copies of the last
    device, dropped): 4 devices after 3 settle in the same compiled program, and the 3 devices' outputs are
    those of the unpadded settle bit for bit."""
    import jax

    from gyrojax._lots import stack as _lot
    traces = []

    def listen(event, secs, fun_name="", **kw):
        if event.endswith("jaxpr_trace_duration") and "_lot_steady" in str(fun_name):
            traces.append(fun_name)

    small = dict(runs=1, seed=5, rates_dps=(-100.0, -10.0, 10.0, 100.0), progress=False)
    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        three = gj.simulate_table(gj.paper_qmg(), devices=3, **small)
        gj.simulate_table(gj.paper_qmg(), devices=4, **small)
        assert len(traces) == 1
        monkeypatch.setattr(_lot, "BUCKET_MAX", 0)
        plain = gj.simulate_table(gj.paper_qmg(), devices=3, **small)
        assert len(traces) == 2  # unpadded, 3 devices are another shape
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    np.testing.assert_array_equal(np.asarray(plain["output"]), np.asarray(three["output"]))
