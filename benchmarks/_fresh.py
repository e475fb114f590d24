"""Run a benchmark's worker in a fresh Python process with an empty compilation cache of its own, and read back
the JSON it writes: for settings that must not share compiled or exported programs (a module constant the
exported-program cache's key does not see, or a first call that must compile)."""

import json
import os
import subprocess
import sys
import tempfile


def run_fresh(script: str, argv: list[str]) -> dict:
    """`python script *argv --result PATH` with `GYROJAX_CACHE_DIR` an empty temporary folder (and no
    `JAX_COMPILATION_CACHE*` variables); returns the JSON the worker wrote to PATH."""
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "r.json")
        env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_COMPILATION_CACHE")}
        env["GYROJAX_CACHE_DIR"] = cache
        subprocess.run([sys.executable, script, *argv, "--result", out], env=env, check=True)
        with open(out) as f:
            return json.load(f)
