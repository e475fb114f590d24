"""A bias that cycles in time (the lab's air conditioning, period 20 min, locked to power-on): the spectral scan
runs along the time as it does along the input, the formula names `periodic(time_s)` and its draft explains the
lot. Lots of the independent NumPy generator (`experiments/_discovery_lot.py`, `bias_periodic_time`), on the
shuffled protocol (design c), where the time is not the input's order."""

import os
import sys

import pytest

import gyrojax as gj
from gyrojax._diagnose.descriptions import describe
from gyrojax._diagnose.draft import write_draft
from gyrojax._diagnose.space import ResidualSpace


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cycling_bias():
    table, info = discovery_lot("bias_periodic_time", snr="mid", design="c", seed=0)
    return table, info, gj.diagnose("paper-qmg", table, progress=False)


def test_the_spectral_scan_along_time_finds_the_period(cycling_bias):
    _, _, d = cycling_bias
    descs, _ = describe(ResidualSpace(d.baseline))
    (scan,) = [x for x in descs if x.family == "periodic" and x.coordinate == "time_s" and x.sweep == "rate_table"]
    assert scan.p_value < 1e-6
    assert abs(scan.where["period"] - 1200.0) < 0.1 * 1200.0  # the scan's grid: 24 log-spaced periods


def test_the_formula_is_periodic_in_time_and_names_the_time(cycling_bias):
    _, info, d = cycling_bias
    assert d.selected == () and d.verdict == "unexplained", d.summary()
    assert {t.name for t in d.formula.terms} == {"periodic(time_s)"} and d.formula.complete
    top = d.discrepancy[0]
    assert top.coordinate == "time_s" and set(top.located_on) == {"rate_table", "vcf_static"}
    # the sine's coefficient is the bias amplitude (1 deg/s x size through the rate scale factor, in LSB)
    (i,) = [k for k, t in enumerate(d.formula.terms) if "sin" in t.expression]
    truth = 13700.0 * info["size"]
    assert abs(d.formula.coefficients[i] - truth) < 3.0 * d.formula.stderr[i] + 0.1 * truth


def test_the_drafted_periodic_term_explains_the_lot(cycling_bias, tmp_path):
    table, _, d = cycling_bias
    path = tmp_path / "cycling_bias.py"
    write_draft(d.formula, path, name="cycling_bias")
    assert "jnp.sin(2 * jnp.pi * t /" in path.read_text()
    (cls,) = gj.load_effects_module(path)
    try:
        again = gj.diagnose("paper-qmg", table, progress=False)
    finally:
        gj.EFFECTS.pop(cls.name, None)
    assert again.selected == ("cycling_bias",) and again.verdict == "explained", again.summary()
    assert 0.8 <= again.final.chi2_red_total <= 1.2
