"""The `gyrojax` command line (docs/cli.md).

Exit codes:

- 0: success.
- 1: a computation failed (a point did not settle, a fit did not converge), or a number the data should give
  could not be determined (`metrics`, `compensate`: printed as "n/a" with the reason; the JSON holds null
  and the reason). Files written before the failure are complete.
- 2: a usage or data error (bad argument, unreadable or invalid file, an output path that cannot be written),
  reported without a traceback; output paths are checked before any data is read or any work is done.
- 3 (`identify`): fitted, but the model does not describe the data (its chi2 is too large for the noise, or a
  fitted parameter is implausible); the standard errors are also given scaled by sqrt(chi2_red).
- 4 (`identify`): the data do not determine the scale factor (it is printed as NaN, with the reason).
- 5 (`identify`): a fit file that predates these checks (status unknown).
  When devices differ, the worst status decides: not converged (1), not determined (4), unknown (5), model
  rejected (3). `diagnose` exits 0 whatever its verdict (explained, partly explained, unexplained: the
  diagnosis itself succeeded), 1 if its final fit did not converge.
- 128 + N: stopped by signal N (130 for SIGINT, 143 for SIGTERM). The first signal is turned into an
  exception, so the file being written is discarded (its temporary file removed) and the previous version is
  kept; it is acted on when the running computation returns to Python. The stop is also recorded and checked
  again between steps and before any output is moved into place (an exception raised by a signal handler is lost
  when the signal lands in a garbage-collector hook), so a stopped command never writes its outputs. The first
  signal restores the default handlers: a second signal kills the process at once (by that signal). Run as the
  program, a stopped command ends with `os._exit` after its cleanup (XLA's teardown at interpreter exit, in the
  middle of a compile, can crash).
"""

import argparse
import contextlib
import math
import os
import signal
import sys
import threading
import warnings

from . import _stop
from ._data.io import OutputPathError, atomic_directory, atomic_write_json, check_output_paths
from ._text import safe_name, safe_text


EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2
EXIT_SIGNAL_BASE = 128

_EXIT_CODES = """exit codes: 0 success; 1 a computation failed, or a number the data should give could not be
determined (printed as n/a with the reason); 2 a usage or data error (no traceback; output paths are checked
before any work); identify: 3 fitted but the model does not describe the data, 4 the scale factor is not
determined by the data, 5 a fit file without status; 128+N stopped by signal N (130 SIGINT, 143 SIGTERM; the file being
written is discarded, the previous one kept)."""


_Interrupted = _stop.Interrupted
_SIGNALS = (signal.SIGTERM, signal.SIGINT)


@contextlib.contextmanager
def _signals_raise():
    """Turn the first SIGTERM or SIGINT into `_Interrupted` for the block, restoring the old handlers after.

    The first signal records the stop (`gyrojax._stop`, checked again at safe points: its exception may be lost),
    raises, and restores the default handlers, so that a second signal kills the process whatever it is doing.
    An `_Interrupted` that Python could not raise (a signal in a garbage-collector hook) is not reported as an
    ignored exception: the safe points act on it.
    """
    if threading.current_thread() is not threading.main_thread():
        yield  # signal handlers can only be set from the main thread
        return

    def handler(signum, frame):
        for s in _SIGNALS:
            signal.signal(s, signal.SIG_DFL)
        _stop.request(signum)
        raise _Interrupted(signum)

    previous_hook = sys.unraisablehook

    def unraisable(hook_args):
        if not isinstance(hook_args.exc_value, _Interrupted):
            previous_hook(hook_args)

    previous = {s: signal.signal(s, handler) for s in _SIGNALS}
    sys.unraisablehook = unraisable
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        for s, h in previous.items():
            signal.signal(s, h)


def _names(table) -> tuple[str, ...]:
    """The device names of `table`, for `safe_text`: a name with a newline or an escape is shown escaped."""
    return tuple(dict.fromkeys(table["device"].tolist()))


def _na(value, spec: str, reason: str | None = None, unit: str = "") -> str:
    """`value` formatted with `spec` and followed by `unit`, or "n/a" (with the reason) when it is None."""
    if value is None:
        return "n/a" + (f" ({reason})" if reason else "")
    return format(value, spec) + unit


def _check_outputs(*outputs) -> None:
    """Check every output path of a command before any work: `(argument, path or None, folder)` triples."""
    check_output_paths(list(outputs))


def _load_effects(args) -> None:
    """Register the installed plugins' effects (entry points, once) and those of every --effects-module."""
    from ._plugins import load_effect_entry_points, load_effects_module

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_effect_entry_points()
        for path in getattr(args, "effects_module", None) or ():
            load_effects_module(path)
    for w in caught:
        print(f"gyrojax {args.command}: warning: {w.message}", file=sys.stderr)


def _check_finite_effects(effects, gyro) -> None:
    """Refuse, by name, an effect that gives `gyro` NaN or infinite parameters (a user effect's bug: without
    this it surfaces far away, as a failed SVD or an unsettled loop). `effects`: (name, scale) pairs."""
    from ._plugins import nonfinite_effect

    for name, scale in effects:
        why = nonfinite_effect(name, gyro, scale)
        if why is not None:
            raise RuntimeError(f"{why}; an effect must give finite parameters at every size (fix the effect).")


def _write_json(obj, path) -> None:
    try:
        atomic_write_json(obj, path)
    except ValueError as e:  # a NaN in a result: a computation that did not give a number, not a usage error
        raise RuntimeError(str(e)) from None


def _parse_effect(text):
    name, _, scale = text.partition("=")
    if not name:
        raise argparse.ArgumentTypeError(f"--effect expects NAME or NAME=SCALE, got {text!r}")
    try:
        return name, float(scale) if scale else 1.0
    except ValueError:
        raise argparse.ArgumentTypeError(f"--effect {text!r}: SCALE must be a number, got {scale!r}") from None


def _sweep_list(text):
    return tuple(s.strip() for s in text.split(",") if s.strip())


def _model_arg(text):
    """A --model (or simulate's --preset): a preset's name or the path of an existing device file (.toml)."""
    from ._device.file import is_device_file
    from ._presets import PRESETS

    if text in PRESETS:
        return text
    if is_device_file(text):
        if not os.path.isfile(text):
            raise argparse.ArgumentTypeError(f"no device file {text!r} (write one with gyrojax describe --model "
                                             "PRESET --toml FILE.toml)")
        return text
    raise argparse.ArgumentTypeError(f"expected a preset ({', '.join(sorted(PRESETS))}) or a device file FILE.toml, "
                                     f"got {text!r}")


def _device_and_free(model: str):
    """The device of a preset or device file, and the file's free parameters (() for a preset)."""
    from ._device.file import is_device_file, read_device_file
    from ._presets import preset

    if is_device_file(model):
        device_file = read_device_file(model)
        return device_file.device, device_file.free
    return preset(model), ()


def _cmd_simulate(args):
    from ._data.files import table_format

    table_format(args.out, "--out")
    _check_outputs(("--out", args.out, False))
    _load_effects(args)

    import gyrojax as gj

    from ._data.files import write_table
    from ._lots.campaign import simulate_table

    tiers = {"steady": gj.CAMPAIGN_TIER, "averaged": gj.Averaged(), "full": gj.FullWaveform()}
    gyro, _ = _device_and_free(args.preset)
    _check_finite_effects(args.effect, gyro)
    for name, scale in args.effect:
        gyro = gj.add_effect(gyro, name, scale)
    table = simulate_table(gyro, devices=args.devices, runs=args.runs, sweeps=args.sweeps,
                           tier=tiers[args.tier], noise_free=args.noise_free, seed=args.seed,
                           protocol=gj.Protocol(order=args.order), progress=not args.quiet)
    write_table(table, args.out)
    print(f"wrote {len(table)} points ({args.devices} device(s) x {args.runs} run(s), sweeps "
          f"{', '.join(args.sweeps)}, tier {args.tier}) to {args.out}")
    return EXIT_OK


def _cmd_metrics(args):
    from ._data.files import read_table
    from ._metrics import metrics_report
    from ._sweeps.registry import sweep_kind

    _check_outputs(("--json", args.json, False))
    report = metrics_report(read_table(args.data))
    undetermined = 0
    for p in report["points"]:
        why = p.get("not_applicable", {})
        head = f"{safe_name(p['device']):>16} run {p['run']:<3} {p['sweep']:<11}"
        kind = sweep_kind(p["sweep"])
        if not kind.straight_line:
            print(f"{head} bandwidth {_na(p.get('bandwidth_hz'), '.4g', why.get('bandwidth_hz'), ' Hz')}")
            continue
        if p["undetermined"]:  # a figure that applies to the kind but was not determined
            undetermined += 1
        unit = kind.scale_factor_unit
        sf = _na(p["scale_factor"], ".6g", why.get("scale_factor"), f" {unit}" if unit else "")
        if p["nonlinearity_max_ppm"] is None:
            print(f"{head} SF {sf}  NL n/a ({why.get('nonlinearity_max_ppm', 'not determined')})")
        else:
            print(f"{head} SF {sf}  NL max {p['nonlinearity_max_ppm']:.1f} ppm  "
                  f"rms {_na(p['nonlinearity_rms_ppm'], '.1f', why.get('nonlinearity_rms_ppm'), ' ppm')}")
    for d in report["devices"]:
        if d["n_runs"] > 1:
            rep = _na(d["repeatability_ppm"], ".2f", d.get("not_applicable", {}).get("repeatability_ppm"), " ppm")
            print(f"{safe_name(d['device']):>16} {d['sweep']:<11} repeatability {rep} over {d['n_runs']} runs")
    if args.json:
        _write_json(report, args.json)
        print(f"wrote {args.json}")
    if undetermined:
        print(f"gyrojax metrics: {undetermined} sweep(s) gave no nonlinearity (n/a above, null in the JSON)",
              file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _alpha(text):
    try:
        alpha = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--alpha expects a number in (0, 0.5], got {text!r}") from None
    if not 0 < alpha <= 0.5:  # also refuses nan
        raise argparse.ArgumentTypeError(f"--alpha is a significance level and must lie in (0, 0.5], got {text!r} "
                                         "(e.g. 0.01; alpha 5 would call every candidate significant)")
    return alpha


def _positive_int(option):
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} expects a whole number >= 1, got {text!r}") from None
        if value < 1:
            raise argparse.ArgumentTypeError(f"{option} expects a whole number >= 1, got {text!r}")
        return value
    return parse


def _run_list(text):
    try:
        runs = tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"--train-runs expects run ids like 0,1, got {text!r}") from None
    if not runs:
        raise argparse.ArgumentTypeError(f"--train-runs expects at least one run id, got {text!r}")
    return runs


def _compensation_na(run: dict, when: str) -> str:
    """Why a run's nonlinearity before/after compensation is None."""
    if when == "after" and run.get("converged") is False:
        return "the compensation did not converge for this device (see its message)"
    if run.get(f"scale_factor_{when}") == 0:
        return ("the outputs do not change with the input" if when == "before"
                else "the compensated rates do not change with the input")
    return "not determined"


def _cmd_compensate(args):
    from ._compensate.compensate import compensate
    from ._data.files import read_table

    _check_outputs(("--json", args.json, False))
    _load_effects(args)
    result = compensate(read_table(args.data), method=args.method, train_runs=args.train_runs,
                        progress=not args.quiet)
    undetermined = 0
    print(f"{'device':>16} {'run':>4} {'use':>8}  worst nonlinearity before -> after (ppm)")
    for r in result.runs:
        before, after = r["nonlinearity_max_ppm_before"], r["nonlinearity_max_ppm_after"]
        undetermined += before is None or after is None
        print(f"{safe_name(r['device']):>16} {r['run']:>4} {'train' if r['used_for_training'] else 'held-out':>8}  "
              f"{_na(before, '10.2f', _compensation_na(r, 'before'))} -> "
              f"{_na(after, '.2f', _compensation_na(r, 'after'))}")
    for d in result.devices:
        if d["n_runs"] < 2:
            continue
        before, after = d["repeatability_ppm_before"], d["repeatability_ppm_after"]
        print(f"{safe_name(d['device']):>16} repeatability over {d['n_runs']} runs: "
              f"{_na(before, '.2f', 'not determined', ' ppm')} -> {_na(after, '.2f', 'not determined', ' ppm')} "
              f"({args.method}, trained on runs "
              f"{', '.join(map(str, d['train_runs']))})")
    if args.json:
        _write_json(result.to_json(), args.json)
        print(f"wrote {args.json}")
    for d in result.devices:
        if d.get("converged") is False:
            print(f"gyrojax compensate: device {safe_name(d['device'])}: {safe_text(d['message'])}", file=sys.stderr)
    if undetermined:
        print(f"gyrojax compensate: {undetermined} run(s) gave no nonlinearity (n/a above)", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _table_and_fit(args):
    """The table of the command's data file and the fit of its --fit file (None without one), read after the
    effects are registered (a saved fit may hold a plugin's effect); the fit's warnings go to standard error."""
    from ._data.files import read_table

    _load_effects(args)
    table = read_table(args.data)
    fit = None
    if args.fit:
        from ._identify.fitio import load_fit

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fit = load_fit(args.fit)
        for w in caught:
            print(f"gyrojax {args.command}: warning: {w.message}", file=sys.stderr)
    return table, fit


def _escape_markdown(folder: str, names) -> None:
    """The report's Markdown pages with the data's unsafe device names escaped (see `safe_text`)."""
    for entry in sorted(os.listdir(folder)):
        if entry.endswith(".md"):
            path = os.path.join(folder, entry)
            with open(path, encoding="utf-8") as f:
                text = f.read()
            if safe_text(text, names) != text:
                with open(path, "w", encoding="utf-8") as f:
                    f.write(safe_text(text, names))


def _cmd_diagnose(args):
    from ._diagnose import diagnose, write_report

    if args.workers is not None or args.scheduler is not None:
        raise ValueError(f"{'--workers' if args.workers is not None else '--scheduler'}: a diagnosis is not run in "
                         "chunks of devices: which effect the lot's residuals show, its significance over every "
                         "description and candidate, and each step's fit are decided for the lot as a whole. Fit a "
                         "large lot with gyrojax identify --workers, and diagnose a sample of its devices (a few "
                         "hundred) in one process.")
    _check_outputs(("--json", args.json, False), ("--report", args.report, True),
                   ("--draft-effect", args.draft_effect, False))
    table, fit = _table_and_fit(args)
    diag = diagnose(args.model, table, alpha=args.alpha, fit=fit, progress=not args.quiet)
    names = _names(table)
    print(safe_text(diag.summary(), names))
    if args.report:
        with atomic_directory(args.report) as folder:  # the report folder appears whole or not at all
            write_report(diag, folder)
            _escape_markdown(folder, names)
        print(f"wrote report to {args.report}")
    if args.json:
        _write_json(diag.to_json(), args.json)
        print(f"wrote {args.json}")
    if args.draft_effect:
        from ._diagnose.draft import DraftError, write_draft

        if diag.formula is None:
            print("gyrojax diagnose: no draft written: no term of the dictionary is significant in what is left "
                  f"(verdict: {diag.verdict})", file=sys.stderr)
            return EXIT_FAILED
        try:
            write_draft(diag.formula, args.draft_effect, source=str(args.data))
        except DraftError as e:
            print(f"gyrojax diagnose: no draft written: {e}", file=sys.stderr)
            return EXIT_FAILED
        print(f"wrote {args.draft_effect}: {diag.formula.description}; load it with --effects-module")
    if "not converged" in diag.final.status:
        bad = [f"{safe_name(d)}: {m}" for d, m, st in zip(diag.final.devices, diag.final.result_message,
                                                            diag.final.status) if st == "not converged"]
        print(f"gyrojax diagnose: the final fit did not converge: {'; '.join(bad)}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _cmd_plan(args):
    from ._plan import plan

    _check_outputs(("--json", args.json, False))
    if args.rate_table_target is not None:
        return _cmd_rate_table_plan(args)
    if args.data is None:
        raise ValueError("give DATA (a data file), or --rate-table-target with --lot-spread or "
                         "--population-report")
    table, fit = _table_and_fit(args)
    result = plan(args.model, table, fit=fit, budget_min=args.budget_min, progress=not args.quiet)
    print(safe_text(result.summary(), _names(table)))
    if args.json:
        _write_json(result.to_json(), args.json)
        print(f"wrote {args.json}")
    return EXIT_OK


def _cmd_rate_table_plan(args):
    from ._plan.rate_table import lot_spread_from_report, rate_table_plan

    if args.data is not None:
        raise ValueError("--rate-table-target takes no DATA: the lot spread comes from --lot-spread or "
                         "--population-report")
    given = [o for o, v in (("--fit", args.fit), ("--budget-min", args.budget_min)) if v is not None]
    if given:
        raise ValueError(f"--rate-table-target plans the rate table from a lot spread alone; {', '.join(given)} "
                         "belong to the plan of DATA")
    if (args.lot_spread is None) == (args.population_report is None):
        raise ValueError("--rate-table-target needs exactly one of --lot-spread R or --population-report FILE")
    devices = args.devices
    if args.population_report is not None:
        spread, n, name = lot_spread_from_report(args.population_report, args.random)
        print(f"lot spread of {name} from {args.population_report}: {spread * 100:.3g} % ({n} devices)")
        devices = devices or n or 64
    else:
        spread = args.lot_spread
    result = rate_table_plan(spread, args.rate_table_target, devices=devices or 64, own=args.own)
    print(result.summary())
    if args.json:
        _write_json(result.report(), args.json)
        print(f"wrote {args.json}")
    return EXIT_OK


def _relative(text):
    """'0.2%' -> 0.002; '0.002' -> 0.002 (a relative number)."""
    t = text.strip()
    try:
        value = float(t[:-1]) / 100.0 if t.endswith("%") else float(t)
    except ValueError:
        value = float("nan")
    if not (value >= 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"expected a relative number such as 0.2% or 0.002, got {text!r}")
    return value


def _positive_minutes(text):
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"--budget-min expects minutes > 0, got {text!r}")
    return value


def _name_list(text):
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"--free expects parameter names like k_vf,vcf_gain, got {text!r}")
    return names


def _cmd_identify(args):
    from ._data.files import read_table
    from ._device.check import checked_start
    from ._diagnose.compare import compare
    from ._identify import PopulationFit, PopulationSolve, identify
    from ._identify.fitio import save_fit
    from ._identify.report import fit_report
    from ._model.parameters import DEFAULT_FREE, Model, zero_effect

    _check_outputs(("--json", args.json, False), ("--save", args.save, False))
    _load_effects(args)
    if args.workers is not None or args.scheduler is not None:
        return _identify_distributed(args)
    table = read_table(args.data)
    device, free = _device_and_free(args.model)
    device = checked_start(device, table, move=args.start_from_data, label="gyrojax identify")
    _check_finite_effects([(name, 1.0) for name in dict.fromkeys(args.effect)], device)
    model = Model(device, tuple(zero_effect(name) for name in args.effect))
    # --population: a population fit (random effects: the lot's mean and spread estimated with the devices).
    lot_solve = "vmap" if args.population is None else PopulationSolve(random=args.population or None)
    result = identify(model, table, free=args.free or free or DEFAULT_FREE, lot_solve=lot_solve)
    population = result if isinstance(result, PopulationFit) else None
    fit = result.fit if population is not None else result
    names = _names(table)
    print(safe_text(fit.summary(), names))
    print(safe_text(compare(fit).summary(), names))
    if population is not None:
        print(safe_text(population.summary(), names))
    if args.json:
        report = fit_report(fit)
        if population is not None:
            report["population"] = population.report()
        _write_json(report, args.json)
        print(f"wrote {args.json}")
    if args.save:
        save_fit(fit, args.save)
        print(f"wrote {args.save}")
    bad = [f"{safe_name(d)}: {st}" for d, st in zip(fit.devices, fit.status) if st != "ok"]
    if bad:
        print("gyrojax identify: " + "; ".join(bad) + " (see the warnings above; the files written say so too)",
              file=sys.stderr)
    if population is not None and not population.converged:
        print("gyrojax identify: the population fit did not converge (see its warnings)", file=sys.stderr)
        return population.exit_status
    return fit.exit_status


def _identify_distributed(args):
    """identify --workers/--scheduler: the lot in chunks of devices on Dask (gyrojax/_distributed), resumable
    from --json's results folder."""
    from ._distributed import DistributedSolve, identify_lot
    from ._model.parameters import DEFAULT_FREE, Model, zero_effect

    option = "--workers" if args.workers is not None else "--scheduler"
    refused = [(args.workers is not None and args.scheduler is not None, "--scheduler (give one of the two)"),
               (args.population is not None, "--population (a population fit couples the devices)"),
               (args.save, "--save (the merged result is --json's report; each chunk's is in its results folder)"),
               (args.start_from_data, "--start-from-data (it reads the whole file)")]
    for bad, what in refused:
        if bad:
            raise ValueError(f"{option} cannot be combined with {what}.")
    if not args.json:
        raise ValueError(f"{option} needs --json OUT.json: the merged report, with each chunk's result in "
                         "OUT.json.parts (a run started again with the same command continues from it).")
    device, free = _device_and_free(args.model)
    _check_finite_effects([(name, 1.0) for name in dict.fromkeys(args.effect)], device)
    model = Model(device, tuple(zero_effect(name) for name in args.effect))
    try:
        strategy = DistributedSolve(workers=args.workers, scheduler=args.scheduler, chunk=args.chunk)
        report = identify_lot(model, args.data, args.json, strategy, free=args.free or free or DEFAULT_FREE)
    except ImportError as e:
        raise ValueError(str(e)) from None
    counts = {}
    for d in report["devices"]:
        counts[d["status"]] = counts.get(d["status"], 0) + 1
    n_failed = sum(len(f["devices"]) for f in report["failed"])
    print(f"{len(report['devices']) + n_failed} device(s): " + ", ".join(f"{k} {st}" for st, k in counts.items())
          + f", {n_failed} failed")
    for f in report["failed"]:
        print(safe_text(f"  chunk {f['chunk']} ({len(f['devices'])} devices, {f['devices'][0]} ..): FAILED: "
                        f"{f['error']}: {f['message']}", f["devices"]), file=sys.stderr)
    print(f"wrote {args.json} (each chunk's result in {args.json}.parts)")
    return EXIT_FAILED if n_failed and report["exit_status"] == 0 else report["exit_status"]


def _cmd_demo(args):
    from ._demo import run_demo

    _check_outputs(("--out", args.out, True))
    where = os.path.abspath(args.out)  # said in full: the default is a folder in the current one
    with atomic_directory(args.out) as folder:  # the demo folder appears whole or not at all
        run_demo(folder, full_tier=args.full and not args.no_full, progress=not args.quiet,
                 log=lambda m: print(m.replace(folder, where), flush=True))
    return EXIT_OK


def _cmd_describe(args):
    from ._describe import describe, describe_text

    _check_outputs(("--json", args.json, False), ("--toml", args.toml, False))
    records = describe(args.model)
    print(describe_text(records))
    if args.json:
        _write_json([r.to_json() for r in records], args.json)
        print(f"wrote {args.json}")
    if args.toml:
        from ._describe import write_toml

        write_toml(args.model, args.toml)
        print(f"wrote {args.toml}: edit it and give it back as --model {args.toml}")
    return EXIT_OK


def _effects_module_option(parser):
    parser.add_argument("--effects-module", action="append", default=[], metavar="FILE.py",
                        help="import this Python file and register every gyrojax.AbstractEffect subclass it "
                             "defines, for --effect and the diagnosis (repeatable); installed packages' effects "
                             "(entry-point group gyrojax.effects) are loaded too")


def build_parser():
    parser = argparse.ArgumentParser(
        prog="gyrojax", epilog=_EXIT_CODES,
        description="Differentiable simulation and identification of MEMS Coriolis vibratory gyroscopes. "
                    "Data files are the tidy table of docs/data_format.md (CSV or Parquet): rates in deg/s, "
                    "gyro outputs in LSB, DAC amplitudes in V.")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_simulate(sub)
    _add_metrics(sub)
    _add_compensate(sub)
    _add_diagnose(sub)
    _add_plan(sub)
    _add_identify(sub)
    _add_demo(sub)
    _add_describe(sub)
    return parser


def _add_simulate(sub) -> None:
    """`gyrojax simulate`: a lot of simulated sweeps written as a data file."""
    from ._sweeps.registry import SWEEP_KINDS

    sim = sub.add_parser("simulate", help="simulate a lot of devices on rate-table, virtual-Coriolis and DAC sweeps",
                         description="Simulate sweeps of a preset device (or a lot around it) and write "
                                     "them in the tidy data format.")
    sim.add_argument("--preset", required=True, type=_model_arg,
                     help="paper-qmg: seed 000's closed-loop QMG; vcf-2018: seed 003's open-loop gyro; or a "
                          "device file FILE.toml (docs/own_device.md)")
    sim.add_argument("--devices", type=_positive_int("--devices"), default=1,
                     help="lot size (default 1: the nominal device)")
    sim.add_argument("--runs", type=_positive_int("--runs"), default=1, help="repeated runs per device (default 1)")
    sim.add_argument("--sweeps", type=_sweep_list, default=("rate_table",),
                     help=f"comma-separated, any of {', '.join(SWEEP_KINDS)} (default rate_table); "
                          "each with its default settings (seed 000 §5's rate table, seed 003's virtual-Coriolis "
                          "tests), see gyrojax.Protocol and the sweep kinds")
    sim.add_argument("--tier", choices=("steady", "averaged", "full"), default="steady",
                     help="simulation tier for settled points (default steady; full is the slow ground truth)")
    sim.add_argument("--effect", type=_parse_effect, action="append", default=[], metavar="NAME[=SCALE]",
                     help="add a physical effect at its typical size times SCALE (repeatable); e.g. dac_inl=2")
    sim.add_argument("--noise-free", action="store_true", help="no measurement noise, no turn-on bias")
    sim.add_argument("--quiet", action="store_true", help="no progress messages (on standard error)")
    sim.add_argument("--order", choices=("listed", "reversed", "alternating", "shuffled"), default="listed",
                     help="the order the points of each run are applied in: listed (ascending, default), reversed, "
                          "alternating (up in even runs, down in odd ones) or shuffled; an input swept one way ties it "
                          "to time and temperature (drift looks like a shape in the input)")
    sim.add_argument("--seed", type=int, default=0, help="PRNG seed for the lot and the noise (default 0)")
    sim.add_argument("--out", required=True, help="output file, .csv or .parquet")
    _effects_module_option(sim)
    sim.set_defaults(func=_cmd_simulate)


def _add_metrics(sub) -> None:
    """`gyrojax metrics`: the scale-factor metrics of a data file."""
    met = sub.add_parser("metrics", help="scale factor, nonlinearity, asymmetry, repeatability of a data file",
                         description="Scale-factor metrics of every device/run/sweep of a data file.")
    met.add_argument("data", help="a tidy data file (.csv or .parquet)")
    met.add_argument("--json", help="write the report as JSON here")
    met.set_defaults(func=_cmd_metrics)


def _add_compensate(sub) -> None:
    """`gyrojax compensate`: a scale-factor compensator fitted and judged."""
    comp = sub.add_parser("compensate", help="fit a scale-factor compensator on training runs, judge it on the rest",
                          description="Compensate the rate_table sweeps of a data file: fit on the training runs "
                                      "of each device, report the worst nonlinearity of every run and the "
                                      "repeatability before and after (seed 000's metrics).")
    comp.add_argument("data", help="a tidy data file (.csv or .parquet) with rate_table rows")
    comp.add_argument("--method", choices=("polynomial", "composite", "model"), default="composite",
                      help="polynomial: seed 000's traditional baseline; composite: seed 000's method (needs "
                           "drive_freq_hz); model: invert the identified physical model (needs drive_freq_hz). "
                           "Default composite")
    comp.add_argument("--train-runs", type=_run_list, default=None, metavar="LIST",
                      help="comma-separated run ids to fit on, e.g. 0,1 (default: each device's first run)")
    comp.add_argument("--json", help="write the report as JSON here")
    comp.add_argument("--quiet", action="store_true", help="no progress messages (on standard error)")
    _effects_module_option(comp)
    comp.set_defaults(func=_cmd_compensate)


def _add_diagnose(sub) -> None:
    """`gyrojax diagnose`: the missing effect found and added."""
    diag = sub.add_parser("diagnose", help="compare model and data, find the missing physical effect, add it",
                          description="Fit the preset's baseline (per device: its gains free, a bias per run), "
                                      "rank every candidate effect by a score test, add the significant ones one "
                                      "at a time (likelihood-ratio confirmed) and report the error falling.")
    diag.add_argument("data", help="a tidy data file (.csv or .parquet): rate_table, vcf_static, vcf_dynamic, dac")
    diag.add_argument("--model", type=_model_arg, default="paper-qmg",
                      help="baseline device: a preset or a device file FILE.toml (default paper-qmg)")
    diag.add_argument("--alpha", type=_alpha, default=0.01,
                      help="family-wise significance per step, in (0, 0.5] (default 0.01)")
    diag.add_argument("--json", help="write the diagnosis as JSON here (keys in docs/diagnosis.md)")
    diag.add_argument("--report", metavar="DIR",
                      help="write a Markdown report with PNG plots into the folder DIR (new, empty, or written by "
                           "gyrojax before: it is replaced as a whole)")
    diag.add_argument("--fit", metavar="FIT", help="a fit of this data saved by `gyrojax identify --save`: the "
                                                  "baseline, instead of fitting it again (its preset replaces --model)")
    diag.add_argument("--draft-effect", metavar="FILE.py",
                      help="write the proposed missing term (the diagnosis's formula) as an effect module here, "
                           "ready for --effects-module")
    diag.add_argument("--quiet", action="store_true", help="no progress messages (on standard error)")
    diag.add_argument("--workers", type=_positive_int("--workers"), default=None, metavar="N",
                      help="refused, with the reason: a diagnosis decides for the lot as a whole (see identify "
                           "--workers)")
    diag.add_argument("--scheduler", default=None, metavar="ADDRESS", help="refused, as --workers")
    _effects_module_option(diag)
    diag.set_defaults(func=_cmd_diagnose)


def _add_plan(sub) -> None:
    """`gyrojax plan`: the measurements that make each effect testable."""
    pln = sub.add_parser("plan", help="which measurements would make each hidden effect testable; the scale "
                                      "factor's best calibration within a time budget",
                         description="From the baseline fit of DATA (fitted here as diagnose does, or --fit), the "
                                     "expected chi2 and power that each candidate effect at its typical size "
                                     "would give with each available experiment added, the cheapest set of runs "
                                     "that makes it testable (power 0.9 at alpha 0.01), and the rates, runs and "
                                     "VCF points that minimise the scale factor's standard error within "
                                     "--budget-min, against seed 000's 22-rate protocol at equal time. No refits.")
    pln.add_argument("data", nargs="?", help="a tidy data file (.csv or .parquet): the measurements made so far "
                                             "(not with --rate-table-target)")
    pln.add_argument("--model", type=_model_arg, default="paper-qmg",
                     help="baseline device: a preset or a device file FILE.toml (default paper-qmg)")
    pln.add_argument("--fit", metavar="FIT", help="a fit of this data saved by `gyrojax identify --save`: the "
                                                 "baseline, instead of fitting it here (its preset replaces --model)")
    pln.add_argument("--budget-min", type=_positive_minutes, default=None, metavar="M",
                     help="test time for the scale factor's design, minutes (default 135: three runs of seed "
                          "000's protocol; at least one run, 45 min)")
    pln.add_argument("--json", help="write the plan as JSON here (keys in docs/planning.md)")
    pln.add_argument("--quiet", action="store_true", help="no progress messages (on standard error)")
    rt = pln.add_argument_group("how many devices to rate-table (the rest predicted by a population fit; no DATA)")
    rt.add_argument("--rate-table-target", type=_relative, metavar="R",
                    help="wanted 95 %% half-width of the predicted devices' scale factors, e.g. 0.2%% or 0.002")
    rt.add_argument("--lot-spread", type=_relative, metavar="R", help="the lot's relative spread of what only the "
                                                                      "rate table sees, e.g. 0.5%%")
    rt.add_argument("--population-report", metavar="FILE", help="or that spread from `gyrojax identify DATA "
                                                                "--population NAME --json FILE`")
    rt.add_argument("--random", metavar="NAME", help="which random parameter of the report (if several)")
    rt.add_argument("--devices", type=int, default=None, metavar="N", help="lot size (default: the report's, else 64)")
    rt.add_argument("--own", type=_relative, default=0.0, metavar="R",
                    help="a predicted device's own relative uncertainty from its other sweeps (default 0)")
    _effects_module_option(pln)
    pln.set_defaults(func=_cmd_plan)


def _add_identify(sub) -> None:
    """`gyrojax identify`: the model's parameters fitted to a data file."""
    idf = sub.add_parser("identify", help="fit the model's physical parameters to every sweep of a data file",
                         description="Fit the free parameters of a preset (plus any effects) to all sweeps of "
                                     "every device jointly, with standard errors; parameters the data cannot "
                                     "fix are named and held. Exit 1 if a fit does not converge.")
    idf.add_argument("data", help="a tidy data file (.csv or .parquet)")
    idf.add_argument("--model", type=_model_arg, default="paper-qmg",
                     help="the device the fit starts from: a preset or a device file FILE.toml (default paper-qmg; "
                          "the file's free = true parameters are freed unless --free is given)")
    idf.add_argument("--free", type=_name_list, default=None, metavar="LIST",
                     help="comma-separated names of gyrojax.PARAMETERS to fit per device (default: "
                          "k_vf,sense_gain,vcf_gain,dac_gain_error,omega_y,q_y, those the device has)")
    idf.add_argument("--effect", action="append", default=[], metavar="NAME",
                     help="add an effect (from zero) and fit its parameters too (repeatable), e.g. dac_inl")
    idf.add_argument("--population", type=_name_list, nargs="?", const=(), default=None, metavar="LIST",
                     help="a population fit: these per-device parameters (comma-separated; without a list, every one "
                          "the fit leaves free) are random effects whose lot mean and spread are estimated with "
                          "them; each device is shrunk toward the lot, a device missing sweeps gets a prediction "
                          "interval (docs/population.md; the JSON gets a 'population' section)")
    idf.add_argument("--json", help="write the report (keys in docs/cli.md) as JSON here")
    idf.add_argument("--save", metavar="FIT", help="save the fit here (read back with gyrojax.load_fit)")
    idf.add_argument("--start-from-data", action="store_true",
                     help="before the fit, move the device's drive resonance, DAC full scale and scale-factor gain "
                          "to what the data read directly (the PLL's drive_freq_hz, the DAC sweep's slope, the rate "
                          "table's slope) where the device is far from them (the check runs and warns without it)")
    idf.add_argument("--workers", type=_positive_int("--workers"), default=None, metavar="N",
                     help="fit the lot in chunks of devices on a local Dask cluster of N worker processes (needs "
                          "gyrojax[distributed] and --json; resumable: the same command continues a killed run)")
    idf.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="as --workers, on an existing Dask cluster (tcp://host:8786)")
    idf.add_argument("--chunk", type=_positive_int("--chunk"), default=16, metavar="C",
                     help="devices per chunk with --workers/--scheduler (default 16)")
    _effects_module_option(idf)
    idf.set_defaults(func=_cmd_identify)


def _add_demo(sub) -> None:
    """`gyrojax demo`: the main job on the embedded default data."""
    demo = sub.add_parser("demo", help="the main job on the embedded default data (seed 000 Table 2, presets)",
                          description="Simulate a lot with a hidden effect and find it (fit, rank candidates, "
                                      "add, watch the error fall); reproduce seed 000 Table 2's DAC "
                                      "nonlinearity; compare the tiers on paper-qmg with a DAC INL; compare "
                                      "vcf-2018's bandwidth with seed 003. Writes report.md, summary.json, "
                                      "plots and a diagnosis/ report. A few minutes on a 2-core CPU.")
    demo.add_argument("--out", default="gyrojax-demo",
                      help="output folder (default ./gyrojax-demo): new, empty, or written by gyrojax before (it is "
                           "replaced as a whole)")
    demo.add_argument("--full", action="store_true",
                      help="also run the (slow, ~1 min) full-waveform tier in the three-tier comparison")
    demo.add_argument("--no-full", action="store_true", help="skip the full-waveform tier (the default)")
    demo.add_argument("--quiet", action="store_true", help="only the steps and their results, no progress messages")
    demo.set_defaults(func=_cmd_demo)


def _add_describe(sub) -> None:
    """`gyrojax describe`: every leaf of a device."""
    desc = sub.add_parser("describe", help="every leaf of a device (a preset or a device file): its path, value, "
                                           "unit and provenance; --toml writes it as a device file",
                          description="List every leaf of the device (the path an effect reads or writes, e.g. "
                                      "vcf_electrode.force_per_volt2), with its value, unit, description and where "
                                      "the preset (or the device file) took it from (docs/adding_an_effect.md); "
                                      "--toml writes it as a device file to edit (docs/own_device.md).")
    desc.add_argument("--model", type=_model_arg, default="paper-qmg",
                      help="the preset or device file FILE.toml to describe (default paper-qmg)")
    desc.add_argument("--json", help="write the records (path, value, unit, description, provenance) as JSON here")
    desc.add_argument("--toml", metavar="OUT.toml",
                      help="write the device as a device file here, to edit and give back as --model OUT.toml "
                           "(docs/own_device.md)")
    desc.set_defaults(func=_cmd_describe)


def _os_error_text(e: OSError) -> str:
    if e.filename is None:
        return str(e)
    text = f"{e.filename}: {e.strerror or e}"
    return text + (f" (moving it to {e.filename2})" if e.filename2 is not None else "")


def main(argv=None):
    """Run the command line; returns the exit code (see the module notes)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse has printed the usage error (or the help)
        return e.code if isinstance(e.code, int) else EXIT_USAGE
    from ._data.cells import DataError

    name = f"gyrojax {args.command}"
    try:
        with _signals_raise():
            try:
                code = args.func(args)
                _stop.check()  # a stop whose exception was lost after the last safe point
                return code
            except BaseException as e:
                # After a stop, whatever the exception (ours, or one a library made of it), the signal decides.
                signum = e.signum if isinstance(e, _Interrupted) else _stop.requested()
                if signum is None:
                    raise
                print(f"{name}: stopped by {signal.Signals(signum).name}; the file being written (if any) was "
                      "discarded and its previous version kept", file=sys.stderr)
                if argv is None:  # run as the program: no interpreter teardown in XLA's state after a stop
                    sys.stdout.flush()
                    sys.stderr.flush()
                    os._exit(EXIT_SIGNAL_BASE + signum)
                return EXIT_SIGNAL_BASE + signum
            finally:
                _stop.clear()
    except KeyboardInterrupt:  # outside the main thread, where no handler could be set
        print(f"{name}: interrupted", file=sys.stderr)
        return EXIT_SIGNAL_BASE + signal.SIGINT
    except (DataError, OutputPathError, ValueError) as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError, FileExistsError) as e:
        print(f"{name}: error: {_os_error_text(e)}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as e:  # the disk is full, an I/O error: nothing the arguments could fix
        print(f"{name}: failed: {_os_error_text(e)}", file=sys.stderr)
        return EXIT_FAILED
    except RuntimeError as e:
        print(f"{name}: failed: {e}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
