"""The chunks of a lot and its results folder: `OUT.parts/` holds `manifest.json` (the input file, its size
and modification time, the device list's digest, the chunk size and the fit's options: what a restart must
match), the input split by chunk (CSV: `input/chunk-00012.csv`), and each chunk's result as it finishes
(`chunk-00012.json`, or `chunk-00012.failed.json` with the error)."""

import hashlib
import json
import os

from .._data.chunked import device_order, split_csv
from .._data.files import table_format
from .._data.io import atomic_write_json


def parts_folder(out: str) -> str:
    return f"{os.fspath(out)}.parts"


def chunk_name(k: int) -> str:
    return f"chunk-{k:05d}"


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


class Plan:
    """A lot's chunks and where their inputs and results are: `devices` (the input's list, in order of first
    appearance), `groups` (devices per chunk), `folder`, and per chunk its `split_file` (None for Parquet)."""

    def __init__(self, data: str, out: str, chunk: int, options: dict):
        self.data = os.fspath(data)
        self.folder = parts_folder(out)
        suffix = table_format(self.data, "identify_lot")
        st = os.stat(self.data)
        manifest_path = os.path.join(self.folder, "manifest.json")
        wanted = {"data": os.path.abspath(self.data), "size": st.st_size, "mtime_ns": st.st_mtime_ns,
                  "chunk": chunk, "options": _digest(options)}
        if os.path.exists(manifest_path):
            with open(manifest_path, encoding="utf-8") as f:
                manifest = json.load(f)
            differ = [k for k in wanted if manifest.get(k) != wanted[k]]
            if differ:
                raise ValueError(f"{self.folder}: the results folder belongs to another run (its {', '.join(differ)} "
                                 f"differ{'s' if len(differ) == 1 else ''} from this one's): a restart continues "
                                 "only with the same data file and options; remove the folder to start again.")
            self.devices = manifest["devices"]
            self.resumed = True
        else:
            os.makedirs(os.path.join(self.folder, "input"), exist_ok=True)
            self.devices = device_order(self.data)
            if not self.devices:
                raise ValueError(f"{self.data}: no devices (no data rows) to fit.")
            self.resumed = False
        self.groups = [self.devices[i:i + chunk] for i in range(0, len(self.devices), chunk)]
        self.split_files = [None if suffix == ".parquet" else os.path.join(self.folder, "input", chunk_name(k) + ".csv")
                            for k in range(len(self.groups))]
        csv_files = [p for p in self.split_files if p is not None]  # every chunk's, for a .csv
        if suffix == ".csv" and not all(os.path.exists(p) for p in csv_files):
            split_csv(self.data, self.groups, csv_files)
        if not self.resumed:
            atomic_write_json({**wanted, "devices": self.devices}, manifest_path)

    def result(self, k: int) -> str:
        return os.path.join(self.folder, chunk_name(k) + ".json")

    def failure(self, k: int) -> str:
        return os.path.join(self.folder, chunk_name(k) + ".failed.json")

    def done(self) -> list[int]:
        return [k for k in range(len(self.groups)) if os.path.exists(self.result(k))]
