"""The lot as a population (`gyrojax.PopulationSolve`, issue 38 point 1): the lot mean and spread recovered within
their standard errors on lots of known spread, shrinkage toward the lot, prediction intervals for a device
without a rate table, the estimator itself on Gaussian data, and the refusals.

The lots: paper-qmg (closed loop), a rate table and a static VCF sweep, electrodes spread 1 % (the generator's
`ProcessSpread.electrode`, so the feedback factor k_vf is drawn as k0 (1 + 0.01 z)); mass and Ag not spread, so
that the rate table's scale factor 2 Ag m a w / K_vf moves with k_vf alone.
"""

import json
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj
from gyrojax._identify.population import Z95, interval_dof, lot_distribution, t_quantile
from gyrojax._identify.problem import sf_temperature
from gyrojax.cli import main


SPREAD = gj.ProcessSpread(mass=0.0, angular_gain=0.0)
K0 = float(gj.paper_qmg().feedback_electrode.k_vf)
SIGMA = SPREAD.electrode  # the generator's relative spread of k_vf
SWEEPS = ("rate_table", "vcf_static")


def _lot_table(devices, seed, no_rate=(), few=(), noise=gj.RateNoise()):
    """A simulated lot; devices `no_rate` (indices) lose their rate table, devices `few` keep only its rates up
    to 20 deg/s."""
    table = gj.simulate_table(gj.paper_qmg(), devices=devices, runs=1, sweeps=SWEEPS, seed=seed, spread=SPREAD,
                              noise=noise, progress=False)
    dev = table["device"].tolist()
    sweep = table["sweep"].tolist()
    x = np.asarray(table["input"])
    index = {d: i for i, d in enumerate(dict.fromkeys(dev))}
    keep = [r for r, (d, s) in enumerate(zip(dev, sweep))
            if not (s == "rate_table" and (index[d] in no_rate or (index[d] in few and abs(x[r]) > 20)))]
    return table.select(keep)


def _true_sf(devices, seed, temps):
    lot = gj.campaign_lot(gj.paper_qmg(), devices=devices, seed=seed, spread=SPREAD)

    def one(g, t):
        return jax.jvp(lambda r: gj.rate_table_points(g, r[None], t[None], gj.CAMPAIGN_TIER).rate[0],
                       (jnp.zeros(()),), (jnp.ones(()),))[1]

    return np.asarray(eqx.filter_jit(eqx.filter_vmap(one))(lot, jnp.asarray(temps))), lot


def test_lot_distribution_recovers_a_gaussian_population_with_uninformed_members():
    """The estimator alone: b_i ~ N(mu, s^2 + c_i^2) for 40 informed members, 200 without information; over 200
    lots the z-scores of mu and log s have mean ~0 and SD ~1."""
    rng = np.random.default_rng(0)
    zs = []
    for _ in range(200):
        c = rng.uniform(0.2, 1.0, 40)
        b = 3.0 + rng.normal(0, 1.0, 40) + c * rng.normal(size=40)
        info = np.concatenate([1 / c**2, np.zeros(200)])[:, None, None]
        h = np.concatenate([b / c**2, np.zeros(200)])[:, None]
        hyper, cov, ok, notes = lot_distribution(info, h, np.array([0.0, 0.0]), 100_000)
        assert ok and not notes
        zs.append([(hyper[0] - 3.0) / math.sqrt(cov[0, 0]), hyper[1] / math.sqrt(cov[1, 1])])
    zs = np.asarray(zs)
    assert np.all(np.abs(zs.mean(0)) < 0.3), zs.mean(0)
    assert np.all(np.abs(zs.std(0) - 1) < 0.2), zs.std(0)


def test_t_quantile():
    np.testing.assert_allclose(t_quantile(0.975, [1.0, 3.0, 10.0, np.inf]), [12.7062047, 3.1824463, 2.2281389, Z95],
                               rtol=1e-6)
    assert np.isnan(t_quantile(0.975, [np.nan])[0])


def test_prediction_interval_covers_with_a_spread_from_four_devices():
    """300 Gaussian lots, 4 precisely measured members each (the rate-tabled devices), one new member predicted
    from the lot (a device without a rate table): the Student-t interval with the REML spread's degrees of freedom
    (~3) covers ~95 %; the normal interval with the same standard error covers ~86 % (P(|t_3| < 1.96))."""
    rng = np.random.default_rng(1)
    t_hits, normal_hits, dofs = [], [], []
    for _ in range(300):
        c = rng.uniform(0.001, 0.002, 4)
        b = 3.0 + rng.normal(0, 1.0, 4) + c * rng.normal(size=4)
        hyper, cov, ok, _ = lot_distribution((1 / c**2)[:, None, None], (b / c**2)[:, None], np.zeros(2), 100_000)
        assert ok
        sd = math.sqrt(math.exp(2 * hyper[1]) + cov[0, 0])  # spread and the lot mean's uncertainty
        dof = interval_dof(np.array([sd**2]), np.ones((1, 1)), hyper, cov)[0]
        err = abs(3.0 + rng.normal() - hyper[0])
        t_hits.append(err < t_quantile(0.975, [dof])[0] * sd)
        normal_hits.append(err < Z95 * sd)
        dofs.append(dof)
    assert abs(np.median(dofs) - 3) < 0.1, np.median(dofs)
    assert 0.92 < np.mean(t_hits) < 0.98, np.mean(t_hits)
    assert np.mean(normal_hits) < 0.91, np.mean(normal_hits)


def test_lot_distribution_says_when_em_does_not_converge():
    info = np.ones((5, 1, 1)) * 4.0
    h = np.arange(5.0)[:, None] * 4.0
    _, _, ok, notes = lot_distribution(info, h, np.array([0.0, 0.0]), 2)
    assert not ok
    assert "did not converge in 2 steps" in notes[0] and "Try:" in notes[0]


def test_population_solve_refuses_what_it_cannot_do():
    table = _lot_table(8, seed=3, no_rate=(7,))  # the first lot below (its simulation compiled once)
    with pytest.raises(ValueError, match="unknown parameter 'k_vff' in random"):
        gj.PopulationSolve(random=("k_vff",))
    with pytest.raises(ValueError, match="random must be a non-empty tuple"):
        gj.PopulationSolve(random="k_vf")
    with pytest.raises(ValueError, match="k_vf has a prior .* and is random"):
        gj.identify("paper-qmg", table, lot_solve=gj.PopulationSolve(random=("k_vf",)), priors={"k_vf": (K0, 1e-8)},
                    progress=False)
    with pytest.raises(ValueError, match="lot-shared parameters .* are not fitted in a population fit"):
        gj.identify("paper-qmg", table, lot_solve=gj.PopulationSolve(random=("k_vf",)), shared=("vcf_gain",),
                    progress=False)


@pytest.mark.slow
def test_lot_mean_and_spread_recovered_and_a_device_without_rate_table_predicted():
    """8-device lots (the last without a rate table), three seeds, k_vf and vcf_gain random (the generator draws
    K_vf and K_svf each as k0 (1 + 0.01 z), independently): each lot mean and spread within 3 of their standard
    errors of the generator's; z-scores printed. vcf_gain is not the fit's first parameter, so its coordinates
    are read from their own column. The device without a rate table sees only K_svf / K_vf: its SF is a
    prediction; with k_vf random its 95 % interval covers its true SF (with both random, within 3 sigma: seed 5
    measured z = -2.4, where the k_vf-only prediction has -1.2)."""
    rows = []
    k_svf = float(gj.paper_qmg().vcf_electrode.force_per_volt2)
    for seed in (3, 4, 5):
        table = _lot_table(8, seed, no_rate=(7,))
        pf = gj.identify("paper-qmg", table, lot_solve=gj.PopulationSolve(random=("k_vf", "vcf_gain")),
                         progress=False)
        assert pf.converged, pf.warnings
        assert pf.fit.names.index("vcf_gain") != 0
        zs = []
        for p, center, sigma in zip(pf.parameters, (K0, k_svf), (SIGMA, SPREAD.vcf_electrode)):
            # the generator's log-mean: E log(1 + sigma z) = -sigma^2 / 2
            zs.append((math.log(p.mean / center) + sigma**2 / 2) / (p.mean_stderr / p.mean))
            zs.append((p.relative_spread - sigma) / (p.spread_stderr / p.mean))
        true_sf, _ = _true_sf(8, seed, sf_temperature(pf.fit.data))
        z_both = (pf.sf[7] - true_sf[7]) / pf.sf_stderr[7]
        # k_vf alone random: the parameter the missing rate table fixes, the case of a batch calibration
        alone = gj.identify("paper-qmg", table, lot_solve=gj.PopulationSolve(random=("k_vf",)), progress=False)
        low, high = alone.interval()
        z_pred = (alone.sf[7] - true_sf[7]) / alone.sf_stderr[7]
        rows.append((seed, *zs, z_pred, z_both, alone.sf_stderr[7] / alone.sf[7]))
        assert all(abs(z) < 3 for z in zs) and abs(z_both) < 3, rows[-1]
        assert pf.missing[7] == ("rate_table",) and all(m == () for m in pf.missing[:7])
        assert low[7] < true_sf[7] < high[7], (seed, low[7], true_sf[7], high[7])
        pf = alone
        # the prediction's width: the lot spread with the mean's uncertainty, ~1 % x sqrt(1 + 1/7)
        assert 0.005 < pf.sf_stderr[7] / pf.sf[7] < 0.03
        # rate-tabled devices keep their own ppm-level SF
        assert np.all(pf.sf_stderr[:7] / pf.sf[:7] < 1e-5)
        assert np.all(np.abs(pf.sf[:7] - true_sf[:7]) < 4 * pf.sf_stderr[:7])
    print("\nseed, z(k_vf mean), z(k_vf spread), z(vcf_gain mean), z(vcf_gain spread), z(prediction, k_vf random), "
          "z(prediction, both random), prediction stderr (rel, k_vf random):")
    for r in rows:
        print("  ", r[0], *(f"{v:+.2f}" for v in r[1:7]), f"{r[7]:.4f}")


@pytest.mark.slow
def test_a_device_with_few_points_is_shrunk_toward_the_lot_mean(tmp_path):
    """Noisy rate tables (300 deg/sqrt(h)), 8 devices: device 0 keeps only its rates up to 20 deg/s (~10x less
    precise in k_vf). Its shrunken estimate lies between its independent estimate and the lot mean, moved by a
    larger share than the well-measured devices', by about the Gaussian weight C / (C + s^2); its stderr shrinks
    too. The CLI's --population writes the same population in its JSON. (8 devices, not fewer: the lot shapes of
    the test above, whose k_vf-random fit compiled the programs this one runs.)"""
    noise = gj.RateNoise(arw_dps_per_sqrt_h=300.0, bias_instability_dph=0.0)
    table = _lot_table(8, seed=6, few=(0,), noise=noise)
    alone = gj.identify("paper-qmg", table, progress=False)
    pf = gj.identify("paper-qmg", table, lot_solve=gj.PopulationSolve(random=("k_vf",)), progress=False)
    assert pf.converged, pf.warnings
    i = alone.names.index("k_vf")
    b, c = np.log(np.asarray(alone.values[:, i])), np.asarray(alone.stderr[:, i] / alone.values[:, i])
    m = np.log(pf.estimates[:, 0])
    mu, s = pf.hyper[0], math.exp(pf.hyper[1])
    share = (b - m) / (b - mu)  # 0: not moved, 1: moved onto the lot mean
    assert c[0] > 5 * c[1:].max()
    assert 0 < share[0] < 1 and share[0] > 3 * np.abs(share[1:]).max(), share
    assert abs(share[0] - c[0] ** 2 / (c[0] ** 2 + s**2)) < 0.15, (share[0], c[0], s)
    assert pf.estimates_stderr[0, 0] < np.asarray(alone.stderr[0, i])

    path = tmp_path / "lot.csv"
    gj.write_table(table, path)
    out = tmp_path / "fit.json"
    code = main(["identify", str(path), "--population", "k_vf", "--json", str(out)])
    assert code == 0
    report = json.loads(out.read_text())["population"]
    assert report["random"] == ["k_vf"] and report["converged"]
    (p,) = report["parameters"]
    assert p["mean"] == pytest.approx(pf.parameters[0].mean, rel=1e-6)
    assert set(p) >= {"mean", "mean_stderr", "spread", "spread_stderr"}
    assert report["devices"][0]["estimates"]["k_vf"]["value"] == pytest.approx(pf.estimates[0, 0], rel=1e-6)


@pytest.mark.slow
def test_a_64_device_lot_mean_and_spread_recovered_within_their_standard_errors():
    """The issue's lot size: 64 devices of known spread (k_vf drawn as k0 (1 + 0.01 z)), 4 of them without a rate
    table: the lot's mean and spread of k_vf within 3 of their standard errors of the generator's (measured at
    seed 21: z -0.80 and -0.19, spread 0.98 +/- 0.09 %); the 4 without a rate table are said to be undetermined
    (their scale factor rests on the DAC gain too, which neither their data nor the lot distribution fix)."""
    table = _lot_table(64, 21, no_rate=(60, 61, 62, 63))
    pf = gj.identify("paper-qmg", table, lot_solve=gj.PopulationSolve(random=("k_vf",)), progress=False)
    assert pf.converged, pf.warnings
    (p,) = pf.parameters
    # the generator's log-mean: E log(1 + sigma z) = -sigma^2 / 2
    z_mean = (math.log(p.mean / K0) + SIGMA**2 / 2) / (p.mean_stderr / p.mean)
    z_spread = (p.relative_spread - SIGMA) / (p.spread_stderr / p.mean)
    print(f"\n64 devices: z(k_vf mean) {z_mean:+.2f}, z(k_vf spread) {z_spread:+.2f}")
    assert abs(z_mean) < 3 and abs(z_spread) < 3
    # Without a rate table a device's VCF sweep fixes vcf_gain / (k_vf g_dac) and the lot fixes k_vf, but its scale
    # factor needs k_vf g_dac: with only k_vf random it is not determined, and the fit says so instead of printing NaN
    assert np.all(np.isfinite(pf.sf[:60])) and np.all(np.isnan(pf.sf[60:]))
    (w,) = [w for w in pf.warnings if "not determined" in w]
    assert all(d in w for d in pf.fit.devices[60:]) and "random=" in w and "dac_gain_error" in w, w
    text = pf.summary()
    assert "nan" not in text.lower() and f"{pf.fit.devices[60]}: SF not determined" in text
