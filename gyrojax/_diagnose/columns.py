"""The lot's standardised residuals and Jacobian laid out for the tests: the rows of each sweep, the columns
of an effect, the baseline's free columns, and the chi2 in excess of the degrees of freedom."""

import numpy as np

from .._identify import Fit
from .._model.fitdata import FitData


def row_blocks(data: FitData):
    """(sweep, start, stop) of each sweep's rows in a device's residual vector."""
    out, k = [], 0
    for sweep in data.sweeps:
        shape = data.blocks[sweep].inputs.shape
        n = int(shape[1] * shape[2])
        out.append((sweep, k, k + n))
        k += n
    return out


def effect_columns(fit: Fit, name: str) -> np.ndarray:
    return np.asarray([i for i, nm in enumerate(fit.names) if nm.startswith(name + ".")], dtype=int)


def base_columns(fit: Fit) -> np.ndarray:
    """The free columns of the fit's Jacobian (device, residual, free): what it could already absorb."""
    return np.asarray(fit.jacobian)[:, :, np.asarray(fit.free)]


def excess_chi2(fit: Fit) -> float:
    return max(fit.chi2_total - fit.dof_total, 0.0)
