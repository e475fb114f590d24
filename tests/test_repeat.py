"""The power-on repeatability guard (gyrojax/_diagnose/repeat.py): a device property fitted on the other runs of a
device predicts the held-out run; a misfit whose projection changes from run to run does not."""

import types

import numpy as np
import pytest
from _experiments import discovery_diagnosis

from gyrojax._diagnose.repeat import (
    absent_run,
    held_out_change,
    repeatability_guard,
    run_factors,
    run_heterogeneity,
    run_of_rows,
)


def _fake_fit(coef_per_run, *, n_dev=4, n_run=2, n_pt=20, seed=0):
    """A Fit-like object: one sweep, a free bias per run, a candidate column `c.x` (a smooth curve) whose
    coefficient in the residuals is `coef_per_run[r]` (per device the same), unit noise."""
    rng = np.random.default_rng(seed)
    t = np.linspace(-1.0, 1.0, n_pt)
    rows = n_run * n_pt
    jac = np.zeros((n_dev, rows, n_run + 1))
    res = np.zeros((n_dev, rows))
    for r in range(n_run):
        sl = slice(r * n_pt, (r + 1) * n_pt)
        jac[:, sl, r] = 1.0  # the run's free bias
        jac[:, sl, n_run] = t**2
        res[:, sl] = coef_per_run[r] * t**2
    res += rng.normal(size=res.shape)
    block = types.SimpleNamespace(inputs=np.zeros((n_dev, n_run, n_pt)))
    data = types.SimpleNamespace(sweeps=("rate_table",), blocks={"rate_table": block})
    names = tuple(f"bias{r}" for r in range(n_run)) + ("c.x",)
    free = (True,) * n_run + (False,)
    return types.SimpleNamespace(residual_vector=res, jacobian=jac, names=names, free=free, data=data)


def test_rows_are_assigned_to_their_runs():
    fit = _fake_fit([1.0, 1.0, 1.0], n_run=3, n_pt=5)
    assert run_of_rows(fit).tolist() == [0] * 5 + [1] * 5 + [2] * 5


def test_a_device_property_predicts_the_held_out_run():
    # the same coefficient in both runs: the held-out chi2 falls by about the signal's chi2 there
    fit = _fake_fit([3.0, 3.0])
    change, folds = held_out_change(fit, "c")
    signal = 4 * 2 * 9.0 * np.sum((np.linspace(-1, 1, 20) ** 2 - np.mean(np.linspace(-1, 1, 20) ** 2)) ** 2)
    assert folds == 8
    assert 0.7 * signal < change < 1.3 * signal
    assert repeatability_guard(fit, "c", signal, 0.01) is None


def test_a_projection_that_changes_sign_between_runs_is_refused():
    # +3 in run 0, -3 in run 1: the score test sees both, the other run predicts the opposite
    fit = _fake_fit([3.0, -3.0])
    change, folds = held_out_change(fit, "c")
    assert change < 0 and folds == 8
    reason = repeatability_guard(fit, "c", 400.0, 0.01)
    assert reason is not None and "does not repeat from power-on to power-on" in reason
    q, df = run_heterogeneity(fit, "c")
    assert df == 4 and q > 100.0  # 4 devices x (2 runs - 1): the +3/-3 split is ~36 sigma^2 per device


def test_an_effect_of_one_power_on_is_absent_from_the_other():
    # the curve in run 0 only: the pooled fit gives it half its size, and run 1 carries none of it
    fit = _fake_fit([3.0, 0.0])
    (r0, a0, se0), (r1, a1, se1) = run_factors(fit, "c")
    assert (r0, r1) == (0, 1)
    assert a0 + a1 == pytest.approx(2.0, abs=1e-6)  # runs of equal information: the pooled change is their mean
    assert abs(a1) < 3 * se1 and 0.1 < se1 < 0.3
    assert absent_run(fit, "c", 0.01)[0] == 1
    reason = repeatability_guard(fit, "c", 200.0, 0.01)
    assert "run 1 carries" in reason and "some power-ons only" in reason


def test_a_device_property_is_present_in_every_run():
    # the same coefficient in every run: each run's factor is 1 within its error, at any signal, and a weak one is
    # refused at about the test's alpha over many seeds
    factors = run_factors(_fake_fit([3.0, 3.0, 3.0], n_run=3), "c")
    assert [r for r, _, _ in factors] == [0, 1, 2]
    assert all(abs(a - 1.0) < 4 * se for _, a, se in factors)
    refused = sum(absent_run(_fake_fit([0.5, 0.5], seed=seed), "c", 0.01) is not None for seed in range(40))
    assert refused <= 2


def test_one_run_has_no_fold():
    fit = _fake_fit([3.0], n_run=1)
    assert held_out_change(fit, "c") == (0.0, 0)
    assert repeatability_guard(fit, "c", 100.0, 0.01) is None
    assert run_heterogeneity(fit, "c") == (0.0, 0)
    assert run_factors(fit, "c") == [] and absent_run(fit, "c", 0.01) is None


def test_a_weak_device_property_is_not_refused_for_its_noise():
    # a stable coefficient at ~1.5 sigma per device: its coefficients fitted on one run carry their noise into
    # the other, so the held-out chi2 rises in most seeds; its run-to-run heterogeneity is chi2(4) noise
    refused, rising = 0, 0
    for seed in range(40):
        fit = _fake_fit([0.5, 0.5], seed=seed)
        rising += held_out_change(fit, "c")[0] <= 0
        refused += repeatability_guard(fit, "c", 20.0, 0.01) is not None
    assert rising >= 25  # what the held-out change alone would refuse
    assert refused <= 2  # the heterogeneity test's alpha, 0.4 expected


@pytest.mark.slow
def test_a_bias_wandering_from_run_to_run_is_not_a_zero_rate_tempco():
    # an independent generator's lot (plain NumPy): a bias following an unrecorded environment, its own slow
    # curve in each (device, run); the score test ranks zro_tempco first (S = 74, p = 3e-9), which the lot's
    # other guards passed before this one
    d = discovery_diagnosis("bias_env_wander", design="a", seed=3)
    assert d.selected == ()
    refused = {r.effect: r for r in d.rejected}
    assert refused["zro_tempco"].kind == "not repeatable"
    assert d.verdict == "unexplained"
