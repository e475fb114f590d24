"""The constancy guard (gyrojax/_diagnose/constancy.py): a library effect's coefficient is a constant of the device;
a misfit that holds part of its shape with a size that changes along a recorded coordinate is not that effect."""

import types

import numpy as np
import pytest
from _experiments import discovery_diagnosis

from gyrojax._diagnose.constancy import (
    MIN_DRIFT_SHARE,
    coefficient_drift,
    constancy_guard,
    drift_columns,
    row_coordinate,
)


def _fake_fit(size_at, *, n_dev=4, n_run=2, n_pt=20, seed=0, temperatures=True):
    """A Fit-like object: one sweep along an input s in [-1, 1], a free bias per run, a candidate column `c.x`
    (s^3) whose coefficient in the residuals is `size_at(T)` at the die temperature T (a warm-up from 25 to 31 C
    in each run), unit noise."""
    rng = np.random.default_rng(seed)
    s = np.linspace(-1.0, 1.0, n_pt)
    temp = np.broadcast_to(25.0 + 6.0 * (1 - np.exp(-np.arange(n_pt) / 6.0)), (n_dev, n_run, n_pt))
    rows = n_run * n_pt
    jac = np.zeros((n_dev, rows, n_run + 1))
    res = np.zeros((n_dev, rows))
    for r in range(n_run):
        sl = slice(r * n_pt, (r + 1) * n_pt)
        jac[:, sl, r] = 1.0  # the run's free bias
        jac[:, sl, n_run] = s**3
        res[:, sl] = size_at(temp[:, r]) * s**3
    res += rng.normal(size=res.shape)
    block = types.SimpleNamespace(inputs=np.broadcast_to(s, (n_dev, n_run, n_pt)),
                                  mask=np.ones((n_dev, n_run, n_pt), bool),
                                  temperatures=np.array(temp) if temperatures else None)
    data = types.SimpleNamespace(sweeps=("rate_table",), blocks={"rate_table": block})
    names = tuple(f"bias{r}" for r in range(n_run)) + ("c.x",)
    free = (True,) * n_run + (False,)
    return types.SimpleNamespace(residual_vector=res, jacobian=jac, names=names, free=free, data=data)


def test_each_row_reads_its_coordinate():
    fit = _fake_fit(lambda t: 0.0 * t, n_dev=2, n_pt=5)
    temp = row_coordinate(fit, "temperature_c")
    assert temp.shape == (2, 10)
    assert temp[0, 0] == 25.0 and temp[1, 5] == 25.0 and 27.0 < temp[0, 4] < 28.0
    assert np.all(np.isnan(row_coordinate(fit, "time_s")))  # not recorded
    assert drift_columns(fit, np.asarray(fit.jacobian)[:, :, 2:], "time_s").shape == (2, 10, 0)


def test_a_constant_coefficient_is_not_refused():
    # a strong compression, the same at every temperature: its drift along the temperature is chi2(4) noise
    refused, qs = 0, []
    for seed in range(40):
        fit = _fake_fit(lambda t: 3.0 + 0.0 * t, seed=seed)
        q, df = coefficient_drift(fit, "c", "temperature_c")
        qs.append(q)
        assert df == 4  # one drift column per device
        refused += constancy_guard(fit, "c", 300.0, 0.01) is not None
    assert 2.0 < np.mean(qs) < 6.5  # chi2(4): mean 4
    assert refused <= 2  # alpha 0.01 over 40 seeds: 0.4 expected


def test_a_coefficient_growing_with_temperature_is_refused():
    # -c (T - 25) s^3: a compression of c times the mean temperature excess, and a drift along T beside it
    fit = _fake_fit(lambda t: 1.0 * (t - 25.0))
    q, df = coefficient_drift(fit, "c", "temperature_c")
    assert df == 4 and q > 100.0
    reason = constancy_guard(fit, "c", 200.0, 0.01)
    assert reason is not None and reason.startswith("its size follows temperature_c")
    # a drift describing less than MIN_DRIFT_SHARE of what the constant part does is a second-order shape
    assert constancy_guard(fit, "c", q / MIN_DRIFT_SHARE * 1.01, 0.01) is None
    # and where no coordinate is recorded there is nothing to drift along
    assert constancy_guard(_fake_fit(lambda t: 1.0 * (t - 25.0), temperatures=False), "c", 200.0, 0.01) is None


@pytest.mark.slow
def test_a_compression_growing_with_temperature_is_not_confirmed():
    # an independent generator's lot (plain NumPy): -c (T - 25) s^3 on the rebalance, T from 25 to 31 C; the
    # score test ranks feedback_compression first (S = 55), which every other guard passed before this one
    d = discovery_diagnosis("temp_x_cube_input", design="a", seed=0)
    assert d.selected == ()
    refused = {r.effect: r for r in d.rejected}
    assert refused["feedback_compression"].kind == "its size drifts"
    assert "its size follows temperature_c" in refused["feedback_compression"].reason
    assert d.verdict == "unexplained"
