"""jaxtyping aliases used across gyrojax."""

from typing import Union

import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Complex, Float, Int


RealScalarLike = Union[float, int, np.floating, np.integer, Float[ArrayLike, ""]]
"""A real scalar: a Python number, a NumPy scalar or a 0-d (possibly traced) array."""

FloatScalar = Float[Array, ""]
ComplexScalar = Complex[Array, ""]

__all__ = ["Array", "ArrayLike", "Bool", "Complex", "Float", "Int", "RealScalarLike", "FloatScalar",
           "ComplexScalar"]
