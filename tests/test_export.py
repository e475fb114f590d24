"""Programs exported beside the compilation cache (gyrojax/_compile/export.py), checked in fresh processes: a second
process loads what the first exported and traces nothing; a changed user module, a corrupt file, a host
callback or a disabled cache take the plain path with the same results."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest


PLUGIN = textwrap.dedent("""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    class Gain(eqx.Module):
        k: jax.Array
        order: int = eqx.field(static=True)

        def apply(self, x):
            return self.k * x ** self.order + OFFSET

    OFFSET = 1.0
""")

# Runs a cached program on a Gain from plugin.py; prints its outputs and the names of the traces as JSON.
PROGRAM = textwrap.dedent("""
    import json, sys
    import jax
    traces = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda e, d, fun_name="?", **k: traces.append(fun_name) if e.endswith("jaxpr_trace_duration") else None)
    import gyrojax as gj
    import jax.numpy as jnp
    import numpy as np
    from gyrojax._compile.export import cached_program
    from plugin import Gain

    def response(gain, x, scale):
        y = jnp.cumsum(gain.apply(x)) * scale
        if CALLBACK:
            jax.debug.callback(lambda v: None, y)
        out = {"y": y, "stats": (jnp.sum(y), jnp.max(y))}
        return {**out, "points": 7} if "python-output" in sys.argv else out

    CALLBACK = "callback" in sys.argv
    if "edited" in sys.argv:  # plugin.py saved again after it was imported: the code on disk may differ
        import time
        time.sleep(0.01)
        with open("plugin.py", "a") as f:
            f.write("# saved again")
    if "patched" in sys.argv:  # a gyrojax function replaced at run time, as a test's monkeypatch does
        import gyrojax._model.residuals

        def stand_in(*args):
            return 0.0

        gyrojax._model.residuals.run_biases = stand_in
    k = jnp.asarray(1.5)
    if "sharded" in sys.argv:  # the gain placed on two CPU devices
        mesh = jax.sharding.Mesh(np.asarray(jax.devices()[:2]), ("lot",))
        k = jax.device_put(k, jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec()))
    out = cached_program("response", response)(Gain(k, 2), jnp.linspace(0.0, 1.0, 7), 3.0)
    print("RESULT " + json.dumps({"y": [float(v) for v in out["y"]], "sum": float(out["stats"][0]),
                                  "points": repr(out.get("points")), "traces": traces,
                                  "cache": gj.io.compilation_cache()}))
""")


def _run(folder, cache, *args, devices=1, timeout=600):
    env = {k: v for k, v in os.environ.items()
           if k not in ("JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
                        "JAX_ENABLE_COMPILATION_CACHE", "GYROJAX_CACHE_DIR")}
    env["XDG_CACHE_HOME"] = str(folder / "xdg")  # the default folder, never the user's own
    env["GYROJAX_CACHE_DIR"] = str(cache)
    if devices > 1:
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={devices}".strip()
    env["PYTHONPATH"] = os.pathsep.join([os.getcwd(), str(folder)] + env.get("PYTHONPATH", "").split(os.pathsep))
    proc = subprocess.run([sys.executable, str(folder / "program.py"), *args], env=env, capture_output=True,
                          text=True, timeout=timeout, cwd=folder)
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


@pytest.fixture
def program(tmp_path):
    (tmp_path / "plugin.py").write_text(PLUGIN)
    (tmp_path / "program.py").write_text(PROGRAM)
    return tmp_path


def _artifacts(cache):
    folder = cache / "gyrojax_export"
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def _expected(offset):
    x = np.linspace(0.0, 1.0, 7)
    return np.cumsum(1.5 * x**2 + offset) * 3.0


def test_a_second_process_loads_the_program_without_tracing_it(program):
    cache = program / "cache"
    first = _run(program, cache)
    assert "export_response" in first["traces"]  # the export traces the program once
    files = _artifacts(cache)
    assert len(files) == 1 and files[0].startswith("response-") and files[0].endswith(".jaxexport")
    second = _run(program, cache)
    assert not {"export_response", "response"} & set(second["traces"])
    assert second["y"] == first["y"] and second["sum"] == first["sum"]
    np.testing.assert_allclose(second["y"], _expected(1.0), rtol=1e-14)
    assert _artifacts(cache) == files


def test_an_edited_user_module_is_traced_again(program):
    """The class of an argument comes from a user's file: editing the file (here a module constant its method
    reads, invisible in the argument itself) gives another key, so the old program is not used."""
    cache = program / "cache"
    before = _run(program, cache)
    (program / "plugin.py").write_text(PLUGIN.replace("OFFSET = 1.0", "OFFSET = 2.0"))
    after = _run(program, cache)
    assert "export_response" in after["traces"]
    np.testing.assert_allclose(before["y"], _expected(1.0), rtol=1e-14)
    np.testing.assert_allclose(after["y"], _expected(2.0), rtol=1e-14)
    assert len(_artifacts(cache)) == 2


def test_a_replaced_gyrojax_function_is_another_program(program):
    cache = program / "cache"
    _run(program, cache)
    patched = _run(program, cache, "patched")
    assert "export_response" in patched["traces"]
    np.testing.assert_allclose(patched["y"], _expected(1.0), rtol=1e-14)
    assert len(_artifacts(cache)) == 2


def test_a_user_module_saved_after_the_import_takes_the_plain_path(program):
    cache = program / "cache"
    out = _run(program, cache, "edited")
    assert "response" in out["traces"] and "export_response" not in out["traces"]
    np.testing.assert_allclose(out["y"], _expected(1.0), rtol=1e-14)
    assert _artifacts(cache) == []


def test_a_corrupt_artifact_falls_back_and_is_written_again(program):
    cache = program / "cache"
    first = _run(program, cache)
    (name,) = _artifacts(cache)
    path = cache / "gyrojax_export" / name
    good = path.read_bytes()
    path.write_bytes(good[: len(good) // 2] + b"\0garbage\0" + good[len(good) // 2 + 9:])
    second = _run(program, cache)
    assert "export_response" in second["traces"]  # traced again: the file was not used
    assert second["y"] == first["y"] and second["sum"] == first["sum"]
    assert path.read_bytes() == good  # the same program, written again


def test_a_host_callback_takes_the_plain_path(program):
    cache = program / "cache"
    first = _run(program, cache, "callback")
    files = _artifacts(cache)
    assert len(files) == 1 and files[0].endswith(".jaxexport.refused")
    assert "callback" in (cache / "gyrojax_export" / files[0]).read_text().lower()
    np.testing.assert_allclose(first["y"], _expected(1.0), rtol=1e-14)
    second = _run(program, cache, "callback")  # the marker: not traced for export again
    assert "export_response" not in second["traces"] and "response" in second["traces"]
    assert second["y"] == first["y"]


def test_a_python_output_takes_the_plain_path(program):
    """equinox.filter_jit returns a Python value as it is; an exported program would return an array."""
    cache = program / "cache"
    out = _run(program, cache, "python-output")
    assert out["points"] == "7"
    files = _artifacts(cache)
    assert len(files) == 1 and files[0].endswith(".refused")
    assert "not an array" in (cache / "gyrojax_export" / files[0]).read_text()


def test_a_disabled_cache_writes_nothing(program):
    out = _run(program, "off")
    assert out["cache"] is None
    np.testing.assert_allclose(out["y"], _expected(1.0), rtol=1e-14)
    assert "export_response" not in out["traces"]
    written = [os.path.join(d, f) for d, _, fs in os.walk(program) for f in fs]
    assert not any("gyrojax_export" in p or p.endswith("-cache") for p in written), written
    assert not (program / "xdg").exists()


def _forged(artifact: bytes, other: bytes) -> bytes:
    """`other`'s program under `artifact`'s key, its digest recomputed as anyone who can write the file can (a
    plain SHA-256 of the rest)."""
    import hashlib

    magic, key, _, _ = artifact.split(b"\n", 3)
    body = other.split(b"\n", 3)[3]
    return b"\n".join((magic, key, hashlib.sha256(body).hexdigest().encode(), body))


def test_a_tampered_artifact_is_refused_and_traced_again(program):
    """Whoever could write an artifact changed the numbers (a reported SF from 13709.208 to 13846.300): the
    program of OFFSET = 2.0 put under the key of OFFSET = 1.0 is refused, not run."""
    cache = program / "cache"
    _run(program, cache)
    (name,) = _artifacts(cache)
    path = cache / "gyrojax_export" / name
    (program / "plugin.py").write_text(PLUGIN.replace("OFFSET = 1.0", "OFFSET = 2.0"))
    _run(program, cache)
    (other,) = set(_artifacts(cache)) - {name}
    (program / "plugin.py").write_text(PLUGIN)  # the first key again
    good = path.read_bytes()
    path.write_bytes(_forged(good, (cache / "gyrojax_export" / other).read_bytes()))
    out = _run(program, cache)
    assert "export_response" in out["traces"]  # the forged file was not used
    np.testing.assert_allclose(out["y"], _expected(1.0), rtol=1e-14)
    assert sorted(_artifacts(cache)) == sorted([name, other])
    assert path.read_bytes() == good  # the program of this key, written again
    key = cache / "gyrojax_export.key"
    assert key.stat().st_size == 32 and key.stat().st_mode & 0o777 == 0o600


def test_a_symlinked_artifact_is_not_followed(program):
    cache = program / "cache"
    first = _run(program, cache)
    (name,) = _artifacts(cache)
    path = cache / "gyrojax_export" / name
    elsewhere = program / "elsewhere.jaxexport"
    path.rename(elsewhere)
    path.symlink_to(elsewhere)
    kept = elsewhere.read_bytes()
    second = _run(program, cache)
    assert "export_response" in second["traces"]  # the link was neither read ...
    assert second["y"] == first["y"]
    assert not path.is_symlink() and path.read_bytes() == kept  # ... nor written through
    assert elsewhere.read_bytes() == kept


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="POSIX FIFOs")
def test_an_artifact_that_is_a_fifo_is_replaced_not_opened(program):
    """Opening a FIFO blocks until someone opens its other end: an artifact path that is one is neither read
    nor written into."""
    cache = program / "cache"
    first = _run(program, cache)
    (name,) = _artifacts(cache)
    path = cache / "gyrojax_export" / name
    good = path.read_bytes()
    path.unlink()
    os.mkfifo(path)
    second = _run(program, cache, timeout=120)
    assert "export_response" in second["traces"] and second["y"] == first["y"]
    assert path.is_file() and path.read_bytes() == good


def test_an_export_folder_others_can_write_is_not_used(program):
    cache = program / "cache"
    (cache / "gyrojax_export").mkdir(parents=True, mode=0o700)
    (cache / "gyrojax_export").chmod(0o777)
    out = _run(program, cache)
    assert out["cache"] == str(cache) and "export_response" not in out["traces"] and "response" in out["traces"]
    np.testing.assert_allclose(out["y"], _expected(1.0), rtol=1e-14)
    assert _artifacts(cache) == []


# One device, the rate table only: identify's evaluation pass and vmapped solve, the two exported programs.
FIT = textwrap.dedent("""
    import json, os, sys
    import jax
    traces = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda e, d, fun_name="?", **k: traces.append(fun_name) if e.endswith("jaxpr_trace_duration") else None)
    import numpy as np
    import gyrojax as gj
    from gyrojax._compile import export as _export
    from gyrojax._model.parameters import DEFAULT_FREE

    table_path, out_path = sys.argv[1], sys.argv[2]
    if not os.path.exists(table_path):
        gj.write_table(gj.simulate_table(gj.paper_qmg(), devices=1, runs=1, sweeps=("rate_table",), seed=3,
                                         progress=False), table_path)
    table = gj.read_table(table_path)

    class NewProgram(BaseException):
        pass

    def refuse(fun, **options):
        raise NewProgram(fun.__name__.removeprefix("export_"))

    # Any program not already stored stops the fit before it is traced. (jax's function, not one of gyrojax's:
    # a gyrojax function replaced at run time is part of the key.)
    if "loaded-only" in sys.argv:
        _export.export.export = refuse
    del traces[:]
    fit = gj.identify("paper-qmg", table, progress=False)
    np.savez(out_path, *[np.asarray(x) for x in jax.tree.leaves(fit)])
    result = {"traces": traces, "new": {}}
    if "loaded-only" in sys.argv:
        for label, free in (("fewer free", ("k_vf", "angular_gain")), ("more free", DEFAULT_FREE + ("angular_gain",))):
            try:
                gj.identify("paper-qmg", table, free=free, progress=False)
            except NewProgram as e:
                result["new"][label] = str(e)
    print("RESULT " + json.dumps(result))
""")


@pytest.mark.slow
def test_a_second_process_fits_without_tracing_the_fit(tmp_path):
    """The exported solve (which also evaluates at the start): a second process with the same lot structure does
    not trace it and gives identical numbers (every array of the Fit); other free parameters are another
    program."""
    (tmp_path / "program.py").write_text(FIT)
    cache, table = tmp_path / "cache", str(tmp_path / "lot.csv")
    first = _run(tmp_path, cache, table, str(tmp_path / "first.npz"))
    assert "export_solve_independent" in first["traces"]
    assert sorted(n.split("-")[0] for n in _artifacts(cache)) == ["solve_independent"]
    second = _run(tmp_path, cache, table, str(tmp_path / "second.npz"), "loaded-only")
    assert not {"export_solve_independent", "_solve_each"} & set(second["traces"])
    a, b = np.load(tmp_path / "first.npz"), np.load(tmp_path / "second.npz")
    assert len(a.files) == len(b.files) > 50
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k])
    assert second["new"] == {"fewer free": "solve_independent", "more free": "solve_independent"}


def test_a_program_on_several_devices_takes_the_plain_path(program):
    cache = program / "cache"
    out = _run(program, cache, "sharded", devices=2)
    assert "response" in out["traces"] and "export_response" not in out["traces"]
    np.testing.assert_allclose(out["y"], _expected(1.0), rtol=1e-14)
    assert _artifacts(cache) == []
