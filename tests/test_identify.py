"""identify: recovery within the reported uncertainty, identifiability, non-convergence said, priors,
save/load, and the CLI's JSON.

One simulated table (3 devices x 2 runs, rate table + static VCF + DAC: the demo's shapes, so that the
compiled fit is shared with test_diagnose in one session) and one fit serve most tests.
"""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj
from gyrojax import rate_table_points
from gyrojax._model.residuals import device_residuals, run_biases


LOT = {"devices": 3, "runs": 2, "sweeps": ("rate_table", "vcf_static", "dac"), "seed": 11}


@pytest.fixture(scope="module")
def csv_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("identify") / "lot.csv"
    gj.write_table(gj.simulate_table(gj.paper_qmg(), **LOT), path)
    return path


@pytest.fixture(scope="module")
def table(csv_path):
    # Read back from the file, as the CLI does: the data's source is part of the compiled function's key.
    return gj.read_table(csv_path)


@pytest.fixture(scope="module")
def fit(table):
    return gj.identify("paper-qmg", table)


@pytest.fixture(scope="module")
def rate_only(table):
    return gj.Table({k: table[k][table["sweep"] == "rate_table"] for k in table.columns}, source="rate-only")


# A rate table alone with k_vf and angular_gain free and a prior on angular_gain. The vague prior (sigma
# 1000x the value) informs nothing but gives every fit below the same array shapes: one compiled function.
VAGUE = {"angular_gain": (1.0, 1e3)}


@pytest.fixture(scope="module")
def truth():
    return gj.campaign_lot(gj.paper_qmg(), devices=LOT["devices"], seed=LOT["seed"])


def _device(lot, i):
    return jax.tree.map(lambda x: x[i] if hasattr(x, "ndim") and x.ndim >= 1 else x, lot)


def _slope(fn, gyro, temp):
    """d(output)/d(input) at zero input of a settled sweep, LSB per input unit."""
    return jax.jvp(lambda x: fn(gyro, x[None], jnp.asarray(temp)[None]).rate[0], (jnp.zeros(()),),
                   (jnp.ones(()),))[1]


@pytest.mark.slow
def test_fit_converges_with_chi2_near_one(fit):
    assert fit.all_converged
    assert fit.check() is fit
    # 3 devices x (2 runs x (22 rate + VCF points) + DAC points): chi2_red of a correct model is ~1 +/- 0.1
    assert 0.8 < fit.chi2_red_total < 1.2
    assert fit.devices == tuple(f"paper-qmg-{i:03d}" for i in range(3))


@pytest.mark.slow
def test_scale_factor_recovered_within_three_sigma(fit, truth):
    """The fitted zero-rate SF against each true device's, both at the fit's reporting temperature."""
    from gyrojax._identify.problem import sf_temperature

    temps = sf_temperature(fit.data)
    true_sfs = np.asarray(eqx.filter_jit(eqx.filter_vmap(lambda g, t: _slope(rate_table_points, g, t)))(truth, temps))
    for i in range(3):
        true_sf = float(true_sfs[i])
        sf, se = float(fit.scale_factor[i]), float(fit.scale_factor_stderr[i])
        assert 0 < se < 1e-5 * abs(sf)  # a few ppm: 44 points per device at ~0.5 mdeg/s noise
        assert abs(sf - true_sf) < 3 * se, (i, sf, true_sf, se)
    # the lot spread (1 % electrodes, 0.5 % mass) is resolved: the devices' SFs differ by many sigma
    sfs = np.asarray(fit.scale_factor)
    assert np.ptp(sfs) > 100 * float(np.max(fit.scale_factor_stderr))


@pytest.mark.slow
def test_vcf_ratio_and_dac_gain_recovered_within_three_sigma(fit, truth):
    """The VCF output sees K_svf / K_vf (virtual force balanced by the feedback force); the DAC sweep pins
    the DAC gain, whose true error is zero."""
    i_kvf, i_vcf, i_dac = (fit.names.index(n) for n in ("k_vf", "vcf_gain", "dac_gain_error"))
    for i in range(3):
        true_ratio = float(truth.vcf_electrode.force_per_volt2[i] / truth.feedback_electrode.k_vf[i])
        ratio = float(fit.values[i, i_vcf] / fit.values[i, i_kvf])
        cov = np.asarray(fit.covariance[i])  # internal (log) coordinates: var(u_vcf - u_kvf)
        se = ratio * np.sqrt(cov[i_vcf, i_vcf] + cov[i_kvf, i_kvf] - 2 * cov[i_vcf, i_kvf])
        assert abs(ratio - true_ratio) < 3 * se, (i, ratio, true_ratio, se)
        assert abs(float(fit.values[i, i_dac])) < 3 * float(fit.stderr[i, i_dac])
        assert float(fit.stderr[i, i_dac]) < 1e-4


@pytest.mark.slow
def test_closed_loop_data_cannot_see_the_sense_mode(fit):
    """Force rebalance holds the sense mode at rest: omega_y and q_y are named and held, not fitted."""
    held = {u.held for u in fit.unidentifiable}
    assert held == {"omega_y", "q_y"}
    for name in ("omega_y", "q_y"):
        k = fit.names.index(name)
        assert not fit.free[k]
        assert np.all(np.isnan(np.asarray(fit.stderr[:, k])))
        np.testing.assert_array_equal(np.asarray(fit.values[:, k]), np.asarray(fit.values[0, k]))
    assert "unidentifiable: omega_y" in fit.summary()


@pytest.mark.slow
def test_product_combination_is_named_and_one_held(rate_only):
    """A rate table alone sees only Ag m a w / K_vf: with k_vf and angular_gain free, the direction is
    named with both and the later one in PARAMETERS' order (angular_gain) held."""
    f = gj.identify("paper-qmg", rate_only, free=("k_vf", "angular_gain"), priors=VAGUE, evaluate_only=True)
    combo = [u for u in f.unidentifiable if len(u.parameters) > 1]
    assert len(combo) == 1
    assert set(combo[0].parameters) == {"k_vf", "angular_gain"}
    assert combo[0].held == "angular_gain"
    assert f.free == (True, False)
    assert "unidentifiable: k_vf x angular_gain" in f.summary()


@pytest.mark.slow
def test_a_prior_pulls_and_fixes_the_combination(rate_only):
    """A design value with a tight tolerance on angular_gain makes the product identifiable: Ag lands on
    the prior and K_vf follows, keeping the measured SF (Ag / K_vf)."""
    ag = 1.002  # the preset's Ag is 1.0 (an ASSUMPTION there); +0.2 % is one lot sigma
    f = gj.identify("paper-qmg", rate_only, free=("k_vf", "angular_gain"), priors={"angular_gain": (ag, 1e-5)})
    base = gj.identify("paper-qmg", rate_only, free=("k_vf", "angular_gain"), priors=VAGUE)
    assert f.all_converged and base.all_converged
    assert f.free == (True, True) and f.unidentifiable == ()
    np.testing.assert_allclose(np.asarray(f.value("angular_gain")), ag, rtol=3e-5)
    np.testing.assert_allclose(np.asarray(f.value("k_vf")) / np.asarray(base.value("k_vf")), ag, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(f.scale_factor), np.asarray(base.scale_factor), rtol=1e-6)


@pytest.mark.slow
def test_more_starts_keep_each_devices_best_solve_and_its_evaluation(rate_only):
    """MultiStart(starts=3): per device the lowest chi2 of three solves (never above the single start's), and
    the evaluation the Fit reports is that of the solve it kept (the fitted model evaluated again gives the same
    residuals)."""
    options = dict(free=("k_vf", "angular_gain"), priors=VAGUE)
    one = gj.identify("paper-qmg", rate_only, **options)
    three = gj.identify("paper-qmg", rate_only, start=gj.MultiStart(starts=3, spread=0.05), **options)
    assert three.all_converged
    assert np.all(np.asarray(three.chi2) <= np.asarray(one.chi2) * (1 + 1e-9))
    again = gj.identify(three.model, rate_only, evaluate_only=True, **options)
    np.testing.assert_allclose(np.asarray(again.residual_vector), np.asarray(three.residual_vector), rtol=0,
                               atol=1e-6)


# BFGS stopped at 5 steps: the retry test below reuses this compiled solve.
NOT_CONVERGED = dict(free=("k_vf", "angular_gain"), priors=VAGUE, solver="bfgs", max_steps=5)
NO_RETRY = (gj.DecrementCertificate(), gj.RestartRunoffs())  # the default recovery without the retry


@pytest.mark.slow
def test_a_fit_that_cannot_converge_says_so(rate_only):
    f = gj.identify("paper-qmg", rate_only, recovery=NO_RETRY, **NOT_CONVERGED)
    assert not bool(np.any(np.asarray(f.converged)))
    assert all("Try:" in m and "max_steps" in m for m in f.result_message)
    with pytest.raises(RuntimeError, match="did not converge for paper-qmg-000: .*max_steps"):
        f.check()
    assert "NOT CONVERGED" in f.summary()


@pytest.mark.slow
def test_a_solve_stopped_near_the_minimum_is_certified_by_the_gauss_newton_decrement(rate_only):
    """A solve that stops at max_steps counts as converged when a full Gauss-Newton step from there would gain
    less than the DecrementCertificate's tol in chi2, device by device. The BFGS solve stopped at 5 steps above
    is left far from the minimum; its decrement is checked against the chi2 each device still had to gain (the
    converged fit's), and tolerances around it certify exactly the devices below them."""
    base = gj.identify("paper-qmg", rate_only, free=("k_vf", "angular_gain"), priors=VAGUE)
    stopped = gj.identify("paper-qmg", rate_only, recovery=(gj.DecrementCertificate(0.0),), **NOT_CONVERGED)
    assert not np.any(np.asarray(stopped.converged))
    gap = np.asarray(stopped.chi2) - np.asarray(base.chi2)  # per device, the chi2 left to gain
    assert np.all(gap > 0) and len(set(np.round(np.log10(gap), 3))) == len(gap)
    f = gj.identify("paper-qmg", rate_only, recovery=(gj.DecrementCertificate(2 * gap.max()),), **NOT_CONVERGED)
    assert f.all_converged
    prefix = "converged (stopped at max_steps=5, where a full Gauss-Newton step would lower chi2 by only "
    assert all(m.startswith(prefix) for m in f.result_message)
    decrement = [float(m[len(prefix):].split(" <")[0]) for m in f.result_message]
    # the problem is nearly linear in k_vf: the decrement is the gap
    np.testing.assert_allclose(decrement, gap, rtol=5e-3)  # as printed: 3 digits
    np.testing.assert_array_equal(np.asarray(f.u), np.asarray(stopped.u))
    tol = np.sort(gap)[1]  # between the smallest gap and the others
    g = gj.identify("paper-qmg", rate_only, recovery=(gj.DecrementCertificate(tol * (1 + 1e-6)),), **NOT_CONVERGED)
    np.testing.assert_array_equal(np.asarray(g.converged), gap < tol * (1 + 1e-6))
    assert sum(np.asarray(g.converged)) == 2


@pytest.mark.slow
def test_a_solve_that_did_not_converge_is_retried_with_gauss_newton(rate_only):
    """BFGS stopped at max_steps=5 is solved again from the start with Gauss-Newton (5 steps here), which
    lands on the Levenberg-Marquardt fit, and the message says so; without that recovery policy the failure
    stands."""
    kw = NOT_CONVERGED
    f = gj.identify("paper-qmg", rate_only, **kw)
    base = gj.identify("paper-qmg", rate_only, free=("k_vf", "angular_gain"), priors=VAGUE)
    assert f.all_converged
    assert all("re-solved from the start with gauss-newton after bfgs did not converge" in m
               for m in f.result_message)
    assert np.all(np.asarray(f.num_steps) > 5)  # both solves counted
    np.testing.assert_allclose(np.asarray(f.scale_factor), np.asarray(base.scale_factor), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(f.chi2_red), np.asarray(base.chi2_red), rtol=1e-7)
    g = gj.identify("paper-qmg", rate_only, recovery=NO_RETRY, **kw)
    assert not np.any(np.asarray(g.converged))
    assert all("Try:" in m for m in g.result_message)
    assert not any("re-solved" in m for m in g.result_message)


@pytest.mark.slow
def test_a_joint_solve_that_did_not_converge_is_retried_as_a_whole(table):
    """A joint fit (lot-shared DAC gain error) whose BFGS solve stops at max_steps=5 is solved again, all
    devices at once, with Gauss-Newton: the result is that of a Gauss-Newton fit, every device says so.
    (Rate table + DAC sweep only: the static VCF sweep would double the compiled model and add nothing.)"""
    keep = table["sweep"] != "vcf_static"
    rate_dac = gj.Table({k: table[k][keep] for k in table.columns}, source="rate+dac")
    kw = dict(shared=("dac_gain_error",), max_steps=5)
    f = gj.identify("paper-qmg", rate_dac, solver="bfgs", **kw)
    g = gj.identify("paper-qmg", rate_dac, solver="gauss-newton", **kw)
    assert f.all_converged and g.all_converged
    assert all("re-solved from the start with gauss-newton after bfgs" in m for m in f.result_message)
    np.testing.assert_array_equal(np.asarray(f.u), np.asarray(g.u))
    np.testing.assert_array_equal(np.asarray(f.u_lot), np.asarray(g.u_lot))


@pytest.mark.slow
def test_a_lot_of_the_same_shapes_reuses_the_traced_fit(rate_only, monkeypatch):
    """The compiled fit sees arrays and shapes only: a second lot with the same shapes but other device names,
    run ids and source, or without output_sigma, is fitted without tracing anything again, and gives the same
    numbers under its own labels. Python functions called inside the compiled fit count its traces: one device's
    residuals and run biases (their own jits, keyed by one device's shapes) and the evaluation at the solve's
    end (traced with the lot's solve)."""
    from gyrojax._identify.evaluation import final_evaluation

    traced = []
    monkeypatch.setattr("gyrojax._identify.problem.device_residuals",
                        lambda *a, **k: traced.append("residuals") or device_residuals(*a, **k))
    monkeypatch.setattr("gyrojax._identify.evaluation.run_biases",
                        lambda *a, **k: traced.append("biases") or run_biases(*a, **k))
    monkeypatch.setattr("gyrojax._identify.strategies.final_evaluation",
                        lambda *a, **k: traced.append("solve") or final_evaluation(*a, **k))
    # In-process reuse only: a program exported to the cache folder by an earlier run would load untraced.
    monkeypatch.setattr("gyrojax._compile.export._folder", lambda: None)
    options = dict(free=("k_vf", "angular_gain"), priors=VAGUE)
    a = gj.identify("paper-qmg", rate_only, **options)  # traced here or by an earlier test
    cols = dict(rate_only.columns)
    cols["device"] = np.asarray(["other-" + d for d in cols["device"]])
    cols["run"] = cols["run"] + 7
    relabelled = gj.Table(cols, source="another lot")
    no_sigma = gj.Table({k: v for k, v in cols.items() if k != "output_sigma"}, source="a lot without sigmas")
    traced.clear()
    b = gj.identify("paper-qmg", relabelled, **options)
    c = gj.identify("paper-qmg", no_sigma, estimate_noise=False, **options)
    assert traced == []
    assert b.devices == tuple("other-" + d for d in a.devices) and b.data.run_ids("rate_table")[0] == (7, 8)
    assert "another lot" in b.summary()
    for name in ("values", "stderr", "chi2", "scale_factor"):
        np.testing.assert_array_equal(np.asarray(getattr(b, name)), np.asarray(getattr(a, name)))
    assert not c.data.weighted and float(np.asarray(c.chi2)[0]) != float(np.asarray(a.chi2)[0])
    # The counter does see a trace: a lot of two devices is another shape (of the lot's solve, not of one device).
    two = rate_only.select(np.flatnonzero(rate_only["device"] != a.devices[-1]))
    gj.identify("paper-qmg", two, evaluate_only=True, **options)
    assert traced == ["solve"]
    # A lot of four is padded, like the three, to four devices (VmapSolve's bucket): the same compiled fit, and
    # each device's numbers are its own (the fourth is a copy of the first under another name).
    first = np.asarray(rate_only["device"]) == a.devices[0]
    extra = {k: np.asarray(v)[first] for k, v in rate_only.columns.items()}
    extra["device"] = np.full(int(first.sum()), "copy-of-000")
    four = gj.Table({k: np.concatenate([np.asarray(v), extra[k]]) for k, v in rate_only.columns.items()},
                    source="four devices")
    traced.clear()
    d = gj.identify("paper-qmg", four, **options)
    assert traced == [] and d.devices == a.devices + ("copy-of-000",)
    for name in ("values", "stderr", "chi2"):
        got, want = np.asarray(getattr(d, name)), np.asarray(getattr(a, name))
        np.testing.assert_array_equal(got[:3], want)
        np.testing.assert_array_equal(got[3], want[0])
    # The step budget is a traced value of the solve: a fit retried with another max_steps traces nothing, and
    # one step short of converging (5 steps here) says so.
    short = gj.identify("paper-qmg", rate_only, max_steps=1, **options)
    assert traced == [] and np.all(np.asarray(a.num_steps) > 1)
    assert short.status == ("not converged",) * 3 and np.all(np.asarray(short.num_steps) == 1)
    assert all(m.startswith("The maximum number of steps was reached") for m in short.result_message)


@pytest.mark.slow
def test_bad_names_are_refused(table):
    with pytest.raises(ValueError, match="unknown parameter 'k_vff' in free"):
        gj.identify("paper-qmg", table, free=("k_vff",))
    with pytest.raises(ValueError, match="'mass' .* is not a parameter of this fit"):
        gj.identify("paper-qmg", table, hold=("mass",))
    with pytest.raises(ValueError, match="starts must be an integer >= 1"):
        gj.identify("paper-qmg", table, start=gj.MultiStart(starts=0))
    with pytest.raises(TypeError, match="recovery must be a tuple of gyrojax.AbstractRecovery policies"):
        gj.identify("paper-qmg", table, recovery=gj.RestartRunoffs())
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match=r"max_steps must be an integer >= 1, got " + repr(bad)):
            gj.identify("paper-qmg", table, max_steps=bad)


@pytest.mark.slow
def test_save_load_round_trip_is_exact(fit, tmp_path):
    path = tmp_path / "lot.fit"
    gj.save_fit(fit, path)
    back = gj.load_fit(path)
    a, ta = jax.tree.flatten(fit)
    b, tb = jax.tree.flatten(back)
    assert ta == tb  # static fields too: names, free, devices, messages, unidentifiable, entries
    for x, y in zip(a, b):
        assert type(x) is type(y)
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        assert np.asarray(x).dtype == np.asarray(y).dtype
    assert back.unidentifiable == fit.unidentifiable
    assert back.summary() == fit.summary()


@pytest.mark.slow
def test_load_refuses_foreign_and_corrupt_files(fit, tmp_path):
    foreign = tmp_path / "data.csv"
    foreign.write_text("device,run\n")
    with pytest.raises(ValueError, match=r"data\.csv: not a gyrojax fit file"):
        gj.load_fit(foreign)
    path = tmp_path / "lot.fit"
    gj.save_fit(fit, path)
    raw = bytearray(path.read_bytes())
    raw[-10] ^= 0xFF
    bad = tmp_path / "flipped.fit"
    bad.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"flipped\.fit: corrupt gyrojax fit file: .*checksum"):
        gj.load_fit(bad)
    cut = tmp_path / "cut.fit"
    cut.write_bytes(bytes(raw[:20]))
    with pytest.raises(ValueError, match=r"cut\.fit: corrupt gyrojax fit file"):
        gj.load_fit(cut)


@pytest.mark.slow
def test_fit_report_json_keys(fit):
    report = gj.fit_report(fit)
    json.dumps(report, allow_nan=False)
    assert set(report) >= {"devices", "lot", "unidentifiable"}
    d = report["devices"][1]
    assert set(d) >= {"parameters", "scale_factor_lsb_per_dps", "scale_factor_stderr", "chi2_red", "converged"}
    assert d["scale_factor_lsb_per_dps"] == float(fit.scale_factor[1])
    assert d["parameters"]["k_vf"] == {"value": float(fit.values[1, 0]), "stderr": float(fit.stderr[1, 0]),
                                       "held": False}
    assert d["parameters"]["q_y"]["stderr"] is None and d["parameters"]["q_y"]["held"]
    assert report["unidentifiable"] == ["omega_y", "q_y"]
    assert report["lot"] == {}
    # noise-only lot, right model: the comparison finds the chi2 at the noise level and no structure
    assert report["compare"]["points"] == 396 and not report["compare"]["fails"]
    assert not any(f["flagged"] for f in report["compare"]["findings"])


@pytest.mark.slow
def test_cli_identify(csv_path, tmp_path, capsys):
    from gyrojax.cli import main

    data = csv_path
    out, saved = tmp_path / "fit.json", tmp_path / "lot.fit"
    assert main(["identify", str(data), "--json", str(out), "--save", str(saved)]) == 0
    report = json.loads(out.read_text())
    assert [d["device"] for d in report["devices"]] == ["paper-qmg-000", "paper-qmg-001", "paper-qmg-002"]
    assert all(d["converged"] for d in report["devices"])
    assert all(0.5 < d["chi2_red"] < 1.5 for d in report["devices"])
    back = gj.load_fit(saved)
    assert back.data.source == str(data)
    np.testing.assert_array_equal(np.asarray(back.scale_factor),
                                  [d["scale_factor_lsb_per_dps"] for d in report["devices"]])
    printed = capsys.readouterr().out
    assert "chi2_red" in printed and "model against measurement: chi2" in printed
    # data errors: exit 2, no traceback
    assert main(["identify", str(tmp_path / "missing.csv")]) == 2
    assert main(["identify", str(data), "--free", "k_vf,nope"]) == 2
    err = capsys.readouterr().err
    assert "missing.csv" in err and "unknown parameter 'nope'" in err and "Traceback" not in err


_SHARDED = r"""
import json, sys
import jax
import numpy as np
import gyrojax as gj

assert len(jax.devices()) == 8, jax.devices()
fit = gj.identify("paper-qmg", gj.read_table(sys.argv[1]), free=("k_vf", "angular_gain"),
                  priors={"angular_gain": (1.0, 1e3)}, lot_solve=gj.VmapSolve(shard=True))
json.dump({"values": np.asarray(fit.values).tolist(), "stderr": np.asarray(fit.stderr).tolist(),
           "chi2": np.asarray(fit.chi2).tolist(), "converged": np.asarray(fit.converged).tolist()},
          open(sys.argv[2], "w"))
"""


@pytest.mark.slow
def test_lot_sharded_over_eight_cpu_devices_gives_the_same_fit(rate_only, tmp_path):
    """The device axis over 8 forced CPU devices (3 devices padded to 8) against the one-device fit (the
    rate-only fit of the tests above: a fresh process compiles everything, and this is the smallest model)."""
    import os
    import subprocess
    import sys

    fit = gj.identify("paper-qmg", rate_only, free=("k_vf", "angular_gain"), priors=VAGUE)
    csv_path = tmp_path / "rate-only.csv"
    gj.write_table(rate_only, csv_path)
    out = tmp_path / "sharded.json"
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=8", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", _SHARDED, str(csv_path), str(out)], env=env,
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(out.read_text())
    assert all(got["converged"])
    free = np.asarray(fit.free)
    # the same optimum to a thousandth of a standard error (the solver's tolerance, not the noise)
    diff = np.abs(np.asarray(got["values"]) - np.asarray(fit.values))[:, free]
    assert np.all(diff < 1e-3 * np.asarray(fit.stderr)[:, free]), diff / np.asarray(fit.stderr)[:, free]
    np.testing.assert_allclose(np.asarray(got["stderr"])[:, free], np.asarray(fit.stderr)[:, free], rtol=1e-4)
    np.testing.assert_allclose(got["chi2"], np.asarray(fit.chi2), rtol=1e-6)


def test_chunks_map_like_vmap_with_padding_and_empty_leaves():
    """VmapSolve(chunk=N)'s machinery: the lot padded to a multiple of N (copies of the last device, then
    dropped), jax.lax.map over vmapped chunks, equal to one vmap, with an empty (device, 0) leaf as the
    priors are. (Every identify of more than 16 devices runs chunked on a CPU: the Monte Carlo test's 100.)"""
    from gyrojax._identify.strategies import LotSpread, map_devices

    n = 5
    tree = {"a": jnp.arange(n * 3.0).reshape(n, 3), "empty": jnp.zeros((n, 0)), "b": jnp.linspace(1.0, 2.0, n)}

    def f(t, y):
        return {"s": jnp.sum(t["a"] ** 2) * t["b"] + y, "e": t["empty"] * 2.0}

    y = jnp.linspace(-1.0, 1.0, n)
    want = jax.vmap(f)(tree, y)
    spread = LotSpread(n, 1, 2)
    assert spread.chunk == 2 and spread.multiple == 2
    padded_tree, padded_y = spread.pad(tree, y)
    assert padded_y.shape == (6,)
    got = spread.unpad(map_devices(f, spread.chunk, padded_tree, padded_y))
    np.testing.assert_array_equal(np.asarray(got["s"]), np.asarray(want["s"]))
    assert got["e"].shape == (n, 0)
    assert LotSpread(n, 1, 16).chunk is None  # a chunk as large as the lot: one vmap


@pytest.mark.slow
def test_lot_chunk_is_checked(table):
    with pytest.raises(ValueError, match="chunk must be .auto., None or an integer >= 1"):
        gj.VmapSolve(chunk=0)
    with pytest.raises(ValueError, match="shared parameters need JointSolve"):
        gj.identify("paper-qmg", table, lot_solve=gj.VmapSolve(chunk=2), shared=("dac_gain_error",))


@pytest.mark.slow
def test_lot_strategies_are_checked_and_the_shortcuts_name_them(table):
    """A lot strategy object takes shard and chunk itself, and must match the fit (joint where parameters are
    shared); the strings are shortcuts for the same objects."""
    with pytest.raises(ValueError, match="shared parameters need JointSolve"):
        gj.identify("paper-qmg", table, lot_solve=gj.VmapSolve(chunk=2), shared=("dac_gain_error",))
    with pytest.raises(ValueError, match="a joint solve, which needs shared parameters"):
        gj.identify("paper-qmg", table, lot_solve=gj.JointSolve())
    with pytest.raises(ValueError, match="lot_solve must be a lot strategy"):
        gj.identify("paper-qmg", table, lot_solve="sharded")
    from gyrojax._identify.shortcuts import lot_solve_from

    assert lot_solve_from("vmap", joint=False) == gj.VmapSolve()
    assert lot_solve_from("loop", joint=False) == gj.LoopSolve()
    assert lot_solve_from("vmap", joint=True) == gj.JointSolve()
    assert lot_solve_from("loop", joint=True) == gj.JointSolve(shard=False)
    at_start = gj.identify("paper-qmg", table, evaluate_only=True, lot_solve="loop", progress=False)
    same = gj.identify("paper-qmg", table, evaluate_only=True, lot_solve=gj.LoopSolve(), progress=False)
    np.testing.assert_array_equal(np.asarray(same.residual_vector), np.asarray(at_start.residual_vector))


def test_directions_the_data_no_longer_fix_at_the_solution_are_named():
    """A parameter that ran off to a flat region (its weighted-Jacobian column ~0 at the solution, as an open-loop
    Q_y did to 1e243 with the solver reporting success) is named in the device's message; a well-fixed device
    gets none."""
    from gyrojax._identify.identifiability import weak_at_solution

    rng = np.random.default_rng(0)
    fixed = rng.normal(size=(40, 3)) * 10.0
    wandered = fixed.copy()
    wandered[:, 2] = 1e-6  # Q_y's column once Q_y is huge: the data no longer move with it
    combo = fixed.copy()
    combo[:, 1] = combo[:, 0] + 1e-3 * rng.normal(size=40)  # two columns the data see only as a sum
    notes = weak_at_solution(np.stack([fixed, wandered, combo]), ["k_vf", "omega_y", "q_y"], 1.0)
    assert notes[0] == ""
    assert "no longer fix q_y (s = " in notes[1] and "k_vf" not in notes[1] and "prior" in notes[1]
    assert "k_vf x omega_y" in notes[2] and "q_y" not in notes[2]


def test_a_nonfinite_model_inside_the_compiled_fit_is_explained():
    """An error raised inside the compiled model (as the implicit derivative's linear solve does on NaN) comes
    out of identify as a RuntimeError that says where and what to try, with the original as its cause."""
    from gyrojax._identify.problem import nonfinite_explained

    @eqx.filter_jit
    def broken(x):
        return eqx.error_if(x, ~jnp.isfinite(x), "A linear solver received non-finite (NaN or inf) input")

    with pytest.raises(RuntimeError, match=r"not finite at the start \(the error inside the compiled model: 'A linear "
                       r"solver received non-finite \(NaN or inf\) input'\).*Try: starting closer") as info:
        with nonfinite_explained("at the start"):
            broken(jnp.asarray(jnp.nan))
    assert isinstance(info.value.__cause__, eqx.EquinoxRuntimeError)


@pytest.mark.slow
def test_open_loop_dynamic_sweep_fits_where_the_first_solve_runs_off():
    """seed 003's dynamic VCF sweep on a vcf-2018 lot: the sense resonance is ~0.1 Hz wide and the process
    spread moves it by several widths, so from the design start Levenberg-Marquardt's first steps overshoot
    and Q_y runs off towards infinity on some devices (and trial steps reach parameters without a steady
    state, which once raised inside the compiled fit). identify restarts those devices with Q_y held, then
    released: every device converges at chi2_red ~1, recovers the true sense resonance within 3 sigma, and
    says which devices were restarted."""
    lot_spec = {"devices": 3, "runs": 1, "seed": 7}
    table = gj.simulate_table(gj.vcf_2018(), sweeps=("vcf_dynamic",), **lot_spec)
    truth = gj.campaign_lot(gj.vcf_2018(), devices=lot_spec["devices"], seed=lot_spec["seed"])
    fit = gj.identify("vcf-2018", table)
    # The solve converges everywhere; the rate-table scale factor does not follow: a VCF sweep sees only
    # sense_gain x vcf_gain, and the SF moves with sense_gain alone (it would rest on K_svf's design value).
    assert all(m.startswith("converged") for m in fit.result_message), fit.summary()
    assert fit.status == ("not determined",) * 3, fit.summary()
    assert all(w[0].startswith("the data cannot fix sense_gain x vcf_gain") for w in fit.warnings), fit.summary()
    assert np.all(np.isnan(np.asarray(fit.scale_factor)))
    assert np.all(np.abs(np.asarray(fit.chi2) / np.asarray(fit.dof) - 1.0) < 0.5), fit.summary()
    restarted = [m for m in fit.result_message if "restarted with q_y held" in m]
    assert restarted, fit.summary()  # the design start does run off on this lot
    # What the sweep sees is the sense resonance relative to the drive (the drive resonance is held at its
    # design value, so omega_y alone is not comparable): the split d_y = (w_y^2 - w_x^2) / (2 w_x), fixed to
    # ~1e-8, and the damping rate w_y / (2 Q_y), seen only through the skirts of the 0.1 Hz-wide peak.
    values = np.asarray(fit.values)
    wy, qy = values[:, fit.names.index("omega_y")], values[:, fit.names.index("q_y")]
    wx = float(gj.vcf_2018().resonator.omega_x)
    r = truth.resonator
    t_wy, t_wx, t_qy = (np.asarray(x) for x in (r.omega_y, r.omega_x, r.q_y))
    split, t_split = (wy**2 - wx**2) / (2 * wx), (t_wy**2 - t_wx**2) / (2 * t_wx)
    assert np.max(np.abs(split / t_split - 1)) < 1e-6, (split, t_split)
    assert np.max(np.abs((wy / qy) / (t_wy / t_qy) - 1)) < 2e-3, (wy / qy, t_wy / t_qy)


def test_a_recovery_policy_is_a_small_object_on_the_solution_so_far():
    """DecrementCertificate on a hand-made solution (no compile): the device stopped at max_steps whose
    residuals a Gauss-Newton step cannot lower is certified, with the reason in its note; the one a step still
    improves stays stopped."""
    from gyrojax._identify.evaluation import Evaluation
    from gyrojax._identify.recovery import DecrementCertificate, Solution, Solving
    from gyrojax._identify.strategies import Lot
    from gyrojax._solution import RESULTS, result_code

    rng = np.random.default_rng(1)
    jac, r = rng.normal(size=(2, 10, 3)), rng.normal(size=(2, 10))
    r[0] -= jac[0] @ np.linalg.lstsq(jac[0], r[0], rcond=None)[0]  # at the minimum: r orthogonal to J
    final = Evaluation(r, jac, np.zeros((2, 10, 0)), np.zeros(2), np.zeros((2, 3)), np.zeros((2, 0)), {}, {},
                       np.zeros(2, dtype=int))
    stopped = result_code(RESULTS.nonlinear_max_steps_reached)
    solution = Solution(np.zeros((2, 3)), np.zeros(0), np.full(2, stopped), np.full(2, 200), np.sum(r**2, axis=-1),
                        np.zeros((2, 3)), final, ("", ""))
    solving = Solving(None, Lot(gj.VmapSolve(chunk=None, shard=False), 2), None, "levenberg-marquardt", 200,
                      0, (0, 1, 2), ("k_vf", "angular_gain", "vcf_gain"), 1.0)
    out = DecrementCertificate(1e-6)(solving, solution)
    assert out.code[0] == result_code(RESULTS.successful) and out.code[1] == stopped
    assert out.notes[0].startswith("stopped at max_steps=200, where a full Gauss-Newton step would lower chi2 by")
    assert out.notes[1] == ""
    assert DecrementCertificate(0.0)(solving, solution).code.tolist() == [stopped, stopped]


def test_the_default_free_parameters_add_what_the_data_sweeps_read():
    """`free=None` frees `DEFAULT_FREE` and each parameter a sweep kind of the data reads beyond it: the dynamic
    VCF's angular gain on a closed-loop device (not on an open-loop one: no rebalance loop), the drive frequency's
    omega_x; a rate table alone reads nothing more."""
    from gyrojax._model.fitdata import fit_data

    def table(sweeps):
        n = len(sweeps)
        return gj.Table.from_columns({
            "device": ["d"] * n, "run": [0] * n, "sweep": list(sweeps), "input": [10.0 * (i + 1) for i in range(n)],
            "output": [1000.0 * (i + 1) for i in range(n)], "output_sigma": [1.0] * n,
            "temperature_c": [25.0] * n})

    base = gj.identification.DEFAULT_FREE
    qmg, open_loop = gj.paper_qmg(), gj.vcf_2018()
    default_free = gj.identification.default_free
    assert default_free(qmg, fit_data(table(["rate_table"] * 3))) == base
    dynamic = fit_data(table(["rate_table"] * 2 + ["vcf_dynamic"] * 2))
    assert default_free(qmg, dynamic) == base + ("angular_gain",) and default_free(open_loop, dynamic) == base
    assert "omega_x" in default_free(qmg, fit_data(table(["rate_table", "drive_frequency", "drive_frequency"])))
    assert gj.FitSpec().free is None


@pytest.mark.slow
def test_a_closed_loop_lot_with_a_dynamic_vcf_fits_its_own_simulation():
    """paper-qmg devices on a rate table and a dynamic VCF: the peak of the rebalance loop's response follows
    K_vf / m, the scale factor Ag m / K_vf, so the angular gain's 0.2 % process spread, held at the design value,
    left both devices of this lot rejected (chi2_red 111 and 3.2); the baseline frees it (the dynamic sweep reads
    it), fits at chi2_red ~1 and recovers each device's Ag."""
    spec = {"devices": 2, "seed": 7}
    freqs = tuple(10.0 * k for k in range(1, 31))
    table = gj.simulate_table(gj.paper_qmg(), sweeps=("rate_table", gj.sweeps.VcfDynamic(frequencies_hz=freqs)),
                              progress=False, **spec)
    fit = gj.identify("paper-qmg", table, progress=False)
    assert fit.status == ("ok", "ok"), fit.summary()
    k = fit.names.index("angular_gain")
    assert fit.free[k], fit.summary()
    truth = np.asarray(gj.campaign_lot(gj.paper_qmg(), **spec).resonator.angular_gain)
    values, stderr = np.asarray(fit.values)[:, k], np.asarray(fit.stderr)[:, k]
    assert np.all(np.abs(values - truth) < 3 * stderr), (values, truth, stderr)
