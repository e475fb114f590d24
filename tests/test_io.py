"""Atomic writes of files and folders, file modes, links and FIFOs, and the output-path checks."""

import json
import os
import re
import stat
import threading

import pytest

from gyrojax._data import io as _io
from gyrojax._data.io import (
    FOLDER_MARKER,
    OutputPathError,
    atomic_directory,
    atomic_open,
    atomic_path,
    atomic_write_bytes,
    atomic_write_json,
    check_output_path,
    check_output_paths,
)


def test_umask_is_read_without_changing_it():
    mask = os.umask(0o022)
    os.umask(mask)
    assert _io._read_umask() == mask
    assert _io._UMASK == mask


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "out.json"
    atomic_write_bytes(path, b"old\n")

    def rows():
        yield b"new first half\n"
        raise RuntimeError("generator broke mid-write")

    with pytest.raises(RuntimeError, match="generator broke"), atomic_open(path, "wb") as f:
        for chunk in rows():
            f.write(chunk)
            f.flush()
            assert len(os.listdir(tmp_path)) == 2  # the partial data really is on disk, in the temporary
    assert path.read_bytes() == b"old\n"
    assert os.listdir(tmp_path) == ["out.json"]


def test_interrupt_during_write_cleans_up(tmp_path):
    path = tmp_path / "out.csv"
    with pytest.raises(KeyboardInterrupt), atomic_path(path) as tmp:
        with open(tmp, "w") as f:
            f.write("partial")
        raise KeyboardInterrupt
    assert os.listdir(tmp_path) == []


def test_modes_new_and_replaced(tmp_path):
    new = tmp_path / "new.json"
    atomic_write_json({"a": 1}, new)
    assert stat.S_IMODE(new.stat().st_mode) == 0o666 & ~_io._UMASK
    kept = tmp_path / "kept.json"
    kept.write_text("{}")
    kept.chmod(0o640)
    atomic_write_json({"a": 2}, kept)
    assert stat.S_IMODE(kept.stat().st_mode) == 0o640
    assert json.loads(kept.read_text()) == {"a": 2}


def test_write_through_a_symlink_keeps_the_link(tmp_path):
    target = tmp_path / "real.json"
    target.write_text("{}")
    target.chmod(0o600)
    link = tmp_path / "link.json"
    link.symlink_to(target.name)
    atomic_write_json({"x": 1.5}, link)
    assert link.is_symlink() and os.readlink(link) == "real.json"
    assert json.loads(target.read_text()) == {"x": 1.5}
    assert stat.S_IMODE(target.stat().st_mode) == 0o600
    dangling = tmp_path / "dangling.json"
    dangling.symlink_to("made.json")
    atomic_write_bytes(dangling, b"{}\n")
    assert dangling.is_symlink() and (tmp_path / "made.json").read_bytes() == b"{}\n"


def test_fifo_is_written_directly(tmp_path):
    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()))
    reader.start()
    atomic_write_json({"k": [1, 2]}, fifo)
    reader.join(10)
    assert json.loads(got[0]) == {"k": [1, 2]}
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)  # still a FIFO, not replaced by a file
    assert os.listdir(tmp_path) == ["pipe.json"]


def test_a_folder_is_not_a_file_target(tmp_path):
    with pytest.raises(IsADirectoryError, match="is an existing folder"):
        atomic_write_bytes(tmp_path, b"x")


def test_json_refuses_nan_naming_the_key(tmp_path):
    path = tmp_path / "r.json"
    with pytest.raises(ValueError, match=re.escape(f"{path}: not written: runs[1].residuals[0] is not a finite")):
        atomic_write_json({"runs": [{"residuals": [0.0]}, {"residuals": [float("nan")]}]}, path)
    assert not path.exists()


# ---------------------------------------------------------------------------------------------------------------
# Folders.


def test_atomic_directory_appears_whole(tmp_path):
    out = tmp_path / "report"
    with atomic_directory(out) as folder:
        assert not out.exists()  # nothing at the final path while it is being built
        (open(os.path.join(folder, "a.md"), "w")).write("a")
    assert sorted(os.listdir(out)) == sorted([FOLDER_MARKER, "a.md"])
    assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~_io._UMASK
    assert sorted(os.listdir(tmp_path)) == ["report"]


def test_atomic_directory_failure_keeps_the_old_folder(tmp_path):
    out = tmp_path / "report"
    with atomic_directory(out) as folder:
        (open(os.path.join(folder, "old.md"), "w")).write("old")
    with pytest.raises(RuntimeError, match="plot failed"), atomic_directory(out) as folder:
        (open(os.path.join(folder, "new.md"), "w")).write("half")
        raise RuntimeError("plot failed")
    assert sorted(os.listdir(out)) == sorted([FOLDER_MARKER, "old.md"])
    assert sorted(os.listdir(tmp_path)) == ["report"]


def test_atomic_directory_replaces_its_own_folder_as_a_whole(tmp_path):
    out = tmp_path / "report"
    with atomic_directory(out) as folder:
        (open(os.path.join(folder, "stale.png"), "w")).write("x")
    with atomic_directory(out) as folder:
        (open(os.path.join(folder, "fresh.md"), "w")).write("y")
    assert sorted(os.listdir(out)) == sorted([FOLDER_MARKER, "fresh.md"])  # stale.png is gone with the old
    assert sorted(os.listdir(tmp_path)) == ["report"]


def test_atomic_directory_nested_in_itself(tmp_path):
    # The command line wraps a writer that may itself use atomic_directory on the folder it is given.
    out = tmp_path / "report"
    with atomic_directory(out) as outer:
        with atomic_directory(outer) as inner:
            (open(os.path.join(inner, "d.md"), "w")).write("d")
    assert sorted(os.listdir(out)) == sorted([FOLDER_MARKER, "d.md"])
    assert sorted(os.listdir(tmp_path)) == ["report"]


def test_atomic_directory_refuses_foreign_folders_and_files(tmp_path):
    mine = tmp_path / "home"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    with pytest.raises(FileExistsError, match="gyrojax did not write"), atomic_directory(mine):
        pass
    assert (mine / "thesis.tex").read_text() == "precious"
    empty = tmp_path / "empty"
    empty.mkdir()
    with atomic_directory(empty) as folder:
        open(os.path.join(folder, "x"), "w").close()
    assert (empty / "x").exists()
    afile = tmp_path / "afile"
    afile.write_text("f")
    with pytest.raises(FileExistsError, match="is an existing file"), atomic_directory(afile):
        pass
    assert sorted(os.listdir(tmp_path)) == ["afile", "empty", "home"]


# ---------------------------------------------------------------------------------------------------------------
# Checks before work.


@pytest.mark.parametrize("case, folder, message", [
    ("missing-dir", False, r"--x {p}: the folder {d} does not exist"),
    ("is-dir", False, r"--x {p}: is an existing folder; give a file path"),
    ("file-as-folder", True, r"--x {p}: is an existing file, not a folder"),
    ("foreign-folder", True, r"--x {p}: is an existing folder that gyrojax did not write"),
    ("parent-is-file", False, r"--x {p}: {d} is not a folder"),
    ("empty", False, r"--x: the path is empty"),
])
def test_check_output_path_refusals(tmp_path, case, folder, message):
    (tmp_path / "file").write_text("x")
    (tmp_path / "dir").mkdir()
    (tmp_path / "dir" / "data.csv").write_text("x")
    path, parent = {
        "missing-dir": (tmp_path / "nodir" / "o.json", tmp_path / "nodir"),
        "is-dir": (tmp_path / "dir", tmp_path),
        "file-as-folder": (tmp_path / "file", tmp_path),
        "foreign-folder": (tmp_path / "dir", tmp_path),
        "parent-is-file": (tmp_path / "file" / "o.json", tmp_path / "file"),
        "empty": ("", tmp_path),
    }[case]
    pattern = message.format(p=re.escape(str(path)), d=re.escape(str(parent)))
    with pytest.raises(OutputPathError, match=pattern):
        check_output_path(path, "--x", folder=folder)


def test_check_output_path_accepts(tmp_path):
    check_output_path(tmp_path / "new.json", "--json")
    check_output_path(tmp_path / "new_folder", "--report", folder=True)
    (tmp_path / "old.json").write_text("{}")
    check_output_path(tmp_path / "old.json", "--json")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_check_output_path_unwritable_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(OutputPathError, match="is not writable"):
            check_output_path(ro / "o.json", "--json")
    finally:
        ro.chmod(0o700)


def test_two_outputs_at_one_path_are_refused(tmp_path):
    p = str(tmp_path / "same")
    with pytest.raises(OutputPathError, match=r"--save .*same: --json writes the same path"):
        check_output_paths([("--json", p, False), ("--save", p, False)])
