"""`gyrojax demo`: the main job on the embedded default data."""

import os

from .._data.io import atomic_directory
from .common import EXIT_OK, check_outputs


def handle(args):
    from .demo_job import run_demo

    check_outputs(("--out", args.out, True))
    where = os.path.abspath(args.out)  # said in full: the default is a folder in the current one
    with atomic_directory(args.out) as folder:  # the demo folder appears whole or not at all
        run_demo(folder, full_tier=args.full and not args.no_full, progress=not args.quiet,
                 log=lambda m: print(m.replace(folder, where), flush=True))
    return EXIT_OK


def add_parser(sub) -> None:
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
    demo.set_defaults(func=handle)
