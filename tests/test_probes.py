"""The score test shared by candidate effects and shape probes (`gyrojax._probes.score_columns`), against
least squares done by hand."""

import numpy as np
import pytest

from gyrojax._probes import score_columns


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
