"""The recorded drive frequency as a witness (`gyrojax._diagnose.record`): an effect whose refit moves the
modelled PLL frequency is not confirmed where the recorded `drive_freq_hz` stands still, and is where the record
moves with it. The lots come from the independent generator (experiments/_discovery_lot.py, plain numpy): a
gain that follows the drive-frequency reading (outside the library) has thermal_drift's shape on the output,
but leaves the frequency where the nominal TCF puts it; a true extra TCF moves both."""

import sys
from pathlib import Path

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._diagnose.record import slope_with_offsets


sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


def test_the_slope_with_offsets_per_device_and_its_standard_error_are_calibrated():
    """y = a_d + beta x + e, offsets per device far larger than the slope's signal: over 400 draws the
    estimate is unbiased and its z-score has SD ~1; no spread of x within the groups gives None."""
    rng = np.random.default_rng(0)
    zs = []
    for _ in range(400):
        dev = np.repeat(np.arange(6), 20)
        x = rng.normal(size=dev.size) * 1e-5
        y = 0.3 * x + 1e-3 * rng.normal(size=6)[dev] + 2e-7 * rng.normal(size=dev.size)
        beta, se = slope_with_offsets(x, y, dev)
        zs.append((beta - 0.3) / se)
    assert abs(np.mean(zs)) < 0.15 and 0.9 < np.std(zs) < 1.1
    assert slope_with_offsets(np.ones(12), np.arange(12.0), np.repeat(np.arange(4), 3)) is None
    assert slope_with_offsets([0.0, 1.0, 2.0], [0.0, 1.0, 2.0], [0, 0, 0]) is None  # one degree of freedom


@pytest.mark.slow
@pytest.mark.parametrize("design", ["a", "b"])
def test_a_gain_following_the_frequency_reading_is_not_taken_for_an_extra_tcf(design):
    """drive_freq_gain (outside the library) on both designs: thermal_drift is not confirmed, and the reason
    is the record (the refit moves the modelled frequency by tens of ppm, the record shows ~0 of it)."""
    table, _ = discovery_lot("drive_freq_gain", snr="mid", design=design, seed=0)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert "thermal_drift" not in [s.effect for s in d.steps]
    (r,) = [r for r in d.rejected if r.effect == "thermal_drift"]
    assert r.kind == "contradicted by drive_freq_hz", r.reason
    beta = float(r.reason.split("record shows ")[1].split(" ")[0])
    assert abs(beta) < 0.1, r.reason


@pytest.mark.slow
def test_a_true_extra_tcf_moves_the_record_with_it_and_is_confirmed():
    """thermal_drift hidden (its extra TCF moves the frequency readings of every steady row): confirmed."""
    table, _ = discovery_lot("thermal_drift", snr="mid", design="a", seed=1)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert [s.effect for s in d.steps] == ["thermal_drift"], [(r.effect, r.reason) for r in d.rejected]
