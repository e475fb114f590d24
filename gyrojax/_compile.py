"""How gyrojax compiles its programs: `jit`, `equinox.filter_jit` with XLA:CPU options chosen by measurement.

gyrojax's programs are large (a fit of the demo lot: ~80 programs, the biggest ~12,000 StableHLO operations)
and run for a second or less, so on a CPU most of a first call is XLA compiling them. Two of XLA's options
change that:

- `xla_cpu_use_fusion_emitters = False` (every program): XLA:CPU's older loop emitters instead of its
  MLIR fusion emitters. First `identify` of the demo lot, empty cache, 2 cores: backend compile 39.5 -> 20.9 s;
  the tiers run as fast or faster (full tier 10.4 -> 7.6 ms per point, steady 0.021 -> 0.018 ms per point).
- `xla_backend_optimization_level = 0` (`quick=True`: the fits, whose compiled solve runs for a second or
  two): LLVM's optimisation passes off. With the first option, identify's compile 20.9 -> 12.5 s and its run
  time unchanged (1.6 s); it would cost the full-waveform tier 2-3x in run time, so simulation keeps them.

The figures are `benchmarks/bench_compile.py` and `benchmarks/bench_tiers.py` runs (see benchmarks/README.md).
The options apply on the CPU backend only, to gyrojax's own top-level programs (a program called inside
another is compiled with the outer one's options). A user's `XLA_FLAGS` wins: an option named there is not set
by gyrojax, so `XLA_FLAGS=--xla_cpu_use_fusion_emitters=true` restores XLA's default.
"""

import functools
import os
from collections.abc import Callable

import equinox as eqx
import jax
from jax._src import core as jax_core  # noqa: PLC2701 - no public form of trace_state_clean


CPU_OPTIONS = {"xla_cpu_use_fusion_emitters": False}
QUICK_CPU_OPTIONS = {**CPU_OPTIONS, "xla_backend_optimization_level": 0}


def _top_level() -> bool:
    """Whether no trace is active (a jit called now is compiled as a program of its own)."""
    clean = getattr(jax_core, "trace_state_clean", None)
    return bool(clean and clean())


def compiler_options(quick: bool = False) -> dict | None:
    """The XLA options for a gyrojax program on the default backend (None: XLA's defaults).

    **Arguments:**

    - `quick`: the program runs briefly (a fit): optimise it less, compile it faster.
    """
    if jax.default_backend() != "cpu":
        return None
    user = os.environ.get("XLA_FLAGS", "")
    options = {k: v for k, v in (QUICK_CPU_OPTIONS if quick else CPU_OPTIONS).items() if f"--{k}" not in user}
    return options or None


def jit(fn: Callable | None = None, *, quick: bool = False) -> Callable:
    """`equinox.filter_jit(fn)` compiled with `compiler_options(quick)`; usable as a decorator, with or without
    arguments. The backend is read at the first call, not at import (importing gyrojax starts no backend)."""
    if fn is None:
        return functools.partial(jit, quick=quick)
    compiled = {}

    @functools.wraps(fn)
    def run(*args, **kwargs):
        # JAX refuses compiler options on a jit inside another trace; there the outer program's options apply.
        options = compiler_options(quick) if _top_level() else None
        key = None if options is None else tuple(sorted(options.items()))
        if key not in compiled:
            compiled[key] = eqx.filter_jit(fn, compiler_options=options) if options else eqx.filter_jit(fn)
        return compiled[key](*args, **kwargs)

    return run
