"""The persistent compilation cache that gyrojax turns on at import (gyrojax/_compile/cache.py), checked in fresh
processes: the suite's own cache (tests/conftest.py sets JAX_COMPILATION_CACHE_DIR) is kept out of them."""

import json
import os
import subprocess
import sys
import textwrap

import pytest


# Imports gyrojax with the monitoring listeners in place, runs `work`, prints what happened as JSON.
CHILD = textwrap.dedent("""
    import json, os, sys, time, warnings
    import jax
    counts, seconds = {}, {}
    jax.monitoring.register_event_listener(lambda e, **k: counts.__setitem__(e, counts.get(e, 0) + 1))
    jax.monitoring.register_event_duration_secs_listener(
        lambda e, d, **k: seconds.__setitem__(e, seconds.get(e, 0.0) + d))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        import gyrojax as gj
    import jax.numpy as jnp
    result = {"dir": gj.io.compilation_cache(), "warnings": [str(w.message) for w in caught
                                                           if issubclass(w.category, RuntimeWarning)]}
    WORK
    result["hits"] = counts.get("/jax/compilation_cache/cache_hits", 0)
    result["writes"] = counts.get("/jax/compilation_cache/cache_misses", 0)
    result["compile_s"] = seconds.get("/jax/core/compile/backend_compile_duration", 0.0)
    print("RESULT " + json.dumps(result))
""")

SETTLE = "result['rate'] = float(gj.settle(gj.paper_qmg(), gj.physics.Stimulus(rate=0.1), gj.Steady()).rate)"
TINY = "result['y'] = float(jax.jit(lambda x: jnp.sum(x * 2.0))(jnp.arange(3.0)))"


def _run(tmp_path, work, **env_vars):
    env = {k: v for k, v in os.environ.items()
           if k not in ("JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
                        "JAX_ENABLE_COMPILATION_CACHE", "GYROJAX_CACHE_DIR")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")  # the default folder, never the user's own
    env.update(env_vars)
    code = CHILD.replace("WORK", textwrap.dedent(work).strip())
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def _entries(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith("-cache")) if folder.exists() else []


def test_a_second_process_loads_a_small_program(tmp_path):
    """The fast tier's check of loading (the settle below is the slow tier's): a second process hits every
    program the first wrote and writes none."""
    cache = tmp_path / "moved"
    first = _run(tmp_path, TINY, GYROJAX_CACHE_DIR=str(cache))
    written = _entries(cache)
    assert written and first["writes"] == len(written) and first["y"] == 6.0
    second = _run(tmp_path, TINY, GYROJAX_CACHE_DIR=str(cache))
    assert second["y"] == 6.0 and second["writes"] == 0 and second["hits"] >= len(written)
    assert _entries(cache) == written


@pytest.mark.slow
def test_a_second_process_loads_what_the_first_compiled(tmp_path):
    cache = tmp_path / "moved"
    first = _run(tmp_path, SETTLE, GYROJAX_CACHE_DIR=str(cache))
    assert first["dir"] == str(cache) and first["warnings"] == []
    written = _entries(cache)
    assert written and first["writes"] == len(written)  # (identical small programs hit within the process)
    assert not (tmp_path / "xdg").exists()  # the variable moved it away from the default

    second = _run(tmp_path, SETTLE, GYROJAX_CACHE_DIR=str(cache))
    assert second["rate"] == first["rate"]
    assert second["writes"] == 0 and second["hits"] >= len(written)
    assert _entries(cache) == written
    # Loading instead of compiling: measured 4.2 s -> 0.3 s on a 2-core CPU; a factor 2 leaves room for load.
    assert second["compile_s"] < 0.5 * first["compile_s"], (first["compile_s"], second["compile_s"])


def test_the_default_folder_is_per_user(tmp_path):
    r = _run(tmp_path, TINY)
    default = tmp_path / "xdg" / "gyrojax" / "jax"
    assert r["dir"] == str(default) and r["warnings"] == []
    assert _entries(default) and r["writes"] == len(_entries(default))


@pytest.mark.parametrize("value", ["OFF", ""])  # case does not matter
def test_off_disables_it(tmp_path, value):
    r = _run(tmp_path, TINY, GYROJAX_CACHE_DIR=value)
    assert r["dir"] is None and r["y"] == 6.0 and r["writes"] == 0 and r["warnings"] == []
    assert not (tmp_path / "xdg").exists()


def test_an_unwritable_folder_warns_once_and_works_without_a_cache(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    bad = blocker / "cache"  # cannot be created, whoever runs the test (root ignores permission bits)
    r = _run(tmp_path, TINY, GYROJAX_CACHE_DIR=str(bad))
    assert r["dir"] is None and r["y"] == 6.0 and r["writes"] == 0
    assert len(r["warnings"]) == 1 and str(bad) in r["warnings"][0] and "GYROJAX_CACHE_DIR" in r["warnings"][0]


def test_a_cache_jax_was_given_is_left_alone(tmp_path):
    own = tmp_path / "jax-own"
    r = _run(tmp_path, TINY, JAX_COMPILATION_CACHE_DIR=str(own), GYROJAX_CACHE_DIR=str(tmp_path / "ignored"))
    assert r["dir"] == str(own) and not (tmp_path / "ignored").exists()
    r = _run(tmp_path, TINY, JAX_ENABLE_COMPILATION_CACHE="false")
    assert r["writes"] == 0 and not (tmp_path / "xdg").exists()


def test_compilation_cache_moves_disables_and_checks_its_argument(tmp_path):
    moved, blocker = tmp_path / "by-call", tmp_path / "a-file"
    blocker.write_text("not a folder")
    r = _run(tmp_path, f"""
        result['moved'] = gj.io.compilation_cache({str(moved)!r})
        jax.jit(lambda x: x + 1.0)(jnp.ones(2)).block_until_ready()
        result['n_moved'] = len([p for p in os.listdir({str(moved)!r}) if p.endswith('-cache')])
        result['off'] = gj.io.compilation_cache(None)
        result['now'] = gj.io.compilation_cache()
        jax.jit(lambda x: x - 1.0)(jnp.ones(2)).block_until_ready()
        result['n_after_off'] = len([p for p in os.listdir({str(moved)!r}) if p.endswith('-cache')])
        errors = []
        for bad in (3, {str(blocker / "sub")!r}):
            try:
                gj.io.compilation_cache(bad)
            except (TypeError, ValueError) as e:
                errors.append(type(e).__name__ + ': ' + str(e))
        result['errors'] = errors
        result['still_off'] = gj.io.compilation_cache()
    """, GYROJAX_CACHE_DIR="off")
    assert r["moved"] == str(moved) and r["n_moved"] >= 1
    assert r["off"] is None and r["now"] is None and r["n_after_off"] == r["n_moved"]
    assert len(r["errors"]) == 2 and all("path" in e for e in r["errors"])
    assert r["errors"][0].startswith("TypeError") and r["errors"][1].startswith("ValueError")
    assert r["still_off"] is None


def _import_stderr(tmp_path, **env_vars):
    """What a plain `import gyrojax` prints on standard error (Python's own warning display)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("JAX_COMPILATION_CACHE_DIR", "JAX_ENABLE_COMPILATION_CACHE", "GYROJAX_CACHE_DIR")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    env.update(env_vars)
    proc = subprocess.run([sys.executable, "-c", "import gyrojax; print(gyrojax.io.compilation_cache())"], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout.strip(), proc.stderr


def test_a_folder_others_can_write_is_not_used(tmp_path):
    """Whoever can write the folder can change the programs gyrojax runs: a world-writable folder gives one
    warning, naming it and why, and no cache."""
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)
    r = _run(tmp_path, TINY, GYROJAX_CACHE_DIR=str(shared))
    assert r["dir"] is None and r["y"] == 6.0 and r["writes"] == 0
    assert len(r["warnings"]) == 1
    assert (f"the compilation cache folder {shared} from GYROJAX_CACHE_DIR={str(shared)!r} is not used: it is "
            "writable by its group and all users (mode 0o777)") in r["warnings"][0]
    assert os.listdir(shared) == []
    printed, err = _import_stderr(tmp_path, GYROJAX_CACHE_DIR=str(shared))
    assert printed == "None"
    assert err.count("gyrojax: warning: the compilation cache folder") == 1 and "RuntimeWarning" not in err, err
    r = _run(tmp_path, f"""
        try:
            gj.io.compilation_cache({str(shared)!r})
        except ValueError as e:
            result['error'] = str(e)
    """, GYROJAX_CACHE_DIR="off")
    assert "cannot be used as a cache folder (it is writable by its group and all users" in r["error"]


def test_the_unwritable_folder_warning_is_printed_once_in_gyrojax_words(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    printed, err = _import_stderr(tmp_path, GYROJAX_CACHE_DIR=str(blocker / "cache"))
    assert printed == "None"
    assert f"gyrojax: warning: the compilation cache folder {blocker / 'cache'} " in err, err
    assert err.count("gyrojax: warning:") == 1 and "_cache.py" not in err and "RuntimeWarning" not in err, err


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="giving a folder away needs root")
def test_a_folder_of_another_user_is_not_used(tmp_path):
    theirs = tmp_path / "theirs"
    theirs.mkdir(mode=0o700)
    os.chown(theirs, 65534, 65534)
    r = _run(tmp_path, TINY, GYROJAX_CACHE_DIR=str(theirs))
    assert r["dir"] is None and r["writes"] == 0 and len(r["warnings"]) == 1
    assert "is not used: it is owned by user id 65534, not by the user running gyrojax" in r["warnings"][0]
