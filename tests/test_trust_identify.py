"""What identify reports can be trusted: a scale factor the data do not fix is NaN with the reason, a misfit
rejects the model and scales its errors, data without output_sigma get their noise estimated, implausible
values and flipped or absurd data are flagged or refused, and a fit file carries each device's status.

Two compiled fits serve every identify test here: one device, two runs of seed 000's rate table, weighted
(with output_sigma) and not (without). Every variant of the data keeps those shapes.
"""

import dataclasses
import hashlib
import io
import json
import struct
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj
from gyrojax._data.arrays import ARRAY_FIELDS
from gyrojax._identify import EXIT_CODES, HELD_LABEL, chi2_p_value, fitio as _fitio
from gyrojax._identify.identifiability import sf_determinacy
from gyrojax._identify.noise import contrasts, noise_scales
from gyrojax._identify.plausibility import check_signs
from gyrojax._model.fitdata import fit_data


slow = pytest.mark.slow

# A cubic output error of 3e-5 LSB per (deg/s)^3: 240 LSB at 200 deg/s, ~110 times the noise (2.2 LSB).
CUBIC = 3e-5


@pytest.fixture(scope="module")
def columns():
    table = gj.simulate_table(gj.paper_qmg(), devices=1, runs=2, sweeps=("rate_table",), seed=3)
    return {k: np.array(table[k]) for k in table.columns}


def _table(columns, source, *, drop=(), output=None):
    cols = {k: v.copy() for k, v in columns.items() if k not in drop}
    if output is not None:
        cols["output"] = output(cols)
    return gj.Table(cols, source=source)


@pytest.fixture(scope="module")
def clean(columns):
    return gj.identify("paper-qmg", _table(columns, "clean"))


@pytest.fixture(scope="module")
def cubic(columns):
    return gj.identify("paper-qmg", _table(columns, "cubic", output=lambda c: c["output"] + CUBIC * c["input"] ** 3))


# --- 1. a design value is never passed off as a measurement ---------------------------------------------

@slow
def test_one_rate_table_point_leaves_the_scale_factor_undetermined(columns, clean):
    """One real point (the same arrays, every other point masked out): its run bias takes it whole, the data
    fix nothing, and the scale factor would be the preset's: NaN, with the reason, not converged, and the
    summary prints no number where the scale factor would be."""
    data = fit_data(_table(columns, "one-point"))
    block = data.blocks["rate_table"]
    keep = np.zeros(block.mask.shape, bool)
    keep[0, 0, int(np.argmax(np.asarray(block.inputs[0, 0])))] = True
    one = eqx.tree_at(lambda d: d.blocks["rate_table"].mask, data, jnp.asarray(keep))
    fit = gj.identify("paper-qmg", one)
    assert fit.status == ("not determined",)
    assert not bool(fit.converged[0]) and not fit.all_converged
    assert np.isnan(float(fit.scale_factor[0])) and np.isnan(float(fit.scale_factor_stderr[0]))
    reason = fit.warnings[0][0]
    assert reason.startswith("the data cannot fix k_vf: 1 rate-table point and 1 free run bias leave no degree of "
                             "freedom"), reason
    assert "design value would not be a measurement" in reason
    text = fit.summary()
    assert "SF NOT DETERMINED" in text and "LSB/(deg/s)" not in text
    assert f"{HELD_LABEL}: k_vf" in text
    with pytest.raises(RuntimeError, match="do not determine the scale factor of paper-qmg-000: the data cannot fix"):
        fit.check()
    assert fit.exit_status == EXIT_CODES["not determined"] == 4
    report = gj.fit_report(fit)
    d = report["devices"][0]
    assert d["status"] == "not determined" and d["scale_factor_lsb_per_dps"] is None
    assert d["parameters"]["k_vf"]["held"] and d["parameters"]["k_vf"]["note"] == HELD_LABEL
    # the full table determines it, and to a few ppm
    assert clean.status == ("ok",) and bool(clean.converged[0])
    assert 0 < float(clean.scale_factor_stderr[0]) < 1e-5 * float(clean.scale_factor[0])


def test_scale_factor_determinacy_is_the_row_space_test():
    """Log coordinates (u_kvf, u_ag): a rate table sees only Ag / K_vf. The SF (Ag / K_vf as well) is
    determined although the product direction is not; a quantity that moves along the product is not; with
    no data nothing is; and in a joint fit a shared column the lot fixes makes a device's SF determined."""
    rng = np.random.default_rng(0)
    a = rng.normal(size=40) * 1e3
    jac = np.stack([-a, a], axis=-1)[None]  # one device, 40 residuals, (k_vf, Ag)
    sf = 1.37e4
    grad = np.array([[-sf, sf]])
    se = np.array([0.01])
    det, part, s = sf_determinacy(jac, None, grad, None, se, 1.0)
    assert det[0] and np.linalg.norm(part[0]) < 1e-9 * sf and s[0].size == 1
    det, part, _ = sf_determinacy(jac, None, np.array([[-sf, 0.0]]), None, se, 1.0)  # K_vf alone
    assert not det[0]
    np.testing.assert_allclose(part[0], [-sf / 2, -sf / 2], rtol=1e-9)
    det, _, _ = sf_determinacy(np.zeros((1, 1, 2)), None, grad, None, np.array([0.0]), 1.0)
    assert not det[0]
    # A dependence on the weak direction (1, 1) / sqrt(2) below a tenth of the SF's standard error is
    # immaterial; above it, it is not.
    weak = np.array([[1.0, 1.0]]) / np.sqrt(2.0)
    assert sf_determinacy(jac, None, grad + 0.05 * se[0] * weak, None, se, 1.0)[0][0]
    assert not sf_determinacy(jac, None, grad + 0.2 * se[0] * weak, None, se, 1.0)[0][0]
    # Joint: each device's data see (own gain + shared gain), its SF its own gain alone: not determined. Rows of
    # device 0 that see the shared gain apart (a rate table) fix the shared gain, hence both own gains.
    b = rng.normal(size=(2, 30, 1)) * 100
    g, g_lot = np.full((2, 1), sf), np.zeros((2, 1))
    two = np.array([0.01, 0.01])
    assert not sf_determinacy(b, b, g, g_lot, two, 1.0)[0].any()
    seen = b.copy()
    seen[0, :10, 0] += 50.0 * rng.normal(size=10)
    assert sf_determinacy(b, seen, g, g_lot, two, 1.0)[0].all()


# --- 2. a misfit reaches the uncertainty -----------------------------------------------------------------

@slow
def test_a_misfit_rejects_the_model_and_scales_its_errors(clean, cubic):
    assert clean.status == ("ok",) and clean.p_value[0] > 0.01
    np.testing.assert_array_equal(np.asarray(clean.stderr_scaled), np.asarray(clean.stderr))
    np.testing.assert_array_equal(np.asarray(clean.scale_factor_stderr_scaled), np.asarray(clean.scale_factor_stderr))
    assert cubic.status == ("model rejected",)
    assert bool(cubic.converged[0])  # the solve is fine; the model is not
    assert cubic.p_value[0] < 1e-10 and cubic.p_value_total < 1e-10
    factor = float(np.sqrt(cubic.chi2_red[0]))
    assert factor > 10
    np.testing.assert_allclose(np.asarray(cubic.scale_factor_stderr_scaled),
                               np.asarray(cubic.scale_factor_stderr) * factor, rtol=1e-12)
    free = np.asarray(cubic.free)
    np.testing.assert_allclose(np.asarray(cubic.stderr_scaled)[:, free], np.asarray(cubic.stderr)[:, free] * factor,
                               rtol=1e-12)
    assert "the model does not describe the data" in cubic.warnings[0][0]
    text = cubic.summary()
    assert "MODEL REJECTED" in text and "x sqrt(chi2_red)" in text
    assert f"+/- {float(cubic.scale_factor_stderr_scaled[0]):.2g} LSB/(deg/s)" in text
    assert cubic.exit_status == EXIT_CODES["model rejected"] == 3 and clean.exit_status == 0
    # a lenient level accepts what a strict one rejects: the test is of the chi2 against reject_alpha
    assert chi2_p_value(np.array([30.0]), np.array([20]), np.array([np.inf]))[0] == pytest.approx(0.0699, abs=1e-4)


@slow
def test_exit_status_precedence(clean):
    """0 only when every device is ok; a failed solve over a missing number over a rejected model."""
    def with_status(*status):
        return dataclasses.replace(clean, status=status)

    assert with_status("ok", "ok").exit_status == 0
    assert with_status("ok", "model rejected").exit_status == 3
    assert with_status("model rejected", "not determined", "ok").exit_status == 4
    assert with_status("not determined", "not converged").exit_status == 1
    assert with_status("unknown", "model rejected").exit_status == 5
    assert sorted(EXIT_CODES.values()) == [0, 1, 3, 4, 5]


# --- 3. data without output_sigma: the noise is estimated ---------------------------------------------

def _linear_problem(x_runs, sigma, biased=True):
    """Residual maker of a straight-line fit with one bias per run (unit weights) on the given inputs."""
    x = np.concatenate(x_runs)
    n = x.size
    cols = [x] if biased else [np.ones(n), x]
    if biased:
        proj = np.eye(n)
        k = 0
        for xr in x_runs:
            sl = slice(k, k + xr.size)
            proj[sl, sl] -= 1.0 / xr.size
            k += xr.size
        jac = proj @ np.stack(cols, -1)
    else:
        proj, jac = np.eye(n), np.stack(cols, -1)
    u, s, _ = np.linalg.svd(jac, full_matrices=False)
    return proj - u @ u.T, jac


RATES = np.array([-200, -100, -50, -20, -10, -5, -2, -1, -0.5, -0.2, -0.1, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100,
                  200.0])


@pytest.mark.parametrize("runs", [1, pytest.param(2, marks=pytest.mark.slow)])  # 2: Monte Carlo, slow tier
def test_the_noise_estimate_is_unbiased_for_white_noise(runs):
    """The method of moments over the fit's residual maker: the mean of the variance estimate over 4000 noise
    draws is the true variance within its Monte Carlo error, for one run (local contrasts) and for two
    (differences between runs), here with a second, unbiased sweep in other units sharing the fit."""
    rng = np.random.default_rng(runs)
    sig_rate, sig_dac = 2.2, 3e-6
    words = np.linspace(-1.0, 1.0, 9)
    n_rate = runs * RATES.size
    # Rate sweep (biased runs) and DAC sweep (unbiased) share a gain: one Jacobian over both.
    m_rate, j_rate = _linear_problem([RATES] * runs, sig_rate)
    j = np.zeros((n_rate + words.size, 3))
    j[:n_rate, :1] = j_rate
    j[n_rate:, 1] = 1.0
    j[n_rate:, 2] = words
    j[n_rate:, 0] = 1e-4 * words  # the shared gain reaches the DAC sweep too
    proj = np.eye(j.shape[0])
    proj[:n_rate, :n_rate] = np.eye(n_rate) - np.kron(np.eye(runs), np.ones((RATES.size, RATES.size)) / RATES.size)
    u, _, _ = np.linalg.svd(j, full_matrices=False)
    resid_maker = proj - u @ u.T
    x_rate = np.tile(RATES, (runs, 1))
    blocks = [(x_rate, np.ones_like(x_rate, bool), np.ones_like(x_rate), True),
              (words[None], np.ones((1, words.size), bool), np.ones((1, words.size)), False)]
    draws = 4000
    k = np.zeros((draws, 2))
    for i in range(draws):
        e = np.concatenate([sig_rate * rng.normal(size=n_rate), sig_dac * rng.normal(size=words.size)])
        k[i], nu, methods, _ = noise_scales(resid_maker @ e, j, blocks)
    mean, err = k.mean(0), k.std(0) / np.sqrt(draws)
    assert abs(mean[0] - sig_rate**2) < 4 * err[0], (mean, err)
    assert abs(mean[1] - sig_dac**2) < 4 * err[1], (mean, err)
    # the effective degrees of freedom describe the spread: var(k) = 2 k^2 / nu
    np.testing.assert_allclose(k.var(0) * nu / (2 * np.array([sig_rate, sig_dac]) ** 4), 1.0, atol=0.15)
    assert methods[0].startswith("differences between runs" if runs == 2 else "combinations of 4 neighbouring")


@pytest.mark.parametrize("runs", [1, pytest.param(2, marks=pytest.mark.slow)])  # 2: Monte Carlo, slow tier
def test_the_chi2_test_with_estimated_noise_holds_its_level(runs):
    """With the noise estimated from the same residuals, chi2 / dof is narrower than F (measured: 1 % of right
    models below p = 0.05 with the F test, on one run). Against its Monte Carlo null a right model is
    rejected at the level asked: 5 % of 1000 noise draws below p = 0.05, within 3 binomial errors."""
    from gyrojax._identify.covariance import mc_p_value

    rng = np.random.default_rng(10 + runs)
    m, j = _linear_problem([RATES] * runs, 1.0)
    x = np.tile(RATES, (runs, 1))
    blocks = [(x, np.ones_like(x, bool), np.ones_like(x), True)]
    dof = runs * RATES.size - runs - 1
    p_mc, p_f = [], []
    for _ in range(1000):
        r = m @ (2.2 * rng.normal(size=runs * RATES.size))
        _, nu, _, (chi2, draws) = noise_scales(r, j, blocks, draws=1000, rng=rng)
        p_mc.append(mc_p_value(chi2, draws, dof, nu[0]))
        p_f.append(chi2_p_value(np.array(chi2), np.array(dof), np.array(nu[0]))[()])
    rate = np.mean(np.array(p_mc) < 0.05)
    assert abs(rate - 0.05) < 3 * np.sqrt(0.05 * 0.95 / 1000), rate
    assert np.mean(np.array(p_f) < 0.05) < 0.03  # what the F test alone would have given


def test_local_contrasts_cancel_a_smooth_misfit():
    """Within a run, the contrasts cancel any quadratic through four neighbouring inputs, so a cubic over the
    rate table enters the estimate ~300x less than it enters the residuals; between runs any repeated misfit
    cancels."""
    rows, _ = contrasts(RATES[None], np.ones((1, RATES.size), bool))
    assert rows.shape == (RATES.size - 3, RATES.size)
    np.testing.assert_allclose(rows @ np.stack([np.ones(22), RATES, RATES**2], -1), 0.0, atol=1e-9)
    m, _ = _linear_problem([RATES], 1.0)
    r = m @ RATES**3
    inflation = (r @ r / 20) / (np.sum((rows @ r) ** 2) / np.trace(rows @ m @ rows.T))
    assert inflation > 100
    rows2, method = contrasts(np.tile(RATES, (2, 1)), np.ones((2, 22), bool))
    assert method.startswith("differences between runs") and rows2.shape == (22, 44)
    np.testing.assert_allclose(rows2 @ np.tile(RATES**3, 2), 0.0, atol=0.0)


def test_a_misfit_that_differs_between_runs_does_not_become_noise():
    """Runs swept up then down under a bias drifting in time: the differences between runs at equal inputs
    take up the drift (3.4x the noise variance), the local contrasts cancel it, and the F test between the
    two sends the estimate to the local contrasts; under white noise it keeps the differences (switches in
    <= 0.5 % of draws) and the estimate stays unbiased."""
    rng = np.random.default_rng(7)
    m, j = _linear_problem([RATES] * 2, 1.0)
    x = np.tile(RATES, (2, 1))
    blocks = [(x, np.ones_like(x, bool), np.ones_like(x), True)]
    t = np.concatenate([np.arange(22), np.arange(22)[::-1]])
    local = contrasts(x, blocks[0][1], "local")[0]
    assert local.shape == (2 * 19, 44)
    k_drift, switched = [], []
    for _ in range(200):
        r = m @ (rng.normal(size=44) + 0.2 * t)
        k, _, methods, _ = noise_scales(r, j, blocks)
        k_drift.append(k[0])
        switched.append(methods[0].startswith("combinations") and "differs from run to run" in methods[0])
    # the drift's share of what the differences alone would measure: more than twice the noise
    rows = contrasts(x, blocks[0][1])[0]
    diff = rows @ m @ (0.2 * t)
    assert np.sum(diff**2) / np.trace(rows @ m @ rows.T) > 3.0
    assert np.mean(switched) > 0.75
    assert 0.85 < np.median(k_drift) < 1.15
    k_null, switched = [], []
    for _ in range(1000):
        k, _, methods, _ = noise_scales(m @ rng.normal(size=44), j, blocks)
        k_null.append(k[0])
        switched.append(not methods[0].startswith("differences between runs"))
    assert np.mean(switched) <= 0.005
    assert abs(np.mean(k_null) - 1.0) < 4 * np.std(k_null) / np.sqrt(1000)


def test_the_lot_pools_a_sweeps_noise_where_its_devices_agree():
    """Bartlett's test across devices: six estimates of one variance (21 degrees of freedom each) are pooled into
    one with 126; one device at 5x the variance keeps the sweep per device (at 3x Bartlett's p is ~0.02: the
    pooling keeps such a device in, with 21 degrees of freedom each). In 2000 draws of equal variances the
    pooling is refused at about its 1 % level."""
    from gyrojax._identify.noise import POOL_ALPHA, _pooled

    rng = np.random.default_rng(3)
    nu = np.full((6, 2), 21.0)
    base = np.ones((6, 2))
    kappa = np.column_stack([4.0 * rng.chisquare(21, 6) / 21, 4.0 * rng.chisquare(21, 6) / 21])
    kappa[:, 1] = [20.0, 4.0, 4.0, 4.0, 4.0, 4.0]  # one device's noise 2.2x in sigma on the second sweep
    k, dof, how = _pooled(kappa, nu, base)
    np.testing.assert_allclose(k[:, 0], np.mean(kappa[:, 0]))
    np.testing.assert_allclose(dof[:, 0], 126.0)
    assert how[0, 0].startswith("pooled over 6 devices")
    assert np.all(np.isnan(k[:, 1])) and how[0, 1] == ""
    # a device in other units (its first-fit scale 10x) is compared in output units
    scaled = kappa[:, :1].copy()
    scaled[2] /= 100.0
    base10 = np.ones((6, 1))
    base10[2] = 10.0
    k10, _, _ = _pooled(scaled, nu[:, :1], base10)
    np.testing.assert_allclose(k10[2, 0] * 100.0, k[2, 0])
    refused = [np.isnan(_pooled(4.0 * rng.chisquare(21, (6, 1)) / 21, nu[:, :1], base[:, :1])[0][0, 0])
               for _ in range(2000)]
    assert abs(np.mean(refused) - POOL_ALPHA) < 4 * np.sqrt(POOL_ALPHA * (1 - POOL_ALPHA) / 2000)


def test_estimate_noise_is_checked():
    with pytest.raises(ValueError, match="estimate_noise must be None, True, False or 'lot', got 'pooled'"):
        gj.identify("paper-qmg", gj.Table({"device": ["a"], "run": [0], "sweep": ["rate_table"], "input": [1.0],
                                           "output": [1.0]}), estimate_noise="pooled", progress=False)


@pytest.fixture(scope="module")
def unweighted(columns):
    def fit(source, output=None):
        return gj.identify("paper-qmg", _table(columns, source, drop=("output_sigma",), output=output))

    return fit


@slow
def test_without_output_sigma_a_strong_cubic_is_rejected_and_clean_data_are_ok(columns, unweighted):
    clean = unweighted("clean, no output_sigma")
    cubic = unweighted("cubic, no output_sigma", lambda c: c["output"] + CUBIC * c["input"] ** 3)
    # clean: ok, chi2_red near 1 in units of the estimated noise, which is the simulator's within its error
    assert clean.status == ("ok",), clean.summary()
    assert 0.5 < float(clean.chi2_red[0]) < 1.6
    true_sigma = float(np.median(columns["output_sigma"]))
    estimated = float(np.median(np.asarray(clean.data.blocks["rate_table"].sigmas)[np.asarray(
        clean.data.blocks["rate_table"].mask)]))
    nu = float(clean.noise_dof[0])
    assert 15 < nu < 30  # 22 differences between the two runs
    assert abs(estimated**2 / true_sigma**2 - 1) < 3 * np.sqrt(2 / nu), (estimated, true_sigma)
    assert any("no output_sigma: the noise was estimated" in w for w in clean.warnings[0])
    # the residuals are in units of the estimate: compare finds them at the noise level
    assert not gj.compare(clean).fails
    # cubic: the repeated misfit cancels between runs, the noise estimate stays the noise, the model is rejected
    assert cubic.status == ("model rejected",), cubic.summary()
    assert float(cubic.chi2_red[0]) > 100 and cubic.p_value[0] < 1e-6
    assert gj.compare(cubic).fails
    np.testing.assert_allclose(np.asarray(cubic.data.blocks["rate_table"].sigmas),
                               np.asarray(clean.data.blocks["rate_table"].sigmas), rtol=0.3)


@slow
def test_without_output_sigma_too_few_points_leave_the_uncertainty_undetermined(columns, unweighted):
    """Three points of one run (the unweighted arrays, the rest masked out): a slope and a bias leave one
    residual, but no four neighbours and no repeated input to measure the noise from. The SF would have no
    honest uncertainty: not determined, and the reason says so first."""
    data = fit_data(_table(columns, "three points, no output_sigma", drop=("output_sigma",)))
    block = data.blocks["rate_table"]
    keep = np.zeros(block.mask.shape, bool)
    keep[0, 0, [0, 10, 21]] = True
    fit = gj.identify("paper-qmg", eqx.tree_at(lambda d: d.blocks["rate_table"].mask, data, jnp.asarray(keep)))
    assert fit.status == ("not determined",)
    assert fit.warnings[0][0].startswith("no output_sigma, and the data leave nothing to estimate the noise of "
                                         "rate_table"), fit.warnings
    assert np.isnan(float(fit.scale_factor[0])) and np.isnan(fit.p_value[0])
    assert "SF NOT DETERMINED" in fit.summary()


# --- 4. plausibility and the data's conventions --------------------------------------------------------

@slow
def test_outputs_a_thousand_times_too_large_flag_k_vf_and_name_the_units(columns, clean):
    def times_1000(c):
        c["output_sigma"] = c["output_sigma"] * 1000
        return c["output"] * 1000

    fit = gj.identify("paper-qmg", _table(columns, "x1000", output=times_1000))
    assert fit.status == ("model rejected",) and bool(fit.converged[0])
    assert fit.p_value[0] > 0.01  # the chi2 is fine: the value is not
    np.testing.assert_allclose(float(fit.scale_factor[0]), 1000 * float(clean.scale_factor[0]), rtol=1e-6)
    warning = next(w for w in fit.warnings[0] if w.startswith("k_vf = "))
    assert "0.001 x its design value" in warning and "10^-3" in warning and "unit" in warning
    assert "MODEL REJECTED" in fit.summary()


def test_absurd_output_is_refused_before_fitting(columns):
    def outlier(c):
        y = c["output"].copy()
        y[3] = 1e300
        return y

    with pytest.raises(ValueError, match=r"device 'paper-qmg-000', run 0, input -20: output 1e\+300 is .* times the "
                                         r"largest other output of its run"):
        gj.identify("paper-qmg", _table(columns, "outlier", output=outlier))


@slow
def test_flipped_outputs_are_refused_before_fitting(columns, clean):
    with pytest.raises(ValueError, match=r"opposite sign of the model 'paper-qmg' .* run 0: slope -1370\d\.\d .*, the "
                                         r"model's 1370\d\.\d; .* run 1: slope -1370\d.*negate the output"):
        gj.identify("paper-qmg", _table(columns, "flipped", output=lambda c: -c["output"]))


# --- 5. failed fits are saved like good ones, and never read back silently -----------------------------

@slow
def test_status_round_trips_and_loading_warns(cubic, clean, tmp_path):
    path = tmp_path / "cubic.fit"
    gj.save_fit(cubic, path)
    with pytest.warns(UserWarning, match=r"cubic\.fit: 1 of 1 device\(s\) are not 'ok': paper-qmg-000 \(model "
                                         r"rejected: the model does not describe"):
        back = gj.load_fit(path)
    a, ta = jax.tree.flatten(cubic)
    b, tb = jax.tree.flatten(back)
    assert ta == tb
    for x, y in zip(a, b):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        assert np.asarray(x).dtype == np.asarray(y).dtype
    assert back.status == cubic.status and back.warnings == cubic.warnings
    assert back.summary() == cubic.summary()
    header = _header(path)
    assert header["format_version"] == 3 and header["status"] == ["model rejected"]
    ok_path = tmp_path / "clean.fit"
    gj.save_fit(clean, ok_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gj.load_fit(ok_path)


def _header(path):
    raw = path.read_bytes()
    (length,) = struct.unpack("<Q", raw[len(_fitio.MAGIC):len(_fitio.MAGIC) + 8])
    start = len(_fitio.MAGIC) + 8
    return json.loads(raw[start:start + length])


def _as_version_1(fit, path):
    """The file version 1 wrote: no status arrays or header keys, sweep blocks of five fields."""
    blocks = {s: _v1_block(b) for s, b in fit.data.blocks.items()}
    old = dataclasses.replace(fit, stderr_scaled=None, lot_stderr_scaled=None, scale_factor_stderr_scaled=None,
                              noise_dof=None, p_value=None, p_value_total=None,
                              data=dataclasses.replace(fit.data, blocks=blocks))
    buf = io.BytesIO()
    eqx.tree_serialise_leaves(buf, old)
    payload = buf.getvalue()
    header = _fitio._header(fit, "paper-qmg")
    for key in ("status", "warnings", "reject_alpha", "block_fields"):
        del header[key]
    header.update(format_version=1, leaves=[_fitio._leaf_spec(x) for x in jax.tree.leaves(old)],
                  sha256=hashlib.sha256(payload).hexdigest())
    head = json.dumps(header).encode()
    path.write_bytes(_fitio.MAGIC + struct.pack("<Q", len(head)) + head + payload)


def _v1_block(block):
    return dataclasses.replace(block, **{f: None for f in ARRAY_FIELDS if f not in _fitio._V1_BLOCK_FIELDS})


@slow
def test_version_1_files_are_read_with_status_unknown(clean, tmp_path):
    path = tmp_path / "old.fit"
    _as_version_1(clean, path)
    with pytest.warns(UserWarning, match=r"old\.fit: this fit file \(format version 1\) predates the status checks"):
        back = gj.load_fit(path)
    assert back.status == ("unknown",)
    np.testing.assert_array_equal(np.asarray(back.scale_factor), np.asarray(clean.scale_factor))
    np.testing.assert_array_equal(np.asarray(back.scale_factor_stderr_scaled), np.asarray(clean.scale_factor_stderr))
    assert back.exit_status == EXIT_CODES["unknown"]
    assert "STATUS UNKNOWN" in back.summary()


@slow
def test_report_gives_status_and_warnings_and_keeps_its_keys(cubic):
    report = gj.fit_report(cubic)
    json.dumps(report, allow_nan=False)
    d = report["devices"][0]
    assert d["status"] == "model rejected" and d["warnings"] == list(cubic.warnings[0])
    assert set(d) >= {"parameters", "scale_factor_lsb_per_dps", "scale_factor_stderr", "chi2_red", "converged",
                      "message", "scale_factor_stderr_scaled", "p_value"}
    assert d["parameters"]["k_vf"] == {"value": float(cubic.values[0, 0]), "stderr": float(cubic.stderr[0, 0]),
                                       "held": False}
    assert d["parameters"]["q_y"]["note"] == HELD_LABEL and d["parameters"]["q_y"]["stderr"] is None
    assert d["scale_factor_stderr_scaled"] == float(cubic.scale_factor_stderr_scaled[0])
    assert report["exit_status"] == 3


@slow
def test_the_cli_exit_code_says_whether_the_result_is_a_measurement(columns, tmp_path, capsys):
    """`gyrojax identify` exits 0 only when every device is "ok": 3 when the model is rejected (a cubic the
    preset lacks), 4 when the scale factor is not determined (one rate-table point); the JSON and the saved fit
    carry the status either way, and stderr names the device."""
    from gyrojax.cli import main

    cubic = tmp_path / "cubic.csv"
    gj.write_table(_table(columns, "cubic", output=lambda c: c["output"] + CUBIC * c["input"] ** 3), cubic)
    out, saved = tmp_path / "cubic.json", tmp_path / "cubic.fit"
    assert main(["identify", str(cubic), "--json", str(out), "--save", str(saved)]) == 3
    err = capsys.readouterr().err
    assert "gyrojax identify: paper-qmg-000: model rejected" in err
    assert json.loads(out.read_text())["devices"][0]["status"] == "model rejected"
    with pytest.warns(UserWarning, match="not 'ok'"):
        gj.load_fit(saved)
    one = tmp_path / "one.csv"
    rows = {k: v[:1] for k, v in columns.items()}
    gj.write_table(gj.Table(rows, source="one"), one)
    assert main(["identify", str(one)]) == 4
    captured = capsys.readouterr()
    assert "SF NOT DETERMINED" in captured.out and "not determined" in captured.err


def test_sign_check_needs_a_model_slope_clear_of_zero():
    """A flipped sign is named only where the model predicts a slope the data could see: against a model slope
    within noise of zero (the drive frequency against the AGC set-point without a cubic spring) the data's
    clear slope is the effect to be found, not a flipped convention. No fit: the check alone."""
    x = np.linspace(-1.0, 1.0, 7)
    rows = {"device": ["d0"] * 7, "run": [0] * 7, "sweep": ["rate_table"] * 7, "input": x,
            "output": -3.0 * x, "output_sigma": np.full(7, 0.01)}
    data = fit_data(gj.Table(rows, source="signs.csv"))
    flat = {"rate_table": jnp.asarray(1e-4 * x)[None, None, :]}  # 1e-4 per unit: 0.03 standard errors
    check_signs(data, flat, "paper-qmg")  # no error
    clear = {"rate_table": jnp.asarray(3.0 * x)[None, None, :]}
    with pytest.raises(ValueError, match=r"signs\.csv: the outputs change with the input with the opposite sign .* "
                                         r"device 'd0', run 0: slope -3 \+/- .*, the model's 3"):
        check_signs(data, clear, "paper-qmg")


# --- 4. a temperature not recorded --------------------------------------------------------------------------

def test_a_fit_without_temperature_c_that_the_data_reject_says_so(columns):
    """The simulated die warms 25.4 -> 27 C after power-on; without temperature_c the model holds every point at
    its power-on temperature, the data reject it, and the warning names the missing column and what follows."""
    bare = gj.identify("paper-qmg", _table(columns, "no temperature", drop=("temperature_c",)), progress=False)
    assert bare.status == ("model rejected",)
    note = [w for w in bare.warnings[0] if "temperature_c" in w]
    assert len(note) == 1 and "no temperature_c for rate_table" in note[0] and "(25 C)" in note[0], bare.warnings
    full = gj.identify("paper-qmg", _table(columns, "with temperature"), progress=False)
    assert not any("temperature_c" in w for w in full.warnings[0])


@slow
def test_the_diagnosis_shows_its_baseline_notes_about_the_data(columns):
    d = gj.diagnose("paper-qmg", _table(columns, "no temperature", drop=("temperature_c", "output_sigma")),
                    max_effects=0, progress=False)
    notes = d.to_json()["baseline"]["notes"]
    texts = [n["note"] for n in notes]
    assert any(t.startswith("the data give no temperature_c") for t in texts), texts
    assert any(t.startswith("no output_sigma: the noise was estimated") for t in texts), texts
    assert all(n["devices"] == ["paper-qmg-000"] for n in notes)
    assert not any(t.startswith("the model does not describe") for t in texts)
    assert "note (paper-qmg-000): the data give no temperature_c" in d.summary()


@slow
def test_identify_pools_the_noise_of_a_lot_when_asked():
    table = gj.simulate_table(gj.paper_qmg(), devices=3, runs=2, sweeps=("rate_table",), seed=4, progress=False)
    bare = gj.Table({k: table[k] for k in table.column_names if k != "output_sigma"}, source="3 devices")
    own = gj.identify("paper-qmg", bare, progress=False)
    lot = gj.identify("paper-qmg", bare, estimate_noise="lot", progress=False)
    assert own.status == lot.status == ("ok",) * 3, (own.summary(), lot.summary())
    assert all("pooled over 3 devices" in lot.warnings[d][0] for d in range(3))
    np.testing.assert_allclose(np.asarray(lot.noise_dof), np.sum(np.asarray(own.noise_dof)), rtol=1e-6)
    sigmas = [np.asarray(lot.data.blocks["rate_table"].sigmas)[d][np.asarray(lot.data.blocks["rate_table"].mask)[d]]
              for d in range(3)]
    np.testing.assert_allclose([s.max() for s in sigmas], sigmas[0].max(), rtol=1e-9)
    true_sigma = float(np.median(np.asarray(table["output_sigma"])))
    assert abs(sigmas[0].max() ** 2 / true_sigma**2 - 1) < 3 * np.sqrt(2 / float(lot.noise_dof[0]))
    assert np.all(np.isfinite(np.asarray(lot.p_value)))
