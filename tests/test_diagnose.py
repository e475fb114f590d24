"""The heart of gyrojax: find a hidden effect in noisy lot data, without being told which.

All tables share one shape (3 devices x 2 runs, rate table + static VCF + DAC) and one candidate set, so the
whole file compiles the model once (the demo uses the same campaign).
"""

import json

import numpy as np
import pytest
from _experiments import load_experiment

import gyrojax as gj
from gyrojax._cli.demo_job import DEMO_LOT
from gyrojax._diagnose.compare import nonlinearity_residual_ppm


pytestmark = pytest.mark.slow


def _table(*effects):
    gyro = gj.paper_qmg()
    for name in effects:
        gyro = gj.add_effect(gyro, name)
    return gj.simulate_table(gyro, **DEMO_LOT)


@pytest.fixture(scope="module")
def hidden_dac_inl():
    table = _table("dac_inl")
    return table, gj.diagnose("paper-qmg", table)


def test_hidden_dac_inl_is_found_and_the_error_falls(hidden_dac_inl):
    _, d = hidden_dac_inl
    assert d.selected == ("dac_inl",)
    assert d.ranking[0].effect == "dac_inl"
    assert d.baseline.chi2_red_total > 100.0
    assert 0.7 <= d.final.chi2_red_total <= 1.4
    # the model-vs-measurement nonlinearity residual falls from the INL's ~460 ppm to the noise
    assert d.baseline_nonlinearity_ppm > 300.0
    assert nonlinearity_residual_ppm(d.final) < 0.02 * d.baseline_nonlinearity_ppm
    step = d.steps[0]
    assert step.lr_p_value < 1e-6 and step.delta_bic < 0
    # hidden at its typical size: the refit finds it at about that size (largest coefficient over the lot;
    # the even INL term is invisible and stays at zero)
    assert 0.95 < step.typical_multiple < 1.05  # measured 1.011
    assert f"fitted at {step.typical_multiple:.3g}x its typical size" in d.summary() and "!" not in d.summary()
    # the even INL term is invisible in AC sweeps: only the odd terms are counted per device
    assert d.ranking[0].df == 2 * DEMO_LOT["devices"]
    # a typical-size INL leaves a chi2 of the order of the one measured (the hidden one is typical-size)
    assert d.ranking[0].typical_chi2 > 1e4
    # at this size the DAC sweep tells the INL from a cubic after the DAC: no look-alike is named
    assert step.look_alikes == ()


def test_the_comparison_says_where_the_baseline_fails_and_that_nothing_is_left(hidden_dac_inl):
    """Workflow steps 1-2 on the hidden INL: the baseline's residuals are odd in the input and cluster by sign
    in every sweep the FTR DAC acts on (rate table, closed-loop VCF, DAC), and nothing is even; after dac_inl
    no structure is left and the chi2 is at the noise level."""
    _, d = hidden_dac_inl
    base, final = d.comparisons[0], d.comparisons[-1]
    assert len(d.comparisons) == len(d.fits) == 2
    assert base.fails and base.chi2 == pytest.approx(d.baseline.chi2_total, rel=1e-9)
    flagged = {(f.sweep, f.test) for f in base.flagged}
    for sweep in ("rate_table", "vcf_static", "dac"):
        assert {(sweep, "odd part"), (sweep, "runs")} <= flagged
        assert (sweep, "even part") not in flagged
    # the DAC sweep is measured in volts with a tight sigma: its residual per point is far below the others'
    shares = {g.label: g.share for g in base.by_sweep}
    assert shares["rate_table"] > 0.3 and shares["vcf_static"] > 0.3 and shares["dac"] < 0.01
    assert not final.flagged and not final.fails
    text = d.summary()
    assert "rate_table odd part: p = 0" in text and text.count("no structure in the residuals") == 1
    report = d.to_json()
    assert [c["fails"] for c in report["compare"]] == [True, False]


def test_an_effect_that_fits_only_far_beyond_its_typical_size_is_flagged(hidden_dac_inl):
    """An INL 40 times the library's typical one is still found, at its size, and the summary warns that a
    candidate this far out of range may stand in for another effect (same shapes: no new compile)."""
    gyro = gj.add_effect(gj.paper_qmg(), "dac_inl", 40.0)
    d = gj.diagnose("paper-qmg", gj.simulate_table(gyro, **DEMO_LOT))
    assert d.selected[0] == "dac_inl"
    assert 38.0 < d.steps[0].typical_multiple < 42.0  # measured 40.009
    assert "! dac_inl explains the data only at" in d.summary()
    assert d.to_json()["steps"][0]["typical_multiple"] == d.steps[0].typical_multiple


def test_gain_and_bias_effects_are_reported_untestable(hidden_dac_inl):
    """A push-pull gain mismatch is a pure gain change on these sweeps: the free K_vf absorbs it. The
    diagnosis names what took it up and the measurement that would reveal it."""
    _, d = hidden_dac_inl
    assert "pushpull_mismatch" in d.untestable
    push = next(c for c in d.ranking if c.effect == "pushpull_mismatch")
    # A typical mismatch is a -500 ppm gain (hundreds of sigma on these sweeps) and K_vf takes all of it.
    assert push.visible_chi2 > 1e3
    assert push.absorbed_by == ("k_vf",)
    assert push.typical_chi2 < 1e-6 * push.visible_chi2
    # A damping coupling is a constant bias: nothing is left once the run biases are out.
    damping = next(c for c in d.ranking if c.effect == "damping_coupling")
    assert damping.visible_chi2 < 1.0
    text = d.summary()
    assert "pushpull_mismatch: a typical size would change the chi2 by" in text and "k_vf absorbs 100 % of it" in text
    assert "Revealed by: a branch_ratio sweep (the two feedback branches' AC voltages compared" in text
    # A quadrature phase error is a bias (Q sin phi) and a second-order gain loss
    assert "quadrature_phase: a typical size changes the chi2 by" in text and "the run biases take it up" in text
    report = d.to_json()
    row = next(r for r in report["ranking"] if r["effect"] == "pushpull_mismatch")
    assert row["absorbed_by"] == ["k_vf"] and row["revealed_by"] == gj.EFFECTS["pushpull_mismatch"].revealed_by
    # The INL's linear part is a DAC gain error (the free dac_gain_error takes it: 84 % of the chi2 measured);
    # its S-curve survives the baseline
    inl = next(c for c in d.ranking if c.effect == "dac_inl")
    assert inl.absorbed_by[0] == "dac_gain_error"
    assert 0.05 * inl.visible_chi2 < inl.typical_chi2 < 0.5 * inl.visible_chi2


def test_no_hidden_effect_selects_nothing(hidden_dac_inl):
    d = gj.diagnose("paper-qmg", _table())
    assert d.selected == ()
    assert 0.7 <= d.baseline.chi2_red_total <= 1.4
    # the score statistics of the testable candidates are of the order of their degrees of freedom
    assert all(c.p_value > 1e-4 for c in d.ranking if c.testable)
    # A damping coupling is a bias the run biases take up; what is left (the bias drifting with the warm-up
    # through the scale factor) leaves a typical-size chi2 far below 1: not testable here, though its
    # projected Jacobian has full rank (it was once reported testable, and a hidden one "missed").
    damping = next(c for c in d.ranking if c.effect == "damping_coupling")
    assert damping.df > 0 and damping.typical_chi2 < 0.1
    assert {"pushpull_mismatch", "damping_coupling"} <= set(d.untestable)
    assert "dac_inl" not in d.untestable and "vref_drift" not in d.untestable


def test_two_hidden_effects_are_both_found(hidden_dac_inl):
    d = gj.diagnose("paper-qmg", _table("dac_inl", "vref_drift"))
    assert set(d.selected) >= {"dac_inl", "vref_drift"} or any(
        "vref_drift" in g for g in d.ambiguous)
    assert "dac_inl" in d.selected
    assert 0.7 <= d.final.chi2_red_total <= 1.4


def test_cli_diagnose_json_and_report(hidden_dac_inl, tmp_path):
    from gyrojax.cli import main

    table, _ = hidden_dac_inl
    path = tmp_path / "lot.csv"
    gj.write_table(table, str(path))
    out = tmp_path / "d.json"
    assert main(["diagnose", str(path), "--json", str(out), "--report", str(tmp_path / "rep")]) == 0
    report = json.loads(out.read_text())
    for key in ("baseline", "ranking", "steps", "selected", "ambiguous", "final"):
        assert key in report
    assert report["selected"] == ["dac_inl"]
    assert {"effect", "statistic", "p_value"} <= set(report["ranking"][0])
    assert {"effect", "statistic", "p_value", "chi2_red_after"} <= set(report["steps"][0])
    for name in ("diagnosis.md", "residuals.png", "ranking.png", "error_fall.png"):
        assert (tmp_path / "rep" / name).stat().st_size > 0
    md = (tmp_path / "rep" / "diagnosis.md").read_text()
    assert "## Where the model fails" in md and "### + dac_inl" in md
    assert len(report["compare"]) == 2 and report["compare"][0]["findings"]
    # the verdict and where the misfit lived: at the baseline an odd cubic (the INL), nothing left at the end
    assert report["verdict"] == "explained" and report["discrepancy"] == []
    assert report["steps"][0]["contradicted_by"] == []
    first = report["baseline_discrepancy"][0]
    assert first["coordinate"] == "input" and first["probe"] in ("cubic_of_dac", "cubic_after_dac")
    assert md.count("model against measurement: chi2") == 2  # once per fit, no repeated summary block
    assert "**verdict: explained" in md and "Data: `" + str(path) + "`" in md
    assert (tmp_path / "rep" / "discrepancy.png").stat().st_size > 0


def test_alpha_is_a_significance_level(hidden_dac_inl):
    table, _ = hidden_dac_inl
    for bad in (0.0, 5.0, -0.1, 0.6):
        with pytest.raises(ValueError, match=r"alpha must be a significance level in \(0, 0.5\]"):
            gj.diagnose("paper-qmg", table, alpha=bad)


def test_bad_candidate_names(hidden_dac_inl):
    table, _ = hidden_dac_inl
    with pytest.raises(ValueError, match="unknown candidate effect 'dac_nl'"):
        gj.diagnose("paper-qmg", table, candidates=("dac_nl",))
    with pytest.raises(ValueError, match="cannot act on device 'paper-qmg'"):
        gj.diagnose("paper-qmg", table, candidates=("duffing_sense",))


def test_score_statistic_matches_the_refit_for_a_linear_effect(hidden_dac_inl):
    """For an effect that enters linearly (DAC INL in the AC describing function is linear in its
    coefficients), the score statistic at zero equals the chi2 drop of the refit (the LR statistic)."""
    _, d = hidden_dac_inl
    s = d.steps[0]
    assert s.lr_statistic == pytest.approx(s.statistic, rel=2e-2)
    assert np.isfinite(s.lr_statistic)


CONFUSION = load_experiment("diagnose_confusion")
# Every case of the confusion table (each effect hidden in turn on the preset where it can act, nothing hidden
# on each preset, the pair) but the three the tests above already run on the same lot.
_DONE = {("paper-qmg", ("dac_inl",)), ("paper-qmg", ()), ("paper-qmg", CONFUSION.PAIR)}
OTHER_CASES = [c for c in CONFUSION.cases()[0] if c not in _DONE]


@pytest.mark.parametrize("preset,hidden", OTHER_CASES, ids=lambda v: v if isinstance(v, str) else
                         "+".join(v) or "none")
def test_each_hidden_effect_is_found_or_absorbed(hidden_dac_inl, preset, hidden):
    """Issue 5's acceptance, one case per candidate: the lot of the tests above (DEMO_LOT: 3 devices x 2 runs,
    noise, default process spread) with the effect hidden at its typical size, diagnosed from the plain preset
    without being told what is hidden. The hidden effect is selected (or in a reported ambiguity group with a
    selected one), or reported untestable because the baseline's free parameters take it up; nothing
    spurious; the final reduced chi2 in [0.7, 1.4]."""
    assert DEMO_LOT["devices"] == 3 and DEMO_LOT["runs"] == 2 and DEMO_LOT["seed"] == 7
    row = CONFUSION.run_case(preset, hidden, devices=3, runs=2, seed=7)
    assert row["missed"] == [], row["verdict"]
    assert row["spurious"] == [], row["verdict"]
    assert row["chi2_ok"], (row["final_chi2_red"], row["verdict"])
    if row["absorbed"]:
        # absorbed means the plain model already fits: the baseline itself is inside the band
        assert CONFUSION.CHI2_BAND[0] <= row["baseline_chi2_red"] <= CONFUSION.CHI2_BAND[1]
        # and the diagnosis says what hid it and what would reveal it
        for h in row["absorbed"]:
            assert row["absorption"][h].endswith("Revealed by: " + gj.EFFECTS[h].revealed_by)
    if not hidden:
        assert row["selected"] == []
    if hidden == ("feedback_compression",):
        # a typical-size compression is ~1.1 sigma from a cubic of the DAC itself on the demo's DAC sweep (to a
        # third of full scale): confirmed, with that look-alike named
        assert row["look_alikes"] == {"feedback_compression": ["cubic_of_dac"]}
    elif hidden:
        assert row["look_alikes"] == {}, row["look_alikes"]


def test_a_saved_baseline_fit_is_not_fitted_again(hidden_dac_inl, tmp_path):
    """`diagnose(fit=...)` (the CLI's `--fit FILE`) starts from a given fit of the same data: the baseline is that
    fit evaluated where it ended (same chi2), and the diagnosis reaches the same conclusion. A fit of other data
    is refused by name."""
    table, d = hidden_dac_inl
    path = tmp_path / "baseline.fit"
    gj.save_fit(d.baseline, path)
    with pytest.warns(UserWarning,
                      match=r"baseline.fit: 3 of 3 device\(s\) are not 'ok': paper-qmg-000 \(model rejected"):
        saved = gj.load_fit(path)  # the baseline the INL breaks: the file says so, and loading warns
    again = gj.diagnose(data=table, fit=saved)
    assert again.baseline.chi2_total == pytest.approx(d.baseline.chi2_total, rel=1e-9)
    assert again.selected == ("dac_inl",) and again.verdict == "explained"
    other = table.select(np.flatnonzero(table["device"] != table["device"][0]))
    with pytest.raises(ValueError, match=r"fit: it was fitted to devices \['paper-qmg-000'"):
        gj.diagnose(data=other, fit=d.baseline)


def test_an_absorbed_candidate_leaves_zero_not_round_off():
    # a direction the free parameters take up entirely leaves ~1e-23 of round-off, which differs between
    # machines: the text says 0 (and a real remainder keeps its digits)
    from gyrojax._diagnose.score import CandidateScore

    def text(left):
        return CandidateScore(effect="pushpull_mismatch", statistic=0.0, df=1, p_value=1.0, testable=False,
                              fingerprint=np.zeros((1, 1)), description="", typical_chi2=left,
                              visible_chi2=2.1e7, absorbed_by=("k_vf",)).absorption
    assert "absorbs 100 % of it, leaving 0. Revealed by: " in text(2.5e-23)
    assert "leaving 0." in text(-3e-24)
    assert "leaving 0.37. Revealed" in text(0.37)
