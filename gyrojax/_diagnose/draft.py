"""The proposed missing term written as an effect module: a readout term (`gyrojax.AbstractOutputTerm`) whose
formula is the diagnosis's, at its fitted size, ready for `--effects-module`."""

import keyword
import re

from .._data.io import atomic_write_bytes
from .._sweeps.steady import AbstractSteadySweep
from .formula import Formula


_JAX = (("abs(", "jnp.abs("), ("sign(", "jnp.sign("), ("exp(", "jnp.exp("), ("sin(", "jnp.sin("),
        ("cos(", "jnp.cos("), ("where(", "jnp.where("), (" pi ", " jnp.pi "))


class DraftError(ValueError):
    """The formula cannot be written as a readout term (the reason says why and what to do instead)."""


def _term_line(i: int, t) -> str:
    """The readout term's line of code for the formula's term `t` (coefficient `c[i]`), or a `DraftError`
    where a readout term cannot hold it."""
    for kind in t.kinds:
        if not isinstance(kind, AbstractSteadySweep):
            raise DraftError(f"the term {t.name} acts on the {kind.name} sweep, which is not read through the readout "
                             "(AbstractOutputTerm acts on settled rate outputs: rate_table, vcf_static): write "
                             "it by hand as the kind of term that acts there (docs/adding_an_effect.md).")
    symbols = set(re.findall(r"[A-Za-z_]+", t.expression))
    if symbols & {"f", "run", "dTdt"}:
        raise DraftError(f"the term {t.name} depends on the drive-frequency reading, the run or the rate of "
                         "change of the temperature, which a readout term does not receive (PointConditions: "
                         "input, temperature, time): write it by hand (docs/adding_an_effect.md).")
    expr = " " + t.expression + " "
    for a, b in _JAX:
        expr = expr.replace(a, b)
    expr = expr.strip()
    return (f"        if conditions.sweep in {tuple(t.sweeps)!r}:\n"
            f"            out = out + c[{i}] * {expr}  # {t.name}, {t.unit}")


def draft_effect_source(formula: Formula, *, name: str = "drafted_term", source: str = "") -> str:
    """The text of an effect module for `formula` (see `write_draft`)."""
    if not re.fullmatch(r"[a-z_][a-z0-9_]*", name) or keyword.iskeyword(name):
        raise DraftError(f"the drafted effect's name must be a lower-case Python identifier, got {name!r}.")
    if not formula.complete:
        raise DraftError("the proposed formula leaves part of the located misfit unexplained (no term of the "
                         "dictionary has its shape): there is no formula to draft; write the term by hand from "
                         "the discrepancy's location and shape.")
    body = "\n".join(_term_line(i, t) for i, t in enumerate(formula.terms))
    values = ", ".join(f"{float(c)!r}" for c in formula.coefficients)
    errors = ", ".join(f"{float(s):.3g}" for s in formula.stderr)
    cls = "".join(p.capitalize() for p in name.split("_")) or "DraftedTerm"
    terms = " + ".join(f"c[{i}] {t.name} on {'+'.join(t.sweeps)}" for i, t in enumerate(formula.terms))
    origin = f" from {source}" if source else ""
    swept = "; ".join(sorted({s for t in formula.terms for s in t.sweeps}))
    return f'''"""Drafted by `gyrojax diagnose --draft-effect`{origin}: the proposed missing term

    output -> output + {terms}

(x: the input column, T: die temperature in deg C, t: time since power-on in s; `*model` terms multiply the
model's output). Fitted over the lot: c = [{values}] +/- [{errors}]. It explains {100 * formula.share:.0f} % of
the misfit it was drafted from. Review the physics before you trust it: the diagnosis found a formula in its
dictionary, not a mechanism. Load it with `--effects-module THIS_FILE.py`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

import gyrojax as gj


# The fitted coefficients (the diagnosis's lot-wide values): the typical size of the drafted term.
FITTED = ({values},)


class {cls}(gj.AbstractEffect, gj.AbstractOutputTerm):
    """The drafted readout term: {terms}."""

    coefficients: jax.Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))

    name = {name!r}
    description = "drafted readout term: {terms}"
    plugs_into = "terms (a readout term of the settled rate output)"
    revealed_by = "the sweeps it was located on: {swept}"

    @classmethod
    def supports(cls, gyro):
        return True

    def apply(self, gyro):
        return gyro.with_term(self)

    def __call__(self, gyro, output, conditions):
        x, T, t = conditions.input, conditions.temperature, conditions.time  # noqa: F841 (some unused)
        c = self.coefficients
        out = output
{body}
        return out

    @classmethod
    def typical(cls, scale=1.0):
        return cls(scale * jnp.asarray(FITTED, dtype=float))
'''


def write_draft(formula: Formula, path, *, name: str = "drafted_term", source: str = "") -> str:
    """Write `formula` as an effect module at `path` (atomically; a `.py` file): a readout term
    (`gyrojax.AbstractOutputTerm`) named `name`, nested at zero, whose typical size is the fitted formula.
    Raises `DraftError` (with the reason and what to do) when the formula cannot be a readout term. Returns the
    text written."""
    if not str(path).endswith(".py"):
        raise DraftError(f"--draft-effect {path!r}: the drafted effect is a Python module; give a path ending in .py.")
    text = draft_effect_source(formula, name=name, source=source)
    atomic_write_bytes(path, text.encode())
    return text
