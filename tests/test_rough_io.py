"""Reading what a user (or a hostile file) gives (issue 36): only regular files, within bounds, each read in a
subprocess under a 2 GB address-space limit and a timeout; and a saved fit used only with the data it was
fitted to, with a header that cannot be edited unseen."""

import json
import os
import struct
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._identify.fitio import MAGIC, header_digest
from gyrojax.cli import main


# Runs each (reader, path) under RLIMIT_AS = 2 GB (set after the import, as the limit is for the read), prints
# for each the seconds it took and the error it raised.
READER = textwrap.dedent("""
    import json, resource, sys, time
    import gyrojax as gj
    resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, 2 * 2**30))
    out = []
    for reader, path in json.loads(sys.argv[1]):
        t = time.perf_counter()
        try:
            getattr(gj, reader)(path)
            error = None
        except Exception as e:
            error = type(e).__name__ + ": " + str(e)
        out.append({"seconds": time.perf_counter() - t, "error": error})
    print("RESULT " + json.dumps(out))
""")


def _read_in_child(cases, timeout=120):
    proc = subprocess.run([sys.executable, "-c", READER, json.dumps(cases)], capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "GYROJAX_CACHE_DIR": "off"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


@pytest.mark.skipif(not hasattr(os, "mkfifo") or not os.path.exists("/dev/zero"), reason="POSIX FIFOs and /dev/zero")
def test_dev_zero_a_fifo_and_a_folder_are_refused_within_a_second(tmp_path):
    """A symbolic link to /dev/zero grew a reader to 24 GB; a FIFO blocked the open until a writer came."""
    paths = {}
    for suffix in (".fit", ".csv", ".parquet"):
        zero, fifo = tmp_path / f"zero{suffix}", tmp_path / f"fifo{suffix}"
        zero.symlink_to("/dev/zero")
        os.mkfifo(fifo)
        folder = tmp_path / f"folder{suffix}"
        folder.mkdir()
        paths[suffix] = (zero, fifo, folder)
    cases = [("load_fit" if suffix == ".fit" else "read_table", str(p)) for suffix, ps in paths.items() for p in ps]
    results = _read_in_child(cases)
    for (reader, path), r in zip(cases, results):
        assert r["seconds"] < 1.0, (path, r)
        assert r["error"] is not None and path in r["error"], (path, r)
        expected = "a .csv or .parquet file" if reader == "read_table" else "a fit file written by gyrojax.save_fit"
        assert expected in r["error"], r["error"]
    by_path = dict(zip((p for _, p in cases), (r["error"] for r in results)))
    zero = str(paths[".fit"][0])
    assert by_path[zero] == (f"NotARegularFile: {zero} (a link to /dev/zero) is a character device, not a regular "
                             "file; give a fit file written by gyrojax.save_fit or `gyrojax identify --save`.")
    fifo = str(paths[".csv"][1])
    assert by_path[fifo] == (f"DataError: {fifo} is a FIFO (named pipe), not a regular file; give a .csv or "
                             ".parquet file.")
    folder = str(paths[".parquet"][2])
    assert by_path[folder] == f"DataError: {folder} is a directory; give a .csv or .parquet file."


def test_a_fit_header_longer_than_the_file_is_refused(tmp_path):
    path = tmp_path / "claims.fit"
    path.write_bytes(MAGIC + struct.pack("<Q", 10**12) + b"{}")
    with pytest.raises(ValueError, match=r"claims\.fit: corrupt gyrojax fit file: unreadable header \(its header "
                                         r"claims 1000000000000 bytes; the file holds 2 after"):
        gj.load_fit(path)


def test_a_csv_is_read_line_by_line_with_a_bounded_line(tmp_path, monkeypatch):
    """The CSV reader takes one line at a time from the file (never the whole file as one string), and a line
    longer than the bound is refused: a file without line ends is not read whole."""
    from gyrojax._data import files

    path = tmp_path / "long.csv"
    path.write_text("device,run,sweep,input,output\n" + "d0,0,rate_table,1.0," + "1" * 300 + "\n")
    monkeypatch.setattr(files, "MAX_LINE_CHARS", 100)
    with pytest.raises(gj.DataError, match=r"long\.csv: a line \(after line 1\) is longer than 100 characters"):
        gj.read_table(path)


# --- a saved fit: its header checked, and used only with its own data -------------------------------------

@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A fit of two devices' rate tables, its file, and the data file it was fitted to."""
    folder = tmp_path_factory.mktemp("saved")
    table = gj.simulate_table(gj.paper_qmg(), devices=2, runs=1, sweeps=("rate_table",), seed=3, progress=False)
    data = folder / "b1.csv"
    gj.write_table(table, data)
    fit = gj.identify("paper-qmg", gj.read_table(data), progress=False)
    path = folder / "b1.fit"
    gj.save_fit(fit, path)
    return fit, path, data


def _split(path):
    raw = path.read_bytes()
    (length,) = struct.unpack("<Q", raw[len(MAGIC):len(MAGIC) + 8])
    start = len(MAGIC) + 8
    return json.loads(raw[start:start + length]), raw[start + length:]


def _write(path, header, payload):
    head = json.dumps(header).encode()
    path.write_bytes(MAGIC + struct.pack("<Q", len(head)) + head + payload)


@pytest.mark.slow
def test_a_forged_huge_shape_is_refused_before_anything_is_allocated(saved, tmp_path):
    """A header claiming a 1e6 x 1e6 array (checksums recomputed, as a forger would) is refused by name in a
    process that could not allocate it."""
    _, path, _ = saved
    header, payload = _split(path)
    i = next(k for k, s in enumerate(header["leaves"]) if s["kind"] == "jax" and s["shape"])
    header["leaves"][i]["shape"] = [1_000_000, 1_000_000]
    header["header_sha256"] = header_digest(header)
    forged = tmp_path / "forged.fit"
    _write(forged, header, payload)
    (r,) = _read_in_child([("load_fit", str(forged))])
    assert r["seconds"] < 1.0
    assert r["error"].startswith(f"ValueError: {forged}: corrupt gyrojax fit file: its header describes ")
    assert (f"the largest: array {i} of shape [1000000, 1000000] and dtype " in r["error"]
            and f"but the file holds {len(payload)} bytes after its header" in r["error"]), r["error"]


@pytest.mark.slow
def test_an_edited_fit_header_is_refused(saved, tmp_path):
    """A status edited by hand (here "ok" to "not determined"; the other way round alike) loaded silently
    when only the arrays had a checksum."""
    _, path, _ = saved
    header, payload = _split(path)
    assert header["format_version"] == 3 and header["status"] == ["ok", "ok"]
    header["status"][1] = "not determined"
    edited = tmp_path / "edited.fit"
    _write(edited, header, payload)
    with pytest.raises(ValueError, match=r"edited\.fit: corrupt gyrojax fit file: its header does not match the "
                                         r"header's checksum \(edited or damaged\)"):
        gj.load_fit(edited)
    # Declared an older format to escape the check: read, but never silently.
    del header["header_sha256"]
    header["format_version"] = 2
    _write(edited, header, payload)
    with pytest.warns(UserWarning, match=r"edited\.fit: this fit file \(format version 2\) predates the header's "
                                         r"checksum"):
        gj.load_fit(edited)


def _other_data(data, tmp_path, name, device, change):
    """The data file `data` with one output changed by `change` (of `device`, at its rate-table input 100)."""
    table = gj.read_table(data)
    columns = {c: table[c].copy() for c in table.column_names}
    row = int(np.flatnonzero((table["device"] == device) & (table["input"] == 100.0))[0])
    columns["output"][row] = change(columns["output"][row])
    path = tmp_path / name
    gj.write_table(gj.Table(columns), path)
    return path, row


@pytest.mark.slow
def test_a_fit_is_used_only_with_the_data_it_was_fitted_to(saved, tmp_path, capsys):
    """The same device names and point counts were enough: a fit of other data was taken as theirs."""
    from gyrojax._identify.fitmatch import check_fit_data
    from gyrojax._model.fitdata import fit_data

    fit, path, data = saved
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = gj.load_fit(path)
    check_fit_data(loaded, fit_data(gj.read_table(data)))  # its own data, read again: accepted
    device = fit.devices[1]
    other, row = _other_data(data, tmp_path, "other.csv", device, lambda y: y + 1.0)
    message = (rf"fit: it was fitted to other data than those given \(the fit's data came from .*b1\.csv, the data "
               rf"given from .*other\.csv\): sweep 'rate_table', device '{device}', column 'output': 1 of \d+ values "
               r"differ; the first at run 0, point \d+ \(input 100\.0 in the data given\): .* in the fit's data, "
               r".* in the data given; give the fit of this data")
    table = gj.read_table(other)
    with pytest.raises(ValueError, match=message):
        gj.diagnose(data=table, fit=loaded, progress=False)
    with pytest.raises(ValueError, match=message):
        gj.plan(data=table, fit=loaded, progress=False)
    for command in ("diagnose", "plan"):
        assert main([command, str(other), "--fit", str(path), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert "column 'output': 1 of" in err and "Traceback" not in err
    # another seed's lot: the same names and counts, every value another
    seed4 = tmp_path / "seed4.csv"
    gj.write_table(gj.simulate_table(gj.paper_qmg(), devices=2, runs=1, sweeps=("rate_table",), seed=4,
                                     progress=False), seed4)
    with pytest.raises(ValueError, match=rf"device '{fit.devices[0]}', column 'output': (\d+) of \1 values differ"):
        gj.diagnose(data=gj.read_table(seed4), fit=loaded, progress=False)
