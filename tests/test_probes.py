"""The score test shared by candidate effects and shape probes (`gyrojax._diagnose.probes.score_columns`), against
least squares done by hand."""

import numpy as np
import pytest

from gyrojax._diagnose.probes import score_columns


def test_score_is_the_chi2_a_refit_with_the_columns_removes():
    """On a linear problem the score statistic is exactly the chi2 drop of the refit with the new columns,
    its fingerprint the refit's residual change, and its coefficients the new columns' least-squares values."""
    rng = np.random.default_rng(0)
    rows, devices = 60, 3
    base = rng.normal(size=(devices, rows, 2))
    cols = rng.normal(size=(devices, rows, 2))
    truth = np.array([0.7, -0.3])
    r = np.stack([rng.normal(size=rows) + cols[d] @ truth for d in range(devices)])
    # residuals of the base fit: r minus its projection on the base columns
    res = np.stack([r[d] - base[d] @ np.linalg.lstsq(base[d], r[d], rcond=None)[0] for d in range(devices)])
    sc = score_columns(base, cols, res)
    drop, coef = 0.0, []
    for d in range(devices):
        full = np.concatenate([base[d], cols[d]], axis=1)
        fit = np.linalg.lstsq(full, r[d], rcond=None)[0]
        drop += np.sum(res[d] ** 2) - np.sum((r[d] - full @ fit) ** 2)
        coef.append(fit[2:])
    assert sc.statistic == pytest.approx(drop, rel=1e-10)
    assert sc.df == 2 * devices
    np.testing.assert_allclose(sc.coefficients, np.array(coef), rtol=1e-9)
    np.testing.assert_allclose(np.abs(sc.coefficients - truth).max(), 0.0, atol=0.5)


def test_columns_inside_the_base_span_are_untestable():
    rng = np.random.default_rng(1)
    base = rng.normal(size=(2, 30, 2))
    cols = base @ np.array([[1.0], [2.0]])  # a combination of the base columns
    sc = score_columns(base, cols, rng.normal(size=(2, 30)))
    assert sc.df == 0 and sc.statistic == 0.0 and sc.p_value == 1.0


def test_a_columns_unit_does_not_decide_its_degrees_of_freedom():
    """The rank tolerance is relative to the columns' own information: the same shape in ppm or in parts
    scores the same."""
    rng = np.random.default_rng(2)
    base = rng.normal(size=(2, 40, 2))
    cols = rng.normal(size=(2, 40, 1))
    res = rng.normal(size=(2, 40)) + 3.0 * cols[..., 0]
    big, small = score_columns(base, cols, res), score_columns(base, cols * 1e-6, res)
    assert big.df == small.df == 2
    assert small.statistic == pytest.approx(big.statistic, rel=1e-9)
    np.testing.assert_allclose(small.coefficients, big.coefficients * 1e6, rtol=1e-9)


def test_a_column_at_round_off_in_the_base_takes_no_real_direction_with_it():
    """A base column the data do not see (round-off, as an effect's even terms on odd data) must not remove part
    of the real columns' span: the projection equals the one without it."""
    from gyrojax._diagnose.probes import project_out

    rng = np.random.default_rng(3)
    real = rng.normal(size=(50, 3)) * np.array([1e4, 3e3, 1.0])
    tiny = rng.normal(size=(50, 1)) * 1e-14
    against = np.concatenate([real[:, :1], tiny, real[:, 1:]], axis=1)
    cols = rng.normal(size=(50, 2))
    np.testing.assert_allclose(project_out(cols, against), project_out(cols, real), atol=1e-12)
    # a column 2 % outside the span keeps its 2 %
    step = 0.02 * np.linalg.norm(real[:, 2]) * cols[:, :1] / np.linalg.norm(cols[:, 0])
    outside = (real @ np.array([1e-4, 2e-4, 0.5]))[:, None] + step
    left = project_out(outside, against)
    assert np.linalg.norm(left) == pytest.approx(np.linalg.norm(project_out(step, real)), rel=1e-9)
    assert 0.5 * np.linalg.norm(step) < np.linalg.norm(left) <= np.linalg.norm(step)


def _linear_fit(rng, c, devices=3, rows=(40, 20)):
    """A linear stand-in for a fit: a base column and an effect column over two sweeps, "a" and "b", and a probe
    equal to the effect on sweep "a" only (as a cubic after the DAC is a DAC INL without the DAC sweep, which
    sees the INL weakly: the effect's rows there are a tenth of the others). The residuals hold the probe at
    size `c` plus unit noise, with the base taken out."""
    import types

    n = sum(rows)
    base = rng.normal(size=(devices, n, 1))
    effect = rng.normal(size=(devices, n, 1))
    effect[:, rows[0]:] *= 0.1
    probe = effect.copy()
    probe[:, rows[0]:] = 0.0
    raw = c * probe[..., 0] + rng.normal(size=(devices, n))
    res = np.stack([raw[d] - base[d] @ np.linalg.lstsq(base[d], raw[d], rcond=None)[0] for d in range(devices)])
    blocks = {s: types.SimpleNamespace(inputs=np.zeros((devices, 1, r))) for s, r in zip("ab", rows)}
    fit = types.SimpleNamespace(jacobian=np.concatenate([base, effect], axis=-1), residual_vector=res,
                                free=np.array([True, False]), names=("k", "inl.c"),
                                data=types.SimpleNamespace(sweeps=("a", "b"), blocks=blocks))
    return fit, probe


def _shape(name, fit, probe):
    """The probe as `score_probes` reports it at `fit`: significant, with its fingerprint beyond the base."""
    from gyrojax._diagnose.discrepancy import Discrepancy

    fingerprint = score_columns(fit.jacobian[:, :, :1], probe, fit.residual_vector).fingerprint
    return Discrepancy(name, "input", f"the shape {name}", (), 0.0, 1, 1.0, 0.0, True, 0.0, 0.0, "", fingerprint)


def test_a_look_alike_is_named_with_its_separation_and_the_sweep_that_holds_it():
    """`look_alikes` against least squares by hand: the separation is |c P g| over the devices (P removing the
    base and the effect, c the probe's own coefficient), it lives on the sweep the probe does not reach, and
    the information factor is 9 / separation^2. A probe the data tell apart (> 3 sigma) or the effect's own
    form is not named."""
    from gyrojax._diagnose.discrepancy import look_alikes
    from gyrojax._diagnose.probes import project_out

    rng = np.random.default_rng(5)
    fit, probe = _linear_fit(rng, c=1.0)
    jac, res = fit.jacobian, fit.residual_vector
    (alike,) = look_alikes(fit, "inl", [_shape("after", fit, probe)], {"after": probe}, alpha=0.01)
    sep2 = 0.0
    for d in range(3):
        c = score_columns(jac[:, :, :1], probe, res).coefficients[d]
        gap = project_out(probe[d], jac[d]) @ c
        sep2 += gap @ gap
    assert alike.separation_sigma == pytest.approx(np.sqrt(sep2), rel=1e-9)
    assert 0.0 < alike.separation_sigma < 3.0
    assert alike.sweeps[0][0] == "b" and alike.sweeps[0][1] > 0.5
    assert alike.information_factor == pytest.approx(9.0 / sep2, rel=1e-9)
    assert "differ by" in alike.description and "b sweep" in alike.description
    # a large probe: the data tell the two apart, and nothing is named
    fit, probe = _linear_fit(np.random.default_rng(5), c=30.0)
    assert look_alikes(fit, "inl", [_shape("after", fit, probe)], {"after": probe}, alpha=0.01) == ()
    # the effect's own form (the probe on both sweeps) is not a look-alike
    own = fit.jacobian[:, :, 1:]
    assert look_alikes(fit, "inl", [_shape("own", fit, own)], {"own": own}, alpha=0.01) == ()
