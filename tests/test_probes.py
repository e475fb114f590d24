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
    from gyrojax._probes import project_out

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
