"""`gyrojax metrics`: the scale-factor metrics of a data file."""

import sys

from .._text import safe_name
from .common import EXIT_FAILED, EXIT_OK, check_outputs, na, write_json


def handle(args):
    from .._data.files import read_table
    from .._metrics import metrics_report
    from .._sweeps.registry import sweep_kind

    check_outputs(("--json", args.json, False))
    report = metrics_report(read_table(args.data))
    undetermined = 0
    for p in report["points"]:
        why = p.get("not_applicable", {})
        head = f"{safe_name(p['device']):>16} run {p['run']:<3} {p['sweep']:<11}"
        kind = sweep_kind(p["sweep"])
        if not kind.straight_line:
            print(f"{head} bandwidth {na(p.get('bandwidth_hz'), '.4g', why.get('bandwidth_hz'), ' Hz')}")
            continue
        if p["undetermined"]:  # a figure that applies to the kind but was not determined
            undetermined += 1
        unit = kind.scale_factor_unit
        sf = na(p["scale_factor"], ".6g", why.get("scale_factor"), f" {unit}" if unit else "")
        if p["nonlinearity_max_ppm"] is None:
            print(f"{head} SF {sf}  NL n/a ({why.get('nonlinearity_max_ppm', 'not determined')})")
        else:
            print(f"{head} SF {sf}  NL max {p['nonlinearity_max_ppm']:.1f} ppm  "
                  f"rms {na(p['nonlinearity_rms_ppm'], '.1f', why.get('nonlinearity_rms_ppm'), ' ppm')}")
    for d in report["devices"]:
        if d["n_runs"] > 1:
            rep = na(d["repeatability_ppm"], ".2f", d.get("not_applicable", {}).get("repeatability_ppm"), " ppm")
            print(f"{safe_name(d['device']):>16} {d['sweep']:<11} repeatability {rep} over {d['n_runs']} runs")
    if args.json:
        write_json(report, args.json)
        print(f"wrote {args.json}")
    if undetermined:
        print(f"gyrojax metrics: {undetermined} sweep(s) gave no nonlinearity (n/a above, null in the JSON)",
              file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def add_parser(sub) -> None:
    """`gyrojax metrics`: the scale-factor metrics of a data file."""
    met = sub.add_parser("metrics", help="scale factor, nonlinearity, asymmetry, repeatability of a data file",
                         description="Scale-factor metrics of every device/run/sweep of a data file.")
    met.add_argument("data", help="a tidy data file (.csv or .parquet)")
    met.add_argument("--json", help="write the report as JSON here")
    met.set_defaults(func=handle)
