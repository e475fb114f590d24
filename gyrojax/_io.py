"""Atomic file writes: a reader never sees a half-written file, and a failed write keeps the old one."""

import json
import os
import tempfile


def atomic_write_bytes(path, data: bytes):
    """Write `data` to a temporary file beside `path`, then move it into place with os.replace."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{os.path.basename(path)}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_json(obj, path):
    """Write `obj` as indented JSON (NaN refused) atomically."""
    text = json.dumps(obj, indent=2, allow_nan=False, default=float) + "\n"
    atomic_write_bytes(path, text.encode())
