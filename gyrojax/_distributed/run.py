"""`identify_lot`: a lot from a table file fitted in chunks of devices on a Dask cluster, resumable, with one
progress line and a merged report in which every device of the input appears exactly once."""

import json
import os
import time
from collections import Counter
from collections.abc import Sequence
from typing import Any

import jax.numpy as jnp
import numpy as np

from .._data.chunked import file_sweep_kinds
from .._data.io import atomic_write_json
from .._gyroscope import Gyroscope
from .._identify.covariance import chi2_p_value
from .._identify.fit import EXIT_CODES, EXIT_PRECEDENCE
from .._identify.spec import free_reading
from .._model.parameters import Model, as_model
from .._runtime.progress import ProgressArg, as_progress
from .engine import DistributedSolve
from .plan import Plan
from .task import fit_chunk


# identify's options a chunk fit takes as they are; shared parameters and population fits couple the devices.
_COUPLED = ("shared", "lot_solve")


def identify_lot(model: Model | Gyroscope | str, data: str, out: str, strategy: DistributedSolve,
                 *, free: Sequence[str] | None = None, progress: ProgressArg = True, **options: Any) -> dict:
    """Fit every device of the table file `data` (CSV or Parquet, read a chunk of devices at a time) with
    `identify`'s independent per-device fit, in chunks on the Dask cluster of `strategy`, and write the merged
    identify report (docs/cli.md's keys) to `out` (JSON).

    Each chunk's result is written to `out + ".parts"` as it finishes; a run started again with the same
    data and options continues from the chunks done (a different file or options are refused). A chunk whose
    worker died is run again on another one (`strategy.retries`); a chunk whose data or fit raises is recorded
    (`failed` in the report, with the error) and run again by the next restart. The report lists every device
    of the input exactly once: in `devices`, or in `failed`.

    **Arguments:** `model` as for `identify` (one device: the start of every device); `free` (None: the
    default free parameters and what the sweep kinds of the whole file read, the same for every chunk) and `options`
    (`hold`, `priors`, `tier`, `solver`, `rtol`, `atol`, `max_steps`, `start`, `recovery`,
    `identifiability_threshold`, `reject_alpha`, `estimate_noise`) as for `identify`. `shared` parameters,
    `lot_solve` and `start` with more than one start are refused: they couple the devices of a lot, which chunks
    fit apart; so are chunks that held different parameters as unidentifiable (raised by the merge). The fit is
    one process's `identify` bit for bit on a CPU for chunks of a multiple of 16 (docs/performance.md).

    **Returns:** the report (a dict), also written to `out`.
    """
    if not isinstance(strategy, DistributedSolve):
        raise TypeError(f"strategy must be a gyrojax.DistributedSolve, got {type(strategy).__name__}.")
    coupled = [k for k in _COUPLED if options.get(k)]
    if coupled:
        raise ValueError(f"identify_lot: {', '.join(coupled)} couple the devices of a lot (one fit of all of them), "
                         "which a lot run in chunks of devices cannot do; fit a shared parameter or a population "
                         "with identify on one process (lot_solve=JointSolve() or PopulationSolve()).")
    first_solve = options.get("start")
    if first_solve is not None and getattr(first_solve, "starts", 1) > 1:
        raise ValueError(f"identify_lot: start={first_solve!r}: more than one start draws every device's starts "
                         "from one stream of the whole lot, which a chunk of devices cannot draw; use starts=1 (the "
                         "default), or identify on one process.")
    strategy.require()  # before the file is planned and split
    model = as_model(model)
    say = as_progress(progress, "gyrojax identify")
    # The file's sweep kinds, not each chunk's: a chunk without a kind's runs would free less than the others.
    free = free_reading(file_sweep_kinds(data), model.device) if free is None else tuple(free)
    options = {**options, "free": free}
    plan = Plan(data, out, strategy.chunk, {k: repr(v) for k, v in sorted(options.items())} | {"model": repr(model)})
    todo = [k for k in range(len(plan.groups)) if k not in set(plan.done())]
    n_done_before = sum(len(plan.groups[k]) for k in range(len(plan.groups)) if k not in todo)
    say(f"{len(plan.devices)} device(s) in {len(plan.groups)} chunk(s) of {strategy.chunk}"
        + (f"; {len(plan.groups) - len(todo)} chunk(s) ({n_done_before} devices) done by an earlier run, resuming"
           if plan.resumed and len(todo) < len(plan.groups) else ""))
    start = time.perf_counter()
    if todo:
        _run_chunks(plan, todo, model, options, strategy, say, n_done_before, start)
    report = merge(plan)
    report["distributed"] = {"engine": "dask", "chunk": strategy.chunk, "chunks": len(plan.groups),
                             "workers": strategy.workers, "scheduler": strategy.scheduler,
                             "devices": len(plan.devices), "devices_failed": len(report["failed"]),
                             "chunks_run": len(todo), "seconds": time.perf_counter() - start,
                             "results": plan.folder}
    atomic_write_json(report, out)
    return report


def _run_chunks(plan, todo, model, options, strategy, say, n_done_before, start):
    from distributed import as_completed

    total = len(plan.devices)
    tasks = chunk_tasks(plan, todo, model, options, strategy.chunk)
    done, failed = n_done_before, 0
    with strategy.client() as client:
        # pure=False: a chunk submitted again (a restart) is a new task, not one the scheduler remembers.
        futures = {client.submit(fit_chunk, t, pure=False): t for t in tasks}
        for future in as_completed(futures):
            task = futures[future]
            try:
                summary = future.result()
            except Exception as e:  # the worker died `retries + 1` times (KilledWorker), or the task could not run
                atomic_write_json({"chunk": task["index"], "devices": list(task["devices"]), "error": type(e).__name__,
                                   "message": f"the chunk's worker process died {strategy.retries + 1} time(s) "
                                              f"running it ({e})" if type(e).__name__ == "KilledWorker" else str(e)},
                                  task["failure"])
                summary = {"devices": len(task["devices"]), "failed": len(task["devices"])}
            done += summary["devices"] - summary["failed"]
            failed += summary["failed"]
            say(progress_line(done, failed, total, n_done_before, time.perf_counter() - start))


def chunk_tasks(plan: Plan, todo, model, options: dict, chunk: int) -> list[dict]:
    """The `fit_chunk` task of each chunk of `todo`: its devices and their position in the lot, where its rows
    are, the fit's options, where its result goes."""
    first = np.cumsum([0] + [len(g) for g in plan.groups])
    return [{"index": k, "devices": plan.groups[k], "first_device": int(first[k]), "data": plan.data,
             "split_file": plan.split_files[k], "model": model, "options": options, "chunk": chunk,
             "result": plan.result(k), "failure": plan.failure(k)} for k in todo]


def progress_line(done: int, failed: int, total: int, done_before: int, seconds: float) -> str:
    """'12/40 devices done, 0 failed, 1.3 devices/s, ETA 22 s': the rate over the devices this run finished."""
    here = done + failed - done_before
    rate = here / seconds if seconds > 0 else 0.0
    left = total - done - failed
    eta = f"ETA {left / rate:.0f} s" if rate > 0 and left else ("ETA 0 s" if not left else "ETA unknown")
    return f"{done}/{total} devices done, {failed} failed, {rate:.2f} devices/s, {eta}"


def merge(plan: Plan) -> dict:
    """The identify report of the whole lot from its chunks' results: devices in the input's order, `failed`
    (per failed or unfinished chunk: its devices and the error), lot-level chi2 and p-value from the devices'
    chi2 and dof. Raises `RuntimeError` unless every device of the input is there exactly once."""
    devices, failed, chi2, dof, noise_dof = [], [], [], [], []
    unidentifiable, directions, compare, alpha, held = [], [], [], None, {}
    for k, group in enumerate(plan.groups):
        if os.path.exists(plan.result(k)):
            with open(plan.result(k), encoding="utf-8") as f:
                r = json.load(f)
            devices += r["devices"]
            chi2 += [np.nan if c is None else c for c in r["chi2"]]
            dof += r["dof"]
            noise_dof += [np.inf if d["noise_dof"] is None else d["noise_dof"] for d in r["devices"]]
            unidentifiable += [p for p in r["unidentifiable"] if p not in unidentifiable]
            held[k] = tuple(sorted({u["held"] for u in r["unidentifiable_directions"]}))
            # A direction's singular value is its chunk's (each chunk file has it), not the lot's: left out.
            directions += [u for u in ({**u, "singular_value": None} for u in r["unidentifiable_directions"])
                           if u not in directions]
            compare.append({"chunk": k, "devices": group, **r["compare"]})
            alpha = r["reject_alpha"]
        elif os.path.exists(plan.failure(k)):
            with open(plan.failure(k), encoding="utf-8") as f:
                r = json.load(f)
            failed.append({"chunk": k, "devices": group, "error": r["error"], "message": r["message"]})
        else:
            failed.append({"chunk": k, "devices": group, "error": "NotRun", "message": "the chunk has no result"})
    names = Counter([d["device"] for d in devices] + [d for f in failed for d in f["devices"]])
    if names != Counter(plan.devices) or any(k > 1 for k in names.values()):
        extra = sorted(set(names) - set(plan.devices))
        missing = sorted(set(plan.devices) - set(names))
        twice = sorted(d for d, k in names.items() if k > 1)
        raise RuntimeError(f"{plan.folder}: the merged results do not hold every device of {plan.data} exactly once "
                           f"(missing {missing[:5]}, twice {twice[:5]}, not in the input {extra[:5]}).")
    _check_same_holds(plan, held)
    order = {d: i for i, d in enumerate(plan.devices)}
    by_order = np.argsort([order[d["device"]] for d in devices], kind="stable")
    devices = [devices[i] for i in by_order]
    chi2_all = np.asarray(chi2, dtype=float)[by_order]
    dof_all, nu = np.asarray(dof, dtype=int)[by_order], np.asarray(noise_dof, dtype=float)[by_order]
    dof_total = int(dof_all.sum())
    # Summed as identify sums them (Fit.chi2_total in XLA, its p-value in numpy), in the lot's order: the same bits.
    chi2_total = float(jnp.sum(jnp.asarray(chi2_all)))
    # Known sigmas: the lot's chi2 test, as identify's. An estimated noise: the F test against the pooled
    # noise degrees of freedom (identify's Monte Carlo null of the lot is not split by chunk).
    pooled = float(np.sum(nu)) if np.all(np.isfinite(nu)) else np.inf
    p_lot = float(chi2_p_value(np.asarray(chi2_all.sum()), np.asarray(dof_total), np.asarray(pooled)))
    statuses = [d["status"] for d in devices] + ["not converged"] * sum(len(f["devices"]) for f in failed)
    exit_status = next((EXIT_CODES[s] for s in EXIT_PRECEDENCE if s in statuses), 0)
    chi2_red = chi2_total / max(dof_total, 1)
    return {"source": plan.data, "chi2_red": chi2_red if devices and np.isfinite(chi2_red) else None,
            "p_value": p_lot if np.isfinite(p_lot) else None,
            "reject_alpha": alpha, "exit_status": exit_status, "devices": devices, "lot": {},
            "unidentifiable": unidentifiable, "unidentifiable_directions": directions,
            "compare": {"by_chunk": compare}, "failed": failed}


def _check_same_holds(plan: Plan, held: dict) -> None:
    """What the data cannot fix is decided from the stacked Jacobians of a fit's devices, so each chunk decides
    it for its own devices. Where no chunk holds anything, neither would one fit of the lot (the lot's mean normal
    matrix is the chunks' weighted mean: its smallest eigenvalue is at least their weighted mean, each above the
    threshold); where every chunk holds the same parameters, they are held for every device alike, as a
    homogeneous lot's structural directions are. Chunks that differ would make the fit depend on the chunking:
    refused."""
    kinds: dict[tuple, list[int]] = {}
    for k, names in held.items():
        kinds.setdefault(names, []).append(k)
    if len(kinds) <= 1:
        return
    union = sorted({n for names in kinds for n in names})
    listed = "; ".join(f"chunk{'s' if len(ks) > 1 else ''} {', '.join(map(str, ks[:4]))}{' ..' if len(ks) > 4 else ''}"
                       f" held {', '.join(names) or 'nothing'}" for names, ks in list(kinds.items())[:4])
    raise ValueError(f"{plan.folder}: the chunks held different parameters as unidentifiable ({listed}): which "
                     "parameters a lot's data cannot fix is decided from all the devices of a fit, so this lot's "
                     "fit would depend on how it is cut into chunks. Hold them for every device (identify_lot(..., "
                     f"hold={tuple(union)!r}), or gyrojax identify --free without them) in a new results folder, or "
                     "fit the lot on one process.")
