"""The fit's standardised residuals as a space to describe the misfit in: each device's residual vector, the
span its free parameters and run biases could already absorb, and generic columns laid out in its rows.

Everything here is host-side numpy on one fit: a column block is scored by projecting out the absorbable span
(one SVD per device, taken once), as the score test does, so a thousand flexible descriptions cost no refit.
"""

import dataclasses

import numpy as np

from .._identify import Fit
from .columns import base_columns, excess_chi2, row_blocks
from .probes import Beyond, standardised


# A projected direction carries information when its eigenvalue exceeds this share of the block's own largest
# (before projection): the same unit-free rule as the probes' score test (`gyrojax._diagnose.probes.RELATIVE_RANK_TOL`),
# a little coarser since flexible bases (hat functions, products) have nearly collinear members.
RANK_TOL = 1e-9

# A location is taken by a candidate when, beyond it, its description keeps less than this share of its chi2 (or
# nothing significant): the same rule as the probes' (`SHAPE_SHARE_LEFT`).
EXPLAINED_SHARE_LEFT = 0.1


@dataclasses.dataclass(frozen=True)
class Scored:
    """A block of columns fitted to the residuals beyond the absorbable span.

    `statistic`: the chi2 it removes (the score S); `df`: its directions that carry information; `p_value`;
    `coefficients` (device, k) per device; `covariance` of each device's coefficients (device, k, k);
    `fingerprint` (device, rows): the residual change it explains."""

    statistic: float
    df: int
    p_value: float
    coefficients: np.ndarray
    covariance: np.ndarray
    fingerprint: np.ndarray


class ResidualSpace:
    """A fit's residuals and the span of its free columns, per device, for scoring generic column blocks.

    **Arguments:** `fit` (a `gyrojax.Fit`); `with_columns` adds further columns to what is absorbable (a
    candidate effect's, a description already chosen)."""

    def __init__(self, fit: Fit):
        self.fit = fit
        self.data = fit.data
        self.residuals = np.asarray(fit.residual_vector, float)
        self.devices, self.rows = self.residuals.shape
        self.blocks = {s: (i, j) for s, i, j in row_blocks(fit.data)}
        self.excess = excess_chi2(fit)
        self.base = base_columns(fit)
        self._u = _spans(self.base)

    def with_columns(self, cols: np.ndarray) -> "ResidualSpace":
        """The same fit with `cols` (device, rows, k) added to the absorbable span: the directions of `cols` beyond
        it that `score` counts (information above `RANK_TOL` of their own), so that a block taken into the span
        absorbs what its score says it explains, and no round-off direction besides."""
        out = ResidualSpace.__new__(ResidualSpace)
        out.__dict__.update(self.__dict__)
        out.base = np.concatenate([self.base, cols], axis=-1)
        scale = np.sqrt(np.sum(cols**2, axis=(0, 1)))
        cols = cols / np.where(scale > 0, scale, 1.0)
        pc = self.project(cols)
        spans = []
        for d in range(self.devices):
            own = float(np.linalg.norm(cols[d], 2)) ** 2 if cols.shape[-1] else 0.0
            evals, evecs = np.linalg.eigh(pc[d].T @ pc[d])
            keep = evals > RANK_TOL * own
            q = pc[d] @ evecs[:, keep] / np.sqrt(evals[keep]) if keep.any() else np.zeros((self.rows, 0))
            spans.append(np.concatenate([self._u[d], q], axis=1))
        out._u = spans
        return out

    # -- columns ------------------------------------------------------------------------------------------
    def columns(self, changes: dict) -> np.ndarray:
        """`changes`: sweep -> (device, run, point, k) changes of the predictions per unit coefficient (output
        unit). Returns them as standardised-residual columns (device, rows, k), run biases projected out on
        biased sweeps, zero on the other sweeps' rows and the prior rows."""
        k = max((np.shape(g)[-1] for g in changes.values()), default=0)
        out = np.zeros((self.devices, self.rows, k))
        for sweep, g in changes.items():
            i, j = self.blocks[sweep]
            part = standardised(self.fit, sweep, g).reshape(self.devices, j - i, -1)
            out[:, i:j, :part.shape[-1]] = part
        return out

    def project(self, cols: np.ndarray) -> np.ndarray:
        """`cols` with each device's absorbable span removed."""
        out = np.empty_like(cols)
        for d in range(self.devices):
            u = self._u[d]
            out[d] = cols[d] - u @ (u.T @ cols[d])
        return out

    # -- scores -------------------------------------------------------------------------------------------
    def score(self, cols: np.ndarray, pooled=False) -> Scored:
        """Fit `cols` (device, rows, k) to the residuals beyond the absorbable span, each device its own
        coefficients, or, for the columns `pooled` marks (True: all; or a boolean per column), one coefficient
        for every device (a shape the same in every device)."""
        # each column to unit norm over the lot, so that the rank rule does not depend on the columns' units
        # (a cube of the output, ~1e19 LSB^3, beside a bias in LSB); the coefficients are scaled back below
        scale = np.sqrt(np.sum(cols**2, axis=(0, 1)))
        scale = np.where(scale > 0, scale, 1.0)
        cols = cols / scale
        pc = self.project(cols)
        r = self.residuals
        n, _, k = pc.shape
        if k == 0:
            return Scored(0.0, 0, 1.0, np.zeros((n, 0)), np.zeros((n, 0, 0)), np.zeros(r.shape))
        mask = np.broadcast_to(np.asarray(pooled, bool), (k,))
        if mask.any():
            return self._score_pooled(cols, pc, scale, mask)
        own = np.array([float(np.linalg.norm(cols[d], 2)) ** 2 for d in range(n)])
        coefs, covs, stat, df = np.zeros((n, k)), np.zeros((n, k, k)), 0.0, 0
        fp = np.zeros(r.shape)
        beyond = Beyond()
        for d in range(n):
            beyond.add(cols[d], r[d], self._u[d])
            inv, df_d = _pinv(pc[d].T @ pc[d], RANK_TOL * own[d])
            if df_d == 0:
                continue
            b = pc[d].T @ r[d]
            coefs[d], covs[d] = inv @ b, inv
            stat += float(b @ coefs[d])
            df += df_d
            fp[d] = pc[d] @ coefs[d]
        return Scored(stat, df, beyond.p_value(stat, df), coefs / scale, covs / np.outer(scale, scale), fp)

    def _score_pooled(self, cols, pc, scale, mask) -> Scored:
        """`score` with the columns `mask` marks shared by every device: one least-squares fit over the lot's
        stacked rows, the per-device columns block-diagonal beside them."""
        r = self.residuals
        n, rows, k = pc.shape
        own_cols, pool_cols = np.flatnonzero(~mask), np.flatnonzero(mask)
        device = np.arange(n)[:, None, None]

        def stack(a):  # (device, rows, k) -> (device x rows, shared + device x own)
            return np.concatenate([a[:, :, pool_cols]] + [np.where(device == d, a[:, :, own_cols], 0.0)
                                                          for d in range(n)], axis=-1).reshape(n * rows, -1)

        x = stack(pc)
        inv, df = _pinv(x.T @ x, RANK_TOL * float(np.linalg.norm(stack(cols), 2)) ** 2)
        b = x.T @ r.reshape(-1)
        theta = inv @ b
        beyond = Beyond()
        for d in range(n):
            beyond.add(cols[d], r[d], self._u[d])
        # per device: the shared coefficients and the device's own, and their covariance, in `cols`' order
        kp, order = pool_cols.size, np.concatenate([pool_cols, own_cols])
        coefs, covs = np.zeros((n, k)), np.zeros((n, k, k))
        for d in range(n):
            idx = np.concatenate([np.arange(kp), kp + d * own_cols.size + np.arange(own_cols.size)])
            coefs[d, order] = theta[idx]
            covs[d][np.ix_(order, order)] = inv[np.ix_(idx, idx)]
        stat = float(b @ theta)
        return Scored(stat, df, beyond.p_value(stat, df), coefs / scale, covs / np.outer(scale, scale),
                      (x @ theta).reshape(n, rows))

    def sweep_rows(self, sweep: str) -> slice:
        i, j = self.blocks[sweep]
        return slice(i, j)

    def raw_excess(self, cols: np.ndarray, sweep: str) -> float:
        """What `cols` (device, rows, k) explain of one sweep's residuals as they are (no span projected out,
        run biases already are), beyond their degrees of freedom: the misfit that sits on that sweep along
        them, measured on its own residuals."""
        sl = self.sweep_rows(sweep)
        total = 0.0
        for d in range(self.devices):
            c, r = cols[d, sl], self.residuals[d, sl]
            if not np.any(c):
                continue
            inv, df = _pinv(c.T @ c, RANK_TOL * float(np.linalg.norm(c, 2)) ** 2)
            b = c.T @ r
            total += float(b @ inv @ b) - df
        return max(total, 0.0)


def _spans(base: np.ndarray) -> list:
    """Each device's orthonormal basis of the span of `base` (device, rows, m), singular values above 1e-12 of
    the largest (as `gyrojax._diagnose.probes.project_out`)."""
    out = []
    for d in range(base.shape[0]):
        if base.shape[-1] == 0:
            out.append(np.zeros((base.shape[1], 0)))
            continue
        # the span does not depend on the columns' scales: each to unit norm first, so that a column in large
        # units (a cube of the output) does not push the others below the singular-value cut
        norms = np.linalg.norm(base[d], axis=0)
        b = base[d][:, norms > 0] / norms[norms > 0]
        if b.shape[1] == 0:
            out.append(np.zeros((base.shape[1], 0)))
            continue
        u, s, _ = np.linalg.svd(b, full_matrices=False)
        out.append(u[:, s > 1e-12 * max(float(s[0]), 1e-300)])
    return out


def _pinv(info: np.ndarray, floor: float):
    """Pseudo-inverse of a symmetric information matrix over its eigen-directions above `floor`, and their
    count."""
    evals, evecs = np.linalg.eigh(info)
    keep = evals > max(floor, 0.0)
    if not keep.any():
        return np.zeros_like(info), 0
    return (evecs[:, keep] / evals[keep]) @ evecs[:, keep].T, int(keep.sum())
