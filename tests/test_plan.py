"""The measurement planner: its statistics against brute force and scipy, its arguments, and (slow) its
scale-factor standard error against the fit's own covariance and the command's JSON."""

import dataclasses
import json
from types import SimpleNamespace

import equinox as eqx
import jax
import numpy as np
import pytest
from _virtual_rate_sweep import AbstractRateTableWithVirtualRate
from scipy.stats import chi2 as scipy_chi2, ncx2

import gyrojax as gj
from gyrojax._model.parameters import Model, batched, build_entries, zero_effect
from gyrojax._numerics.stats import chi2_isf, ncx2_sf
from gyrojax._plan import experiment as plan_experiment
from gyrojax._plan.experiment import NoiseLevel, jacobians, predict, weighted_rows, window_correlation
from gyrojax._plan.information import kept_columns, nuisances, reduce_rows, residual_chi2, run_info, sf_variance
from gyrojax._plan.power import power, required_noncentrality
from gyrojax._plan.results import Recommendation
from gyrojax.cli import main


@pytest.mark.parametrize("df", [1, 2, 3, 4, 7, 12])
@pytest.mark.parametrize("nc", [0.0, 0.3, 5.0, 14.9, 60.0, 400.0])
def test_power_matches_scipy_ncx2(df, nc):
    c = scipy_chi2.isf(0.01, df)
    assert chi2_isf(0.01, df) == pytest.approx(c, rel=1e-10)
    assert power(nc, df, 0.01) == pytest.approx(ncx2.sf(c, df, nc) if nc > 0 else 0.01, rel=1e-9, abs=1e-13)
    assert ncx2_sf(0.7 * c, df, nc) == pytest.approx(ncx2.sf(0.7 * c, df, nc) if nc > 0 else
                                                      scipy_chi2.sf(0.7 * c, df), rel=1e-9, abs=1e-13)


@pytest.mark.parametrize("df", [1, 4, 12])
def test_required_noncentrality_gives_the_target_power(df):
    lam = required_noncentrality(df, 0.9, 0.01)
    assert ncx2.sf(scipy_chi2.isf(0.01, df), df, lam) == pytest.approx(0.9, abs=1e-7)


def test_power_rejects_bad_df():
    with pytest.raises(ValueError, match="df must be an integer >= 1"):
        power(3.0, 0)
    with pytest.raises(ValueError, match="target power must be in"):
        required_noncentrality(2, 1.5)


def _experiment(n):
    return gj.CandidateExperiment("extra", "rate_table", np.linspace(-1.0, 1.0, n), np.full(n, 25.0), np.zeros(n),
                                  10.0)


def test_expected_chi2_equals_a_refit_on_a_noise_free_linear_case():
    # Existing data (rows x params) and one new biased run: the effect (2 columns) at theta leaves, after a
    # least-squares refit of the nuisances and the new run's bias, exactly the planner's lambda.
    rng = np.random.default_rng(3)
    j0 = rng.normal(size=(30, 6))
    j0[:, 3] = j0[:, 2]  # a column the existing data cannot tell from another
    jn = rng.normal(size=(9, 6)) + 0.4
    sig = rng.uniform(0.5, 2.0, 9)
    theta = np.array([0.7, -1.3])
    nuis, eff = [0, 1, 2, 3], [4, 5]
    exp = _experiment(9)
    blocks = [np.concatenate([reduce_rows(j0), reduce_rows(weighted_rows(exp, jn, sig))])]
    lam = residual_chi2(blocks[0], nuis, eff, theta)
    # brute force: the whole design with an explicit bias column for the new run, refitted without the effect
    y = np.concatenate([j0[:, eff] @ theta, (jn[:, eff] @ theta) / sig])
    x = np.zeros((39, 5))
    x[:30, :4] = j0[:, nuis]
    x[30:, :4] = jn[:, nuis] / sig[:, None]
    x[30:, 4] = 1.0 / sig
    resid = y - x @ np.linalg.lstsq(x, y, rcond=None)[0]
    assert lam == pytest.approx(float(resid @ resid), rel=1e-9)
    assert lam > 0.1
    # the existing data alone: the duplicated column is held by identification's rule, and changes nothing
    assert kept_columns([reduce_rows(j0)], nuis, 1.0) == [0, 1, 2]
    alone = residual_chi2(reduce_rows(j0), [0, 1, 2], eff, theta)
    y0 = j0[:, eff] @ theta
    r0 = y0 - j0[:, :3] @ np.linalg.lstsq(j0[:, :3], y0, rcond=None)[0]
    assert alone == pytest.approx(float(r0 @ r0), rel=1e-9)


def test_candidate_experiment_checks_its_settings():
    with pytest.raises(ValueError, match="sweep must be a registered sweep kind"):
        gj.CandidateExperiment("x", "mode_reversal", (1.0, 2.0), (25.0, 25.0), (0.0, 0.0), 1.0)
    with pytest.raises(ValueError, match="one value per point"):
        gj.CandidateExperiment("x", "rate_table", (1.0, 2.0), (25.0,), (0.0, 0.0), 1.0)
    with pytest.raises(ValueError, match="minutes must be > 0"):
        gj.CandidateExperiment("x", "rate_table", (1.0, 2.0), (25.0, 25.0), (0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="protocol must be a gyrojax.Protocol"):
        gj.CandidateExperiment("x", "rate_table", (1.0, 2.0), (25.0, 25.0), (0.0, 0.0), 1.0, 120.0)
    exp = gj.CandidateExperiment("x", gj.sweeps.VcfDynamic(), (10.0, 20.0), (25.0, 25.0), (0.0, 0.0), 1.0)
    assert exp.kind == "vcf_dynamic" and not exp.biased


def test_default_experiments_minutes_follow_the_protocol():
    exps = {e.name: e for e in gj.default_experiments(gj.preset("paper-qmg"))}
    # one run of every registered kind the device allows, in registry order, and the warmer rate table
    assert list(exps)[:5] == ["rate_table", "rate_table_hot", "vcf_static", "vcf_dynamic", "dac"]
    assert set(exps) == {"rate_table_hot"} | set(gj.sweeps.SWEEP_KINDS)
    assert exps["rate_table"].minutes == pytest.approx(1 + 22 * 2)  # seed 000: 1 min warm-up, 2 min per rate
    assert exps["rate_table_hot"].minutes == pytest.approx(45 + 30)
    assert exps["vcf_dynamic"].minutes == pytest.approx((60 + 50 * 10) / 60)
    assert exps["dac"].minutes == pytest.approx(22 * 10 / 60)
    hot = np.asarray(exps["rate_table_hot"].temperatures_c) - np.asarray(exps["rate_table"].temperatures_c)
    assert np.allclose(hot, 20.0)
    assert exps["rate_table"].biased and not exps["vcf_dynamic"].biased
    assert exps["dac"].inputs[0] == pytest.approx(-exps["dac"].inputs[-1])  # words for -200 and +200 deg/s
    assert np.all(np.isnan(exps["dac"].temperatures_c))  # a bench measurement of the DAC alone


class _OffsetRateTable(AbstractRateTableWithVirtualRate):
    """A sweep kind the planner has never heard of: a rate table with a constant virtual rate on the
    virtual-Coriolis electrode, at 3 rates and a dwell of its own."""

    name = "plan_test_offset_rate_table"
    stream = 102

    def inputs(self, gyro=None):
        return np.asarray((-100.0, 0.0, 100.0))

    def n_points(self):
        return 3

    def dwell_s(self, protocol):
        return 60.0


def test_a_registered_sweep_kind_is_a_candidate_with_its_own_minutes_and_noise():
    gj.sweeps.register_sweep(_OffsetRateTable)
    try:
        exps = {e.name: e for e in gj.default_experiments(gj.preset("paper-qmg"))}
    finally:
        del gj.sweeps.SWEEP_KINDS[_OffsetRateTable.name]
    new = exps[_OffsetRateTable.name]
    assert new.minutes == pytest.approx((60 + 3 * 60) / 60)  # warm-up + 3 dwells of 60 s
    assert dict(new.settings)["offset_v"] == 0.5 and new.biased and new.inputs == (-100.0, 0.0, 100.0)
    level = NoiseLevel(lsb_per_dps=1000.0, scale=2.0, voltmeter_sigma_v=1e-5)
    rate = exps["rate_table"].sigmas(level)
    # rate noise averaged over the kind's own dwell (60 s against the rate table's 120 s)
    ratio = gj.RateNoise().point_sigma_dps(60.0) / gj.RateNoise().point_sigma_dps(120.0)
    assert ratio > 1.2
    assert rate[0] == pytest.approx(2.0 * 1000.0 * gj.RateNoise().point_sigma_dps(120.0), rel=1e-12)
    assert new.sigmas(level) == pytest.approx(np.full(3, rate[0] * ratio), rel=1e-12)
    assert exps["dac"].sigmas(level) == pytest.approx(np.full(22, 1e-5))


def test_relative_noise_kinds_take_their_fraction_of_the_predicted_reading():
    exps = {e.name: e for e in gj.default_experiments(gj.preset("paper-qmg"))}
    level = NoiseLevel(lsb_per_dps=1000.0, scale=2.0, voltmeter_sigma_v=1e-5)
    reading = np.linspace(0.9, 1.1, 7)
    # 1 ppm of the AGC registers' reading, sqrt(2) x 10 ppm of the branch ratio, not scaled by the rate noise
    assert exps["drive_amplitude"].sigmas(level, 4.0e6 * reading) == pytest.approx(4.0 * reading, rel=1e-12)
    assert exps["drive_frequency"].sigmas(level, 2.0e4 * reading) == pytest.approx(0.02 * reading, rel=1e-12)
    branch = exps["branch_ratio"]
    ratio = np.linspace(0.999, 1.001, branch.points)
    assert branch.sigmas(level, ratio) == pytest.approx(np.sqrt(2.0) * 1e-5 * ratio, rel=1e-12)
    with pytest.raises(ValueError, match="relative_sigma with predicted outputs"):
        branch.sigmas(level)


def test_window_correlation_matches_the_simulated_point_noise():
    noise = gj.RateNoise()
    corr = window_correlation(noise, 4, 120.0)
    _, x = noise.sample_point_means(np.random.default_rng(5), (40000,), 4, 120.0)
    # neighbours share 0.1225 of the variance through the 30 s wander (x = T / tau = 4); two apart e^-4 of it
    assert corr[0, 1] == pytest.approx(0.12251, abs=1e-5)
    assert corr[0, 2] == pytest.approx(corr[0, 1] * np.exp(-4.0), rel=1e-12)
    assert np.allclose(np.corrcoef(x.T), corr, atol=0.012)
    assert np.allclose(np.diag(corr), 1.0)


def test_sandwich_variance_of_a_slope_under_correlated_noise():
    # one run of y = b + s x with a fitted bias: the planner's variance with and without the noise's
    # correlation against the weighted least-squares slope's exact variance
    x = np.linspace(-1.0, 1.0, 5)
    rows, sig = x[:, None], np.full(5, 2.0)
    corr = np.array([[0.3 ** abs(i - j) for j in range(5)] for i in range(5)])
    info, meat = run_info(rows, sig, list(range(5)), lambda n: corr)
    xc = x - x.mean()
    c = xc / np.sum(xc**2)  # the slope's weights
    exact = float(c @ (4.0 * corr) @ c)
    assert sf_variance(info, np.ones(1), [0], 0.0, meat) == pytest.approx(exact, rel=1e-12)
    assert sf_variance(info, np.ones(1), [0], 0.0) == pytest.approx(4.0 / np.sum(xc**2), rel=1e-12)


def test_plan_rejects_bad_arguments():
    with pytest.raises(ValueError, match="budget_min must be at least one run of seed 000's protocol"):
        gj.plan("paper-qmg", None, budget_min=30.0)
    with pytest.raises(ValueError, match="alpha must be a significance level"):
        gj.plan("paper-qmg", None, alpha=0.7)
    with pytest.raises(ValueError, match="max_repeats must be an integer in 1..8"):
        gj.plan("paper-qmg", None, max_repeats=0)
    with pytest.raises(ValueError, match="plan needs data"):
        gj.plan("paper-qmg", None)


def test_cli_plan_rejects_a_bad_budget(tmp_path, capsys):
    assert main(["plan", str(tmp_path / "x.csv"), "--budget-min", "-5"]) == 2
    assert "--budget-min expects minutes > 0" in capsys.readouterr().err
    assert main(["plan", str(tmp_path / "missing.csv")]) == 2


def _same_shapes(shift):
    # one lot's experiments: the default ones' DAC words and VCF voltages follow its fitted device
    return (gj.CandidateExperiment("rate_table", "rate_table", [-100.0 + shift, 0.0, 100.0], [25.0 + shift] * 3,
                                   [600.0, 720.0, 840.0], 10.0),
            gj.CandidateExperiment("dac", "dac", [-9000.0 - 100.0 * shift, 9000.0], [np.nan] * 2, [np.nan] * 2, 1.0))


def _lot_model():
    model = batched(Model(gj.preset("paper-qmg")), 1)
    return model, build_entries(model, ("k_vf", "vcf_gain"))


def test_the_jacobians_program_is_keyed_by_shapes_not_by_the_experiments_numbers(monkeypatch):
    # What the compiled Jacobians are keyed on (everything but the arrays) is the same for two lots' experiments.
    class Called(Exception):
        pass

    seen = []

    def record(*args):
        seen.append(eqx.partition(args, eqx.is_array)[1])
        raise Called

    monkeypatch.setattr(plan_experiment, "_jacobians", record)
    model, entries = _lot_model()
    for shift in (0.0, 7.0):
        with pytest.raises(Called):
            jacobians(model, entries, _same_shapes(shift), [25.0 + shift])
    (leaves_a, tree_a), (leaves_b, tree_b) = (jax.tree.flatten(x) for x in seen)
    assert tree_a == tree_b and leaves_a == leaves_b


@pytest.mark.slow
def test_experiments_of_the_same_shapes_share_one_jacobian_program():
    # A second lot of the same shapes traces nothing, and its predictions are its own points'.
    model, entries = _lot_model()
    traces = []

    def listen(event, secs, **kw):
        if event == "/jax/core/compile/jaxpr_trace_duration" and "_jacobians" in str(kw.get("fun_name")):
            traces.append(secs)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        jacobians(model, entries, _same_shapes(0.0), [25.0])
        first = len(traces)
        (jac, g), (pred, sf) = jacobians(model, entries, _same_shapes(7.0), [30.0])
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert first == 1 and len(traces) == 1
    own, own_sf = predict(gj.preset("paper-qmg"), _same_shapes(7.0), 30.0)
    assert pred[0][0] == pytest.approx(np.asarray(own[0]), rel=1e-9)
    assert pred[1][0] == pytest.approx(np.asarray(own[1]), rel=1e-9)
    assert sf[0] == pytest.approx(float(own_sf), rel=1e-9)
    assert jac[0].shape == (1, 3, 2) and jac[1].shape == (1, 2, 2) and g.shape == (1, 2)


@pytest.mark.slow
def test_plan_on_a_rate_table(tmp_path):
    table = gj.simulate_table(gj.preset("paper-qmg"), runs=2, seed=1, progress=False)
    plan = gj.plan("paper-qmg", table, max_repeats=2, progress=False)
    fit = plan.baseline
    sfd = plan.scale_factor
    # the scale factor's stderr on the data given is the fit's own (its covariance and gradient)
    assert sfd.data_stderr[0] == pytest.approx(float(fit.scale_factor_stderr[0]), rel=1e-6)
    # three runs of the seed-000 protocol against the two given: sqrt(2/3) of the stderr, times 1.06 for the
    # bias wander that neighbouring points share (the fit's own stderr weighs them as independent)
    assert sfd.seed000_runs == 3
    assert sfd.seed000_stderr[0] / (sfd.data_stderr[0] * np.sqrt(2 / 3)) == pytest.approx(1.0595, abs=0.005)
    # the +/-200 deg/s design: the shared wander cancels in each pair's difference
    assert sfd.rates_dps == (-200.0, 200.0) and sfd.rate_runs == 27
    assert sfd.ratio == pytest.approx(0.339, abs=0.005)
    assert sfd.minutes <= sfd.budget_min + 1e-9 and sfd.ratio < 1.0
    dac = plan.candidate("dac_inl")
    assert dac.testable and dac.power > 0.99 and not dac.recommended
    # a run-bias-absorbed effect stays untestable on more rate tables (its fingerprint is a constant)
    assert not plan.candidate("damping_coupling").testable
    report = plan.to_json()
    assert set(report) >= {"candidates", "scale_factor"}
    for c in report["candidates"].values():
        assert set(c) >= {"testable", "recommended"}
        for r in c["recommended"]:
            assert set(r) >= {"sweep", "settings", "minutes", "expected_chi2", "power"}
    assert set(report["scale_factor"]) >= {"stderr", "seed000", "ratio", "rates_dps", "rate_runs"}
    # the command, from the saved fit
    data, saved, out = tmp_path / "t.csv", tmp_path / "base.fit", tmp_path / "plan.json"
    gj.write_table(table, data)
    gj.save_fit(fit, saved)
    assert main(["plan", str(data), "--fit", str(saved), "--json", str(out), "--quiet"]) == 0
    cli = json.loads(out.read_text())
    assert cli["scale_factor"]["seed000"]["stderr"][0] == pytest.approx(sfd.seed000_stderr[0], rel=1e-9)
    assert cli["candidates"]["dac_inl"]["testable"] is True


def test_diagnose_max_effects_is_a_count():
    # max_effects=0 ranks at the baseline only (the planner's validation scores that way); a bad count is refused
    # before any data are read
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="max_effects must be an integer >= 0"):
            gj.diagnose("paper-qmg", None, max_effects=bad)


SMALL_RATES = (-200.0, -50.0, -5.0, 5.0, 50.0, 200.0)
SMALL = (gj.sweeps.RateTable(rates_dps=SMALL_RATES), gj.sweeps.VcfStatic(virtual_rates_dps=SMALL_RATES))


def _join(table, extra, runs_before):
    cols = {}
    for c in dict.fromkeys(table.column_names + extra.column_names):
        a = np.asarray(table[c]) if c in table else np.full(len(table), np.nan)
        b = np.asarray(extra[c]) if c in extra else np.full(len(extra), np.nan)
        cols[c] = np.concatenate([a, b + runs_before if c == "run" else b])
    return gj.Table.from_columns(cols)


@pytest.mark.slow
def test_a_hidden_quadrature_phase_is_found_with_the_recommended_run():
    """A row of the confusion table with the planner (experiments/diagnose_confusion.py --plan), on one device:
    the standard sweeps cannot test a hidden quadrature_phase; the plan on their baseline recommends the
    quadrature injection; simulated for the same device (another noise seed) and added, the diagnosis selects
    it, its test sees about the chi2 the plan promised, and the final fit is within the chi2 band."""
    gyro = gj.add_effect(gj.paper_qmg(), gj.effects.QuadraturePhase.typical(1.0))
    table = gj.simulate_table(gyro, runs=2, seed=3, progress=False, sweeps=SMALL)
    cands = ("quadrature_phase", "damping_coupling")
    d = gj.diagnose("paper-qmg", table, candidates=cands, progress=False)
    assert "quadrature_phase" in d.untestable and not d.selected
    exps = tuple(e for e in gj.default_experiments(gj.paper_qmg(), kinds=SMALL)
                 if e.name in ("rate_table", "vcf_static", "quadrature_injection"))
    p = gj.plan(fit=d.baseline, experiments=exps, max_repeats=2, progress=False)
    c = p.candidate("quadrature_phase")
    assert not c.testable and c.expected_chi2 < 1e-3
    assert [r.experiment.name for r in c.recommended] == ["quadrature_injection"]
    runs = c.recommended[0].runs
    # the run biases take damping_coupling up whatever is added: no recommendation, a reason
    assert not p.candidate("damping_coupling").recommended
    extra = gj.simulate_table(gyro, runs=runs, seed=4, progress=False,
                              sweeps=("quadrature_injection",))
    d2 = gj.diagnose("paper-qmg", _join(table, extra, 2), candidates=cands, progress=False)
    assert d2.selected == ("quadrature_phase",)
    assert 0.7 <= d2.final.chi2_red_total <= 1.4
    seen = next(s for s in d2.ranking if s.effect == "quadrature_phase")
    assert 0.5 <= seen.typical_chi2 / c.recommended_chi2 <= 2.0, (seen.typical_chi2, c.recommended_chi2)


@pytest.mark.slow
def test_a_drive_frequency_run_frees_omega_x_and_leaves_duffing_its_shape():
    # One drive-frequency run: a typical duffing_drive pulls the frequency by 3/8 kappa a^2, whose mean over the
    # set-points is an omega_x shift. The diagnosis of those data frees omega_x (Plan.free), so the planner's
    # expected chi2 is what is left after omega_x too: the direct projection, a fraction of the held value.
    g = gj.preset("paper-qmg")
    exp = next(e for e in gj.default_experiments(g) if e.kind == "drive_frequency")
    assert exp.reads == ("omega_x",)
    assert next(e for e in gj.default_experiments(g) if e.kind == "rate_table").reads == ()
    model = batched(Model(g, (zero_effect("duffing_drive"),)), 1)
    entries = build_entries(model, ("k_vf", "omega_x"))
    assert [e.label for e in entries] == ["k_vf", "omega_x", "duffing_drive.kappa"]
    (jac, _), (pred, sf) = jacobians(model, entries, (exp,), [25.0])
    rows = weighted_rows(exp, jac[0][0], exp.sigmas(NoiseLevel(abs(float(sf[0])), 1.0, 1e-4), pred[0][0]))
    data = np.diag([40.0, 0.0, 0.0])  # the data given fix k_vf, see neither omega_x nor the pull
    blocks = [np.concatenate([data, reduce_rows(rows)])]
    theta = np.atleast_1d(np.asarray(gj.EFFECTS["duffing_drive"].typical(1.0).kappa) / np.asarray(entries[2].scale))
    assert nuisances(blocks, (0,), [0], [0], [[1]], 1.0) == [0]  # nothing added: the baseline's free ones
    held = nuisances(blocks, (1,), [0], [0], [[]], 1.0)
    freed = nuisances(blocks, (1,), [0], [0], [[1]], 1.0)
    assert held == [0] and freed == [0, 1]
    lam_held = residual_chi2(blocks[0], held, [2], theta)
    lam_freed = residual_chi2(blocks[0], freed, [2], theta)
    x, y = np.concatenate([data, rows])[:, :2], np.concatenate([data, rows])[:, 2] * theta[0]
    r = y - x @ np.linalg.lstsq(x, y, rcond=None)[0]
    assert lam_freed == pytest.approx(float(r @ r), rel=1e-6)
    assert lam_held == pytest.approx(float(y @ y), rel=1e-6)  # k_vf does not move the drive frequency
    assert 1.0 < lam_freed < 0.5 * lam_held, (lam_freed, lam_held)


def _plan_of(recommended, device="paper-qmg"):
    """A Plan whose candidates ask for `recommended`: {effect: ((experiment, runs), ...)} (None: testable)."""
    cands = tuple(gj.CandidatePlan(effect, 1, 0.0, 0.0, recs is None, (), (),
                                   tuple(Recommendation(e, k, 50.0, 0.99) for e, k in (recs or ())), 0.0, 0.0, "")
                  for effect, recs in recommended.items())
    baseline = SimpleNamespace(model=gj.Model(gj.preset(device), ()))  # Plan.free reads its device
    return gj.Plan(cands, None, (), baseline, 0.01, 0.9, 3, ("d0",))


def test_the_plans_runs_are_the_union_and_free_what_they_read():
    g = gj.preset("paper-qmg")
    by = {e.name: e for e in gj.default_experiments(g)}
    p = _plan_of({"agc_finite_gain": ((by["drive_amplitude"], 1),), "vref_drift": None,
                  "duffing_drive": ((by["drive_frequency"], 2), (by["drive_amplitude"], 3))})
    runs = p.runs()
    assert list(runs) == ["drive_amplitude", "drive_frequency"]
    assert runs["drive_amplitude"][1:] == (3, ("agc_finite_gain", "duffing_drive"))
    assert runs["drive_frequency"][1:] == (2, ("duffing_drive",))
    assert p.free(("k_vf", "omega_y")) == ("k_vf", "omega_y", "omega_x")
    assert p.free(("omega_x", "k_vf")) == ("omega_x", "k_vf")
    only_agc = _plan_of({"agc_finite_gain": ((by["drive_amplitude"], 1),)})
    assert only_agc.free(("k_vf",)) == ("k_vf",)
    # a dynamic VCF run reads the angular gain through the rebalance loop: closed loop only
    dynamic = {"vref_drift": ((by["vcf_dynamic"], 1),)}
    assert _plan_of(dynamic).free(("k_vf",)) == ("k_vf", "angular_gain")
    assert _plan_of(dynamic, "vcf-2018").free(("sense_gain",)) == ("sense_gain",)
    # free=None starts from the data's default: what the given sweeps read (a dynamic VCF's angular gain) too
    from gyrojax._model.fitdata import fit_data

    given = gj.Table.from_columns({"device": ["d0"] * 3, "run": [0] * 3, "sweep": ["rate_table", "vcf_dynamic",
                                   "vcf_dynamic"], "input": [10.0, 10.0, 20.0], "output": [1e3, 3e4, 3.1e4],
                                   "output_sigma": [1.0] * 3, "temperature_c": [25.0] * 3})
    fitted = SimpleNamespace(data=fit_data(given), model=gj.Model(g, ()))
    with_data = dataclasses.replace(p, baseline=fitted)
    assert with_data.free() == gj.identification.DEFAULT_FREE + ("angular_gain", "omega_x")


def test_a_reading_experiment_adds_its_columns_to_the_joint_fit_only_with_its_runs():
    # Column 2 (omega_x) is seen by experiment 1's rows only; the rule frees it only in sets with runs of it.
    rng = np.random.default_rng(5)
    blocks = [np.concatenate([np.diag([30.0, 20.0, 0.0, 0.0]), rng.normal(size=(6, 4)) * 5.0])]
    reading = [[], [2]]
    assert nuisances(blocks, (0, 0), [0], [0, 1], reading, 1.0) == [0]
    assert nuisances(blocks, (2, 0), [0], [0, 1], reading, 1.0) == [0, 1]
    assert nuisances(blocks, (0, 1), [0], [0, 1], reading, 1.0) == [0, 1, 2]
    blocks[0][:, 2] = 1e-3  # too weak to fix: identification's rule holds it
    assert nuisances(blocks, (0, 1), [0], [0, 1], reading, 1.0) == [0, 1]


def test_the_plans_runs_are_simulated_for_the_same_lot_and_appended(monkeypatch):
    # Which devices, seeds, protocols and run numbers `Plan.simulate` asks the simulator for (stubbed: a point per
    # run), and the table it returns.
    from gyrojax._plan import simulate as plan_simulate

    calls = []

    def fake(one, *, devices, runs, sweeps, protocol, seed, progress):
        calls.append((float(one.resonator.omega_x), devices, runs, sweeps, float(one.temperature(0.0)), seed))
        return gj.Table.from_columns({"device": ["x"] * runs, "run": np.arange(1, runs + 1),
                                      "sweep": list(sweeps) * runs, "input": np.zeros(runs),
                                      "output": np.full(runs, float(seed))})

    monkeypatch.setattr(plan_simulate, "simulate_table", fake)
    g = gj.preset("paper-qmg")
    by = {e.name: e for e in gj.default_experiments(g)}
    p = _plan_of({"agc_finite_gain": ((by["drive_amplitude"], 2),), "zro_tempco": ((by["rate_table_hot"], 1),)})
    given = gj.Table.from_columns({"device": ["paper-qmg-000"], "run": [1], "sweep": ["rate_table"],
                                   "input": [10.0], "output": [3.0], "temperature_c": [25.0]})
    t = p.simulate(g, given, devices=2, runs=2, seed=7, noise_seed=100)
    lot = gj.campaign_lot(g, devices=2, seed=7)
    wx = [float(x) for x in np.asarray(lot.resonator.omega_x)]
    hot = float(dict(by["rate_table_hot"].settings)["chamber_c"])
    own = float(g.temperature(0.0))
    assert hot == own + 20.0
    assert [c[1:] for c in calls] == [(1, 2, ("drive_amplitude",), own, 107), (1, 2, ("drive_amplitude",), own, 108),
                                      (1, 1, ("rate_table",), hot, 107), (1, 1, ("rate_table",), hot, 108)]
    assert [c[0] for c in calls] == pytest.approx(wx * 2, rel=1e-12) and wx[0] != wx[1]
    assert len(t) == 1 + 2 * 2 + 2 * 1
    assert list(t["device"]) == ["paper-qmg-000"] + ["paper-qmg-000"] * 2 + ["paper-qmg-001"] * 2 + [
        "paper-qmg-000", "paper-qmg-001"]
    # after the given 2 runs; the hot run after those and the most runs of any experiment (2), plus one
    assert list(t["run"]) == [1, 3, 4, 3, 4, 6, 6]
    assert list(t["output"][1:]) == [107.0, 107.0, 108.0, 108.0, 107.0, 108.0]
    assert t["temperature_c"][0] == 25.0 and np.all(np.isnan(t["temperature_c"][1:]))
    with pytest.raises(ValueError, match="recommends no runs"):
        _plan_of({"vref_drift": None}).simulate(g)
