"""identify's covariance: (J^T J)^+ from the SVD of the column-scaled Jacobian, not from J^T J."""

import numpy as np

from gyrojax._identify.covariance import covariance


def _orthonormal(rows, cols, seed=0):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(rows, cols)))
    return q


def test_badly_scaled_columns_keep_every_direction():
    # J = Q diag(s): (J^T J)^-1 = diag(1/s^2) exactly, with a condition number of J^T J of 1e36.
    s = np.array([1e-9, 1.0, 1e9])
    jac = _orthonormal(12, 3) * s
    cov = covariance(jac)
    np.testing.assert_allclose(np.diag(cov), 1.0 / s**2, rtol=1e-9)
    off = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov))) - np.eye(3)
    assert np.max(np.abs(off)) < 1e-9
    # what forming J^T J loses: its pseudo-inverse misses the weak direction by orders of magnitude
    assert np.linalg.pinv(jac.T @ jac)[0, 0] < 1e-3 / s[0] ** 2


def test_held_columns_get_zero_rows_and_batches_match_one_by_one():
    rng = np.random.default_rng(1)
    jac = rng.normal(size=(4, 20, 5)) * np.array([1e4, 1.0, 0.0, 1e-3, 10.0])  # column 2 held
    cov = covariance(jac)
    assert np.all(cov[:, 2, :] == 0.0) and np.all(cov[:, :, 2] == 0.0)
    for d in range(4):
        keep = [0, 1, 3, 4]
        j = jac[d][:, keep]
        np.testing.assert_allclose(cov[d][np.ix_(keep, keep)], np.linalg.inv(j.T @ j), rtol=1e-8)


def test_gauss_newton_decrement_is_the_chi2_a_linear_fit_still_gains():
    """identify certifies a solve stopped at max_steps by the chi2 a full Gauss-Newton step would still gain:
    on a linear problem r(x) = y - J x that is chi2(x0) - min chi2, exactly, also with badly scaled columns;
    a joint fit's decrement is that of the lot's block Jacobian (per-device blocks plus shared columns)."""
    from gyrojax._identify.covariance import gauss_newton_decrement, joint_jacobian

    rng = np.random.default_rng(2)
    jac = rng.normal(size=(3, 15, 4)) * np.array([1e6, 1.0, 1e-4, 0.0])  # a held (zero) column too
    r0 = rng.normal(size=(3, 15))
    best = [np.sum((r - j @ np.linalg.lstsq(j, r, rcond=None)[0]) ** 2) for j, r in zip(jac, r0)]
    expected = np.sum(r0**2, axis=1) - np.array(best)
    np.testing.assert_allclose(gauss_newton_decrement(jac, None, r0, joint=False), expected, rtol=1e-9)
    # joint: three devices, two shared columns
    jac_lot = rng.normal(size=(3, 15, 2))
    full = joint_jacobian(jac, jac_lot)
    assert full.shape == (45, 14)
    np.testing.assert_array_equal(full[15:30, 4:8], jac[1])
    np.testing.assert_array_equal(full[15:30, 12:], jac_lot[1])
    r = r0.reshape(-1)
    x = np.linalg.lstsq(full, r, rcond=None)[0]
    joint = gauss_newton_decrement(jac, jac_lot, r0, joint=True)
    np.testing.assert_allclose(joint, np.full(3, r @ r - np.sum((r - full @ x) ** 2)), rtol=1e-9)
    # a device whose Jacobian is not finite is never certified
    jac[1, 0, 0] = np.nan
    dec = gauss_newton_decrement(jac, None, r0, joint=False)
    assert np.isinf(dec[1]) and np.all(np.isfinite(dec[[0, 2]]))
