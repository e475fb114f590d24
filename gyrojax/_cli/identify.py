"""`gyrojax identify`: the model's parameters fitted to a data file, in one process or in chunks on Dask."""

import argparse
import sys

from .._text import safe_name, safe_text
from .common import (
    EXIT_FAILED,
    check_finite_effects,
    check_result_outputs,
    device_and_free,
    device_names,
    effects_module_option,
    load_effects,
    model_arg,
    positive_int,
    result_options,
    write_result_files,
)


def _name_list(text):
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"--free expects parameter names like k_vf,vcf_gain, got {text!r}")
    return names


def handle(args):
    from .._data.files import read_table
    from .._device.check import checked_start
    from .._identify import PopulationFit, PopulationSolve, identify
    from .._identify.fitio import save_fit
    from .._identify.report import IdentifyReport
    from .._model.parameters import Model, zero_effect

    check_result_outputs(args, ("--save", args.save, False))
    load_effects(args)
    if args.workers is not None or args.scheduler is not None:
        return _identify_distributed(args)
    table = read_table(args.data)
    device, free = device_and_free(args.model)
    device = checked_start(device, table, move=args.start_from_data, label="gyrojax identify")
    check_finite_effects([(name, 1.0) for name in dict.fromkeys(args.effect)], device)
    model = Model(device, tuple(zero_effect(name) for name in args.effect))
    # --population: a population fit (random effects: the lot's mean and spread estimated with the devices).
    lot_solve = "vmap" if args.population is None else PopulationSolve(random=args.population or None)
    result = identify(model, table, free=args.free or free or None, lot_solve=lot_solve)
    population, fit = (result, result.fit) if isinstance(result, PopulationFit) else (None, result)
    report = IdentifyReport(fit=fit, population=population)
    print(safe_text(report.summary(), device_names(table)))
    write_result_files(args, report)
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
    from .._distributed import DistributedSolve, identify_lot
    from .._model.parameters import Model, zero_effect

    option = "--workers" if args.workers is not None else "--scheduler"
    refused = [(args.workers is not None and args.scheduler is not None, "--scheduler (give one of the two)"),
               (args.population is not None, "--population (a population fit couples the devices)"),
               (args.save, "--save (the merged result is --json's report; each chunk's is in its results folder)"),
               (args.out, "--out (the merged result is --json's report)"),
               (args.start_from_data, "--start-from-data (it reads the whole file)")]
    for bad, what in refused:
        if bad:
            raise ValueError(f"{option} cannot be combined with {what}.")
    if not args.json:
        raise ValueError(f"{option} needs --json OUT.json: the merged report, with each chunk's result in "
                         "OUT.json.parts (a run started again with the same command continues from it).")
    device, free = device_and_free(args.model)
    check_finite_effects([(name, 1.0) for name in dict.fromkeys(args.effect)], device)
    model = Model(device, tuple(zero_effect(name) for name in args.effect))
    try:
        strategy = DistributedSolve(workers=args.workers, scheduler=args.scheduler, chunk=args.chunk)
        report = identify_lot(model, args.data, args.json, strategy, free=args.free or free or None)
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


def add_parser(sub) -> None:
    """`gyrojax identify`: the model's parameters fitted to a data file."""
    idf = sub.add_parser("identify", help="fit the model's physical parameters to every sweep of a data file",
                         description="Fit the free parameters of a preset (plus any effects) to all sweeps of "
                                     "every device jointly, with standard errors; parameters the data cannot "
                                     "fix are named and held. Exit 1 if a fit does not converge.")
    idf.add_argument("data", help="a tidy data file (.csv or .parquet)")
    idf.add_argument("--model", type=model_arg, default="paper-qmg",
                     help="the device the fit starts from: a preset or a device file FILE.toml (default paper-qmg; "
                          "the file's free = true parameters are freed unless --free is given)")
    idf.add_argument("--free", type=_name_list, default=None, metavar="LIST",
                     help="comma-separated names of gyrojax.PARAMETERS to fit per device (default: "
                          "k_vf,sense_gain,vcf_gain,dac_gain_error,omega_y,q_y, those the device has, and what "
                          "the data's sweeps read: omega_x with drive_frequency, angular_gain with vcf_dynamic)")
    idf.add_argument("--effect", action="append", default=[], metavar="NAME",
                     help="add an effect (from zero) and fit its parameters too (repeatable), e.g. dac_inl")
    idf.add_argument("--population", type=_name_list, nargs="?", const=(), default=None, metavar="LIST",
                     help="a population fit: these per-device parameters (comma-separated; without a list, every one "
                          "the fit leaves free) are random effects whose lot mean and spread are estimated with "
                          "them; each device is shrunk toward the lot, a device missing sweeps gets a prediction "
                          "interval (docs/population.md; the JSON gets a 'population' section)")
    idf.add_argument("--json", help="write the report (keys in docs/cli.md) as JSON here")
    result_options(idf, "report")
    idf.add_argument("--save", metavar="FIT", help="save the fit here (read back with gyrojax.load_fit)")
    idf.add_argument("--start-from-data", action="store_true",
                     help="before the fit, move the device's drive resonance, DAC full scale and scale-factor gain "
                          "to what the data read directly (the PLL's drive_freq_hz, the DAC sweep's slope, the rate "
                          "table's slope) where the device is far from them (the check runs and warns without it)")
    idf.add_argument("--workers", type=positive_int("--workers"), default=None, metavar="N",
                     help="fit the lot in chunks of devices on a local Dask cluster of N worker processes (needs "
                          "gyrojax[distributed] and --json; resumable: the same command continues a killed run)")
    idf.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="as --workers, on an existing Dask cluster (tcp://host:8786)")
    idf.add_argument("--chunk", type=positive_int("--chunk"), default=16, metavar="C",
                     help="devices per chunk with --workers/--scheduler (default 16)")
    effects_module_option(idf)
    idf.set_defaults(func=handle)
