"""One chunk's fit, run in a worker process: read the chunk's rows, `identify` them with the lot's options,
write the result (the chunk's identify report with each device's chi2 and dof) atomically; a chunk whose data
or fit raises writes its failure (the error's type and message) instead, so that the run goes on."""

import dataclasses
import os
import sys
import time
import traceback

from .._data.io import atomic_write_json


def fit_chunk(task: dict) -> dict:
    """Fit one chunk (`task` from `identify_lot`: `index`, `devices`, `first_device` (the position of its first
    device in the lot), `data`, `split_file`, `model`, `options`, `chunk`, `result`, `failure`).
    Returns a short summary for the progress line."""
    import numpy as np

    from .._data.chunked import read_chunk
    from .._identify import Fit, MultiStart, VmapSolve, identify
    from .._identify.report import fit_report

    start = time.perf_counter()
    try:
        table = read_chunk(task["data"], task["devices"], task["split_file"])
        got = set(table["device"].tolist())
        if got != set(task["devices"]):
            missing = sorted(set(task["devices"]) - got)
            raise ValueError(f"{task['data']}: the chunk's rows lack devices {missing[:5]} (or hold others): the "
                             "file changed since the run was planned; remove the results folder to start again.")
        # The noise Monte Carlo of data without output_sigma draws each device with its position in the lot.
        first = dataclasses.replace(task["options"].get("start", MultiStart()), first_device=task["first_device"])
        fit = identify(task["model"], table, lot_solve=VmapSolve(pad_to=task["chunk"]), progress=False,
                       **{**task["options"], "start": first})
        if not isinstance(fit, Fit):  # lot_solve is a VmapSolve: never a population fit
            raise RuntimeError(f"the chunk's fit is a {type(fit).__name__}, not a gyrojax.Fit.")
        if list(fit.devices) != list(task["devices"]):
            raise RuntimeError(f"the chunk's fit holds devices {list(fit.devices)[:5]} in another order than the "
                               f"plan's {list(task['devices'])[:5]}: their positions in the lot would be wrong.")
        report = fit_report(fit)
        report["chi2"] = [float(x) if np.isfinite(x) else None for x in np.asarray(fit.chi2)]
        report["dof"] = [int(x) for x in np.asarray(fit.dof)]
        report["seconds"] = time.perf_counter() - start
        report["chunk"] = task["index"]
        report["worker"] = {"pid": os.getpid(), "peak_rss_mb": _peak_rss_mb()}
        atomic_write_json(report, task["result"])
        if os.path.exists(task["failure"]):
            os.remove(task["failure"])
        return {"index": task["index"], "devices": len(task["devices"]), "failed": 0,
                "seconds": report["seconds"]}
    except Exception as e:  # a chunk's failure is a result: recorded, reported, retried on a restart
        atomic_write_json({"chunk": task["index"], "devices": list(task["devices"]), "error": type(e).__name__,
                           "message": str(e), "traceback": traceback.format_exc(limit=8)}, task["failure"])
        return {"index": task["index"], "devices": len(task["devices"]), "failed": len(task["devices"]),
                "seconds": time.perf_counter() - start}


def _peak_rss_mb() -> float | None:
    """The worker process's peak resident memory, MB (None where the platform does not say)."""
    try:
        import resource
    except ImportError:
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10  # bytes on macOS, KiB on Linux
