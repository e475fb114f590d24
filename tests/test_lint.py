"""The code passes ruff's checks (the rules are `[tool.ruff]` in pyproject.toml)."""

import importlib.util
import pathlib
import subprocess
import sys


ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    assert importlib.util.find_spec("ruff") is not None, 'ruff is missing: python -m pip install -e ".[test]"'
    # --no-cache: nothing written into the checkout.
    out = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "gyrojax", "experiments", "benchmarks",
                          "tests"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, f"ruff check failed:\n{out.stdout}{out.stderr}"
