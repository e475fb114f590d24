"""The rival guard (`gyrojax/_diagnose/rival.py`): a library effect is compared with the closed form the data
propose for the misfit it takes, and the formula of a misfit is written along the coordinate it was located on.

Lots from the discovery benchmark's independent generator (`experiments/_discovery_lot.py`, plain NumPy, middle
SNR: the hidden effect's visible chi2 is 300): a zero-rate output proportional to dT/dt (outside the library,
which `vref_drift` took on c46d262..cfed775 with LR p ~ 1e-20), the library's own reference drift (which must
still be confirmed), and a gain on positive table rates only (placed on time since power-on before, whose sweep
order follows the input).
"""

import os
import sys

import pytest

import gyrojax as gj


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


pytestmark = pytest.mark.slow


def _diagnose(hidden):
    table, info = discovery_lot(hidden, snr="mid", design="a", seed=0)
    return gj.diagnose("paper-qmg", table, progress=False), info


def test_a_bias_following_dT_dt_is_not_taken_for_a_reference_drift():
    d, _ = _diagnose("bias_dTdt")
    assert d.selected == ()
    reasons = {r.effect: r.reason for r in d.rejected}
    assert "vref_drift" in reasons
    assert "closed form of another shape" in reasons["vref_drift"] and "lin(dtemperature_dt)" in reasons["vref_drift"]
    # dT/dt follows the time since power-on on this protocol: the location names both, the formula is one term
    top = d.discrepancy[0]
    assert "dtemperature_dt" in (top.coordinate, *top.confounded_with)
    assert {s for s, _ in top.sweeps} == {"rate_table", "vcf_static"}
    assert len(d.formula.terms) == 1 and d.formula.complete


def test_a_true_reference_drift_is_still_confirmed():
    d, _ = _diagnose("vref_drift")
    assert d.selected == ("vref_drift",)
    assert d.verdict == "explained"


def test_a_gain_of_positive_rates_is_placed_on_the_input():
    d, info = _diagnose("sign_gain_rate")
    top = d.discrepancy[0]
    assert top.coordinate == "input" and {s for s, _ in top.sweeps} == {"rate_table"}
    assert [t.name for t in d.formula.terms] == ["abs(input)"]
    assert "time_s" in top.confounded_with  # the sweep's order follows the input: said, not hidden


def _verdict(z, inside):
    from gyrojax._diagnose.rival import Rivalry

    return Rivalry(formula=None, z=z, delta=z, distance=1.0, inside=inside).verdict  # type: ignore[arg-type]


@pytest.mark.parametrize("z, inside, verdict", [
    (0.3, 0.2, "rival fits as well"),
    (-0.5, 0.2, "not told apart"),  # a rival of another shape asks for up to Z_CRIT: 1.96 x 0.8 = 1.57
    (-1.5, 0.2, "not told apart"),
    (-1.7, 0.2, "look-alike"),
    (-0.5, 0.9, "look-alike"),  # nearly the effect's own shape asks for 0.196
    (-2.5, 0.2, "effect fits better"),
    (-0.1, 0.995, "same shape"),
])
def test_the_margin_a_rival_asks_for_grows_with_how_different_its_shape_is(z, inside, verdict):
    assert _verdict(z, inside) == verdict


def test_a_gain_growing_with_temperature_is_not_named_a_zero_rate_tempco_at_low_snr():
    # T x |input| (outside the library) at low SNR: zro_tempco takes part of it (LR p ~ 1e-7 on 6 df) and fits
    # better than lin(temperature_c)*abs(input) by z ~ 0.6 only, though 55 % of its change lies outside that
    # form's span: not confirmed, with the closed form named
    table, _ = discovery_lot("temp_x_abs_input", snr="low", design="b", seed=0)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert "zro_tempco" not in d.selected
    kinds = {r.effect: (r.kind, r.reason) for r in d.rejected}
    assert kinds["zro_tempco"][0] == "not told from a closed form of another shape"
    assert "lin(temperature_c)*abs(input)" in kinds["zro_tempco"][1]
    as_json = {r["effect"]: r["kind"] for r in d.to_json()["rejected"]}
    assert as_json["zro_tempco"] == "not told from a closed form of another shape"


def test_a_dac_inl_taken_for_a_feedback_compression_at_low_snr_is_declared_ambiguous():
    # neither removes significant chi2 beyond the other (the fingerprints' cosine is 0.91, below 0.95): the
    # diagnosis says it cannot tell them apart instead of naming one
    table, _ = discovery_lot("dac_inl_cubic", snr="low", design="b", seed=1)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert d.selected == ("feedback_compression",)
    assert ("feedback_compression", "dac_inl") in d.ambiguous


def test_noise_larger_than_stated_confirms_nothing():
    # a null lot whose rate and VCF rows carry extra heavy-tailed noise (Student t, 3 dof, unit variance: the
    # stated sigma is sqrt(2) too small): read against the stated sigma, a temperature tempco's chi2 drop looked
    # significant (zro_tempco confirmed on this lot); read against the refit's own scatter, it is not
    import numpy as np

    table, _ = discovery_lot(None, snr="mid", design="a", seed=1)
    cols = dict(table.columns)
    sigma = np.asarray(cols["output_sigma"], float)
    rng = np.random.default_rng(101)
    rng.choice(np.flatnonzero(np.asarray(cols["sweep"]) == "rate_table"))  # the draw the study made first
    t3 = rng.standard_t(3, size=sigma.size) / np.sqrt(3.0)
    cols["output"] = np.asarray(cols["output"], float) + sigma * t3 * (np.asarray(cols["sweep"]) != "dac")
    d = gj.diagnose("paper-qmg", gj.Table(cols, source="<null lot, noise sqrt(2) x stated>"), progress=False)
    assert d.selected == ()
    assert d.final.chi2_red_total > 1.5  # the scatter is said, not explained away
