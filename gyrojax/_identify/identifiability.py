"""Identifiability: what the data cannot fix. At the start, the weighted Jacobian's SVD names the directions
below the threshold and holds one parameter of each (the hold rules); at the solution, directions the data no
longer fix are named (weak directions); and the scale factor is reported only where its gradient has no part
along a direction the data leave open (its determinacy)."""

import numpy as np

from .._model.fitdata import FitData
from .covariance import joint_jacobian
from .fit import Unidentifiable


# A held direction moves the scale factor by g.v per natural unit of the parameters (one internal unit: an
# e-fold of a positive parameter, `scale` of a signed one). Below a tenth of the SF's standard error, a design
# value off by that much would add under 1 % to the SF's variance: immaterial. Above it the SF rests on the
# design value.
_SF_HELD_TOL = 0.1


def sf_determinacy(jac, jac_lot, grad, grad_lot, sf_stderr, threshold):
    """Per device, whether the scale factor is estimable: its gradient `grad` (device, candidate) over the
    candidate parameters (free, or held as unidentifiable) must lie in the row space of the weighted Jacobian
    `jac` (device, residual, candidate), up to the directions the data fix (singular value >= `threshold`).
    A joint fit's lot-shared columns (`jac_lot`, `grad_lot`) make one Jacobian of the whole lot.

    **Returns:** `(determined (device,), weak part of the gradient (device, candidate + lot), weak singular
    values per device)`. Determined: some free parameter the data fix moves the SF (`sf_stderr` > 0) and the
    weak part is below `_SF_HELD_TOL` standard errors per natural unit."""
    jac, grad = np.asarray(jac, dtype=float), np.asarray(grad, dtype=float)
    n, _, nc = jac.shape
    n_lot = np.shape(jac_lot)[-1] if jac_lot is not None else 0
    weak_part = np.zeros((n, nc + n_lot))
    weak_s = []
    if n_lot:
        full = joint_jacobian(jac, np.asarray(jac_lot, dtype=float))
        ok = np.all(np.isfinite(full))
        s, vt = _singular(np.where(np.isfinite(full), full, 0.0))
        v = vt[s < threshold]
        for d in range(n):
            g = np.zeros(full.shape[1])
            g[d * nc:(d + 1) * nc], g[n * nc:] = grad[d], np.asarray(grad_lot, dtype=float)[d]
            part = v.T @ (v @ g) if ok else g
            weak_part[d] = np.concatenate([part[d * nc:(d + 1) * nc], part[n * nc:]])
            weak_s.append(s[s < threshold])
    else:
        for d in range(n):
            j = jac[d]
            if not np.all(np.isfinite(j)) or not np.all(np.isfinite(grad[d])):
                weak_part[d] = np.where(np.isfinite(grad[d]), grad[d], np.inf)
                weak_s.append(np.zeros(0))
                continue
            s, vt = _singular(j) if nc else (np.zeros(0), np.zeros((0, 0)))
            v = vt[s < threshold]
            weak_part[d] = v.T @ (v @ grad[d])
            weak_s.append(s[s < threshold])
    se = np.asarray(sf_stderr, dtype=float)
    size = np.linalg.norm(weak_part, axis=1)
    determined = np.isfinite(se) & (se > 0) & (size <= _SF_HELD_TOL * se)
    return determined, weak_part, weak_s


def _count_text(data: FitData, d: int) -> tuple[str, int, int]:
    """('22 rate-table points and 4 DAC points', points, run biases) of device `d`."""
    parts, points, biases = [], 0, 0
    for s in data.sweeps:
        m = np.asarray(data.blocks[s].mask[d])
        k = int(m.sum())
        if k:
            parts.append(f"{k} {data.kind(s).title} point{'s' if k != 1 else ''}")
            points += k
            if data.kind(s).biased:
                biases += int(np.sum(np.any(m, axis=-1)))
    text = " and ".join([", ".join(parts[:-1]), parts[-1]] if len(parts) > 1 else parts) or "no points"
    return text, points, biases


def undetermined_reason(data, d, names, weak_part, n_free, threshold) -> str:
    """Why device `d`'s scale factor is not determined, naming the parameters it rests on (those of the
    gradient's part along the directions the data do not fix, `weak_part`)."""
    size = np.abs(weak_part)
    involved = [names[k] for k in np.flatnonzero(size > 0.3 * size.max())] if size.max() > 0 else []
    counts, points, biases = _count_text(data, d)
    if not involved:
        return (f"the scale factor moves with no parameter the data fix ({counts}): it is the design value, not a "
                "measurement")
    what = " x ".join(involved)
    left = points - biases - n_free
    if points - biases <= 0:
        why = (f"{counts} and {biases} free run bias{'es' if biases != 1 else ''} leave no degree of freedom")
    elif left < 0:
        why = f"{counts} leave {points - biases} independent residual(s) after the run biases, too few"
    else:
        why = (f"the data do not change along {'this combination' if len(involved) > 1 else 'it'} (singular value "
               f"below identifiability_threshold = {threshold:g}); a prior (priors=...) or a sweep that sees it "
               "would fix it")
    return f"the data cannot fix {what}: {why}; the printed design value would not be a measurement"


def weak_directions(jac, threshold):
    """Per device, the free directions the data no longer fix at the solution: (member indices into the free
    list, singular value) for each singular value of the weighted Jacobian (data and prior rows) below
    `threshold`, in internal units. `jac` is (device, residual, free)."""
    out = []
    for j in np.asarray(jac, dtype=float):
        if j.shape[1] == 0 or not np.all(np.isfinite(j)):
            out.append([])
            continue
        # the SVD, as in `hold_unidentifiable` (eigh of J^T J cannot resolve s below ~sqrt(eps) s_max)
        s, vt = _singular(j)
        out.append([(tuple(int(k) for k in _members(vt[i])), float(s[i])) for i in np.nonzero(s < threshold)[0]])
    return out


def weak_at_solution(jac, names_free, threshold):
    """Per device, text naming the free directions the data no longer fix at the solution (`weak_directions`).
    They were fixed at the start (or identify would have held them), so the fit moved somewhere flat: a
    log-parameter run off towards 0 or infinity (an open-loop Q_y of 1e243, measured, with the solver reporting
    success) is the typical case."""
    out = []
    for weak in weak_directions(jac, threshold):
        notes = [f"{' x '.join(names_free[k] for k in members)} (s = {s:.2g})" for members, s in weak]
        out.append("" if not notes else
                   "the data no longer fix " + "; ".join(notes) + f" at the solution (singular value < "
                   f"{threshold:g}): the fit may have wandered along a flat direction. Give it a prior "
                   "(priors=...), hold it (hold=...), or start from the data")
    return out


def _singular(j):
    """Singular values and right singular vectors (rows of `vt`) of `j`, one per column: fewer rows than
    columns are padded with zero rows, so that the null directions come out with s = 0."""
    if j.shape[0] < j.shape[1]:
        j = np.concatenate([j, np.zeros((j.shape[1] - j.shape[0], j.shape[1]))])
    _, s, vt = np.linalg.svd(j, full_matrices=False)
    return s, vt


def _members(direction):
    """Indices of the parameters taking part in a weak direction: components over 0.3 of its largest."""
    v = np.abs(direction)
    return np.nonzero(v > 0.3 * v.max())[0]


def hold_unidentifiable(jac, names_free, threshold):
    """Indices (into the free list) to hold, and the reports. `jac` is (device, residual, free)."""
    # The lot's Jacobians stacked (its Gram matrix is the lot's mean normal matrix). Combinations come from its
    # SVD, not eigh of J^T J, whose absolute error eps * s_max^2 left nothing below ~400 resolvable beside a
    # dynamic VCF sweep (s_max ~ 3e10), which the former 1e-7 * s_max guard then had to hold.
    stacked = np.asarray(jac, dtype=float).reshape(-1, jac.shape[-1]) / np.sqrt(max(jac.shape[0], 1))
    keep = list(range(len(names_free)))
    reports = []
    # Parameters the data do not see at all, one by one; then combinations.
    columns = np.linalg.norm(stacked, axis=0)
    scale = float(np.max(columns)) if keep else 0.0
    # A single column's norm is a sum of squares (no cancellation): only a column at the round-off of the
    # largest is numerically zero. (1e-7 here held a sense Duffing coefficient with a column norm of 1.1e3
    # beside a dynamic VCF sweep's 2.7e10 for omega_y: the diagnosis then could not add it.)
    for j in list(keep):
        s_j = float(columns[j])
        if s_j < threshold or s_j < 1e-12 * scale:
            reports.append(Unidentifiable(parameters=(names_free[j],), held=names_free[j], singular_value=s_j))
            keep.remove(j)
    while keep:
        s, vt = _singular(stacked[:, keep])
        evecs = vt.T
        i = int(np.argmin(s))
        if s[i] >= threshold and s[i] >= 1e-12 * s.max():
            break
        involved = [keep[j] for j in _members(evecs[:, i])]
        held = max(involved)  # the last in order of preference
        reports.append(Unidentifiable(parameters=tuple(names_free[j] for j in involved), held=names_free[held],
                                      singular_value=float(s[i])))
        keep.remove(held)
    return keep, tuple(reports)
