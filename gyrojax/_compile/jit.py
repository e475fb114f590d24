"""How gyrojax compiles its programs: `jit`, `equinox.filter_jit` with an XLA:CPU option chosen by measurement.

gyrojax's programs are large (a fit of the demo lot: ~80 programs, the biggest ~14,000 StableHLO operations)
and run for a second or less, so on a CPU most of a first call is XLA compiling them. XLA:CPU's older loop
emitters (`xla_cpu_use_fusion_emitters = False`) instead of its MLIR fusion emitters compile them in a third to
a half less time and run as fast or faster: first `identify` of the demo lot, empty cache, 2 cores, XLA compile
39.6 -> 26.4 s (wall 62.2 -> 50.3 s); the fit of 256 devices 5.46 against 5.44 s; the full-waveform tier
10.4 -> 7.6 ms per point.

Measured and not taken: LLVM's optimisation level 0 (`xla_backend_optimization_level = 0`) compiles the fit
faster still (identify 20.9 -> 12.5 s) but runs the fit of 256 devices 3x slower (16.3 s) and the full tier
2-3x slower.

The figures are `benchmarks/bench_compile.py`, `bench_identify_lot.py` and `bench_tiers.py` runs (see
benchmarks/README.md). The option applies on the CPU backend only, to gyrojax's own top-level programs (a
program called inside another trace is compiled with the outer one's options: JAX refuses options on a nested
jit). A user's `XLA_FLAGS` wins: an option named there is not set by gyrojax, so
`XLA_FLAGS=--xla_cpu_use_fusion_emitters=true` restores XLA's default.
"""

import functools
import os
from collections.abc import Callable

import equinox as eqx
import jax
from jax._src import core as jax_core  # noqa: PLC2701 - no public form of trace_state_clean


CPU_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def top_level() -> bool:
    """Whether no trace is active (a jit called now is compiled as a program of its own)."""
    clean = getattr(jax_core, "trace_state_clean", None)
    return bool(clean and clean())


def compiler_options() -> dict | None:
    """The XLA options for a gyrojax program on the default backend (None: XLA's defaults)."""
    if jax.default_backend() != "cpu":
        return None
    user = os.environ.get("XLA_FLAGS", "")
    options = {k: v for k, v in CPU_OPTIONS.items() if f"--{k}" not in user}
    return options or None


def jit(fn: Callable) -> Callable:
    """`equinox.filter_jit(fn)` compiled with `compiler_options()` when called outside any trace. The backend is
    read at the call, not at import (importing gyrojax starts no backend)."""
    compiled = {}

    @functools.wraps(fn)
    def run(*args, **kwargs):
        # JAX refuses compiler options on a jit inside another trace; there the outer program's options apply.
        options = compiler_options() if top_level() else None
        key = None if options is None else tuple(sorted(options.items()))
        if key not in compiled:
            # options None: XLA's defaults. equinox's overloads of filter_jit omit the jax.jit keywords it passes on.
            compiled[key] = eqx.filter_jit(fn, compiler_options=options)  # pyright: ignore[reportCallIssue]
        return compiled[key](*args, **kwargs)

    return run
