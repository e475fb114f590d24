import gc
import os
from pathlib import Path

import jax
import pytest


# ppm-level work: float64 everywhere, and no silent dtype promotion.
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")

# The suite is compile-bound (XLA compile ~60 % of test_identify.py's time, tracing ~30 %). Executables that took
# over 1 s to compile go to a persistent cache shared by the pytest-xdist workers, the notebook kernels and the
# 8-device identify subprocess (the environment variable reaches them), and they survive the clears below. Most of
# the suite's speed-up is the two workers: one full run wrote only 38 entries.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR",
                      str(Path(__file__).resolve().parent.parent / ".pytest_cache" / "jax-compilation"))
jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])

# Every loaded XLA:CPU executable holds memory maps of its JIT code (one identify on the demo lot: ~4,100 maps),
# and jit caches keep them all. The suite compiles enough to pass Linux's default vm.max_map_count (65,530):
# measured 63,743 maps 31 min in, then the process aborted inside an XLA compile. Between test files, once the
# count passes half the limit, drop the compiled code (later files recompile what they need).
MAP_COUNT_CLEAR = 30_000


def _map_count() -> int:
    try:
        with open("/proc/self/maps") as f:
            return sum(1 for _ in f)
    except OSError:  # not Linux
        return 0


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    yield
    if _map_count() > MAP_COUNT_CLEAR:
        jax.clear_caches()
        gc.collect()


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: takes over ~30 s (compiles a fit); deselect with -m 'not slow'")
