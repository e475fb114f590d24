"""`gyrojax metrics`: the scale-factor metrics of a data file."""

import sys

from .common import EXIT_FAILED, EXIT_OK, check_result_outputs, result_options, write_result_files


def handle(args):
    from .._data.files import read_table
    from .._metrics import metrics_report

    check_result_outputs(args)
    report = metrics_report(read_table(args.data))
    text = report.summary()  # device names escaped by the report
    if text:
        print(text)
    write_result_files(args, report)
    undetermined = report.undetermined()  # a figure that applies to the kind but was not determined
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
    result_options(met, "report")
    met.set_defaults(func=handle)
