"""`gyrojax plan`: the measurements that make each effect testable, the scale factor's design, and how many
devices to rate-table (`--rate-table-target`)."""

import argparse
import math

from .._text import safe_text
from .common import (
    EXIT_OK,
    check_result_outputs,
    device_names,
    effects_module_option,
    model_arg,
    result_options,
    table_and_fit,
    write_result_files,
)


def handle(args):
    from .._plan import plan

    check_result_outputs(args)
    if args.rate_table_target is not None:
        return _cmd_rate_table_plan(args)
    if args.data is None:
        raise ValueError("give DATA (a data file), or --rate-table-target with --lot-spread or "
                         "--population-report")
    table, fit = table_and_fit(args)
    result = plan(args.model, table, fit=fit, budget_min=args.budget_min, progress=not args.quiet)
    print(safe_text(result.summary(), device_names(table)))
    write_result_files(args, result)
    return EXIT_OK


def _cmd_rate_table_plan(args):
    from .._plan.rate_table import lot_spread_from_report, rate_table_plan

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
    write_result_files(args, result)
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


def add_parser(sub) -> None:
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
    pln.add_argument("--model", type=model_arg, default="paper-qmg",
                     help="baseline device: a preset or a device file FILE.toml (default paper-qmg)")
    pln.add_argument("--fit", metavar="FIT", help="a fit of this data saved by `gyrojax identify --save`: the "
                                                 "baseline, instead of fitting it here (its preset replaces --model)")
    pln.add_argument("--budget-min", type=_positive_minutes, default=None, metavar="M",
                     help="test time for the scale factor's design, minutes (default 135: three runs of seed "
                          "000's protocol; at least one run, 45 min)")
    pln.add_argument("--json", help="write the plan as JSON here (keys in docs/planning.md)")
    result_options(pln, "plan")
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
    effects_module_option(pln)
    pln.set_defaults(func=handle)
