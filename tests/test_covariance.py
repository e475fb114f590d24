"""identify's covariance: (J^T J)^+ from the SVD of the column-scaled Jacobian, not from J^T J."""

import numpy as np

from gyrojax._identify import _covariance


def _orthonormal(rows, cols, seed=0):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(rows, cols)))
    return q


def test_badly_scaled_columns_keep_every_direction():
    # J = Q diag(s): (J^T J)^-1 = diag(1/s^2) exactly, with a condition number of J^T J of 1e36.
    s = np.array([1e-9, 1.0, 1e9])
    jac = _orthonormal(12, 3) * s
    cov = _covariance(jac)
    np.testing.assert_allclose(np.diag(cov), 1.0 / s**2, rtol=1e-9)
    off = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov))) - np.eye(3)
    assert np.max(np.abs(off)) < 1e-9
    # what forming J^T J loses: its pseudo-inverse misses the weak direction by orders of magnitude
    assert np.linalg.pinv(jac.T @ jac)[0, 0] < 1e-3 / s[0] ** 2


def test_held_columns_get_zero_rows_and_batches_match_one_by_one():
    rng = np.random.default_rng(1)
    jac = rng.normal(size=(4, 20, 5)) * np.array([1e4, 1.0, 0.0, 1e-3, 10.0])  # column 2 held
    cov = _covariance(jac)
    assert np.all(cov[:, 2, :] == 0.0) and np.all(cov[:, :, 2] == 0.0)
    for d in range(4):
        keep = [0, 1, 3, 4]
        j = jac[d][:, keep]
        np.testing.assert_allclose(cov[d][np.ix_(keep, keep)], np.linalg.inv(j.T @ j), rtol=1e-8)
