import os


# Before JAX starts its CPU backend (see gyrojax/__init__.py: XLA's CPU runtime can wedge on identify's graphs).
if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()

os.environ.setdefault("EQX_ON_ERROR", "nan")  # as gyrojax does, before equinox is imported

import jax  # noqa: E402


# ppm-level work: float64 everywhere, and no silent dtype promotion.
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
