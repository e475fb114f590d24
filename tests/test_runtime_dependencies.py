"""The package runs on its declared dependencies alone: nothing it imports may come from the test extras
(the README's first command installs only the runtime ones)."""

import subprocess
import sys
import tomllib
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent


def test_only_runtime_dependencies_are_imported(tmp_path):
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    runtime = {d.split(">")[0].split("=")[0].split("[")[0].strip().lower() for d in meta["project"]["dependencies"]}
    test_only = {d.split(">")[0].split("=")[0].split("[")[0].strip().lower()
                 for d in meta["project"]["optional-dependencies"]["test"]} - runtime
    assert "scipy" in test_only
    blocked = sorted(m.replace("-", "_") for m in test_only)
    code = (
        "import importlib.abc, sys\n"
        f"BLOCKED = {blocked!r}\n"
        "class Block(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name.split('.')[0] in BLOCKED:\n"
        "            raise ImportError(f'{name} is a test-only dependency')\n"
        "sys.meta_path.insert(0, Block())\n"
        "import gyrojax, gyrojax.cli, gyrojax.plot\n"
        "import gyrojax._identify, gyrojax._diagnose, gyrojax._compensate.model, gyrojax._cli.demo_job\n"
        "gyrojax.cli.build_parser()\n"
        "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env={"GYROJAX_CACHE_DIR": "off", "PATH": "/usr/bin:/bin", "HOME": str(tmp_path),
                              "MPLCONFIGDIR": str(tmp_path / "mpl")})
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-2000:]
