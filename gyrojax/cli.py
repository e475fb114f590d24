"""The `gyrojax` command line (DESIGN.md §7).

Exit codes: 0 success; 1 a computation failed (a point did not settle, a fit did not converge);
2 a usage or data error (bad argument, unreadable or invalid file) - reported without a traceback.
"""

import argparse
import sys

from ._io import atomic_write_json

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


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


def _cmd_simulate(args):
    import gyrojax as gj

    from ._campaign import simulate_table
    from ._dataset import write_table

    tiers = {"steady": gj.CAMPAIGN_TIER, "averaged": gj.Averaged(), "full": gj.FullWaveform()}
    gyro = gj.preset(args.preset)
    for name, scale in args.effect:
        gyro = gj.add_effect(gyro, name, scale)
    table = simulate_table(gyro, devices=args.devices, runs=args.runs, sweeps=args.sweeps,
                           tier=tiers[args.tier], noise_free=args.noise_free, seed=args.seed)
    write_table(table, args.out)
    print(f"wrote {len(table)} points ({args.devices} device(s) x {args.runs} run(s), sweeps "
          f"{', '.join(args.sweeps)}, tier {args.tier}) to {args.out}")
    return EXIT_OK


def _cmd_metrics(args):
    from ._dataset import read_table
    from ._metrics import metrics_report

    report = metrics_report(read_table(args.data))
    for p in report["points"]:
        if p.get("scale_factor") is None:
            continue
        print(f"{p['device']:>16} run {p['run']:<3} {p['sweep']:<11} SF {p['scale_factor']:.6g}  "
              f"NL max {p['nonlinearity_max_ppm']:.1f} ppm  rms {p['nonlinearity_rms_ppm']:.1f} ppm")
    for d in report["devices"]:
        if d.get("repeatability_ppm") is not None:
            print(f"{d['device']:>16} {d['sweep']:<11} repeatability {d['repeatability_ppm']:.2f} ppm "
                  f"over {d['n_runs']} runs")
    if args.json:
        atomic_write_json(report, args.json)
        print(f"wrote {args.json}")
    return EXIT_OK


def _run_list(text):
    try:
        runs = tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"--train-runs expects run ids like 0,1, got {text!r}") from None
    if not runs:
        raise argparse.ArgumentTypeError(f"--train-runs expects at least one run id, got {text!r}")
    return runs


def _cmd_compensate(args):
    from ._compensate.compensate import compensate
    from ._dataset import read_table

    result = compensate(read_table(args.data), method=args.method, train_runs=args.train_runs)
    print(f"{'device':>16} {'run':>4} {'use':>8}  worst nonlinearity before -> after (ppm)")
    for r in result.runs:
        print(f"{r['device']:>16} {r['run']:>4} {'train' if r['used_for_training'] else 'held-out':>8}  "
              f"{r['nonlinearity_max_ppm_before']:10.2f} -> {r['nonlinearity_max_ppm_after']:.2f}")
    for d in result.devices:
        before, after = d["repeatability_ppm_before"], d["repeatability_ppm_after"]
        if before is not None:
            print(f"{d['device']:>16} repeatability over {d['n_runs']} runs: {before:.2f} -> {after:.2f} ppm "
                  f"({args.method}, trained on runs {', '.join(map(str, d['train_runs']))})")
    if args.json:
        atomic_write_json(result.to_json(), args.json)
        print(f"wrote {args.json}")
    return EXIT_OK


def _cmd_diagnose(args):
    from ._dataset import read_table
    from ._diagnose import diagnose, write_report

    table = read_table(args.data)
    diag = diagnose(table, args.model, alpha=args.alpha, progress=lambda m: print(f"... {m}", flush=True))
    print(diag.summary())
    if args.report:
        write_report(diag, args.report)
        print(f"wrote report to {args.report}")
    if args.json:
        atomic_write_json(diag.to_json(), args.json)
        print(f"wrote {args.json}")
    if not diag.final.all_converged:
        print(f"gyrojax diagnose: the final fit did not converge: {diag.final.result_message}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _name_list(text):
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"--free expects parameter names like k_vf,vcf_gain, got {text!r}")
    return names


def _cmd_identify(args):
    from ._compare import compare
    from ._dataset import read_table
    from ._fitio import save_fit
    from ._fitreport import fit_report
    from ._identify import identify
    from ._parameters import DEFAULT_FREE, Model, zero_effect
    from ._presets import preset

    table = read_table(args.data)
    model = Model(preset(args.model), tuple(zero_effect(name) for name in args.effect))
    fit = identify(model, table, free=args.free or DEFAULT_FREE)
    print(fit.summary())
    print(compare(fit).summary())
    if args.json:
        atomic_write_json(fit_report(fit), args.json)
        print(f"wrote {args.json}")
    if args.save:
        save_fit(fit, args.save)
        print(f"wrote {args.save}")
    fit.check()  # a RuntimeError naming the devices and what to try: exit 1
    return EXIT_OK


def _cmd_demo(args):
    from ._demo import run_demo

    run_demo(args.out, full_tier=args.full and not args.no_full)
    return EXIT_OK


def build_parser():
    from ._presets import PRESETS

    parser = argparse.ArgumentParser(
        prog="gyrojax",
        description="Differentiable simulation and identification of MEMS Coriolis vibratory gyroscopes. "
                    "Data files are the tidy table of DESIGN.md §6 (CSV or Parquet): rates in deg/s, "
                    "gyro outputs in LSB, DAC amplitudes in V.")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="simulate a lot of devices on rate-table, virtual-Coriolis and DAC sweeps",
                         description="Simulate sweeps of a preset device (or a lot around it) and write "
                                     "them in the tidy data format.")
    sim.add_argument("--preset", required=True, choices=sorted(PRESETS),
                     help="paper-qmg: seed 000's closed-loop QMG; vcf-2018: seed 003's open-loop gyro")
    sim.add_argument("--devices", type=int, default=1, help="lot size (default 1: the nominal device)")
    sim.add_argument("--runs", type=int, default=1, help="repeated runs per device (default 1)")
    sim.add_argument("--sweeps", type=_sweep_list, default=("rate_table",),
                     help="comma-separated, any of rate_table, vcf_static, vcf_dynamic, dac (default rate_table); "
                          "the protocols are seed 000 §5's rate table and seed 003's virtual-Coriolis tests, see "
                          "gyrojax.Protocol")
    sim.add_argument("--tier", choices=("steady", "averaged", "full"), default="steady",
                     help="simulation tier for settled points (default steady; full is the slow ground truth)")
    sim.add_argument("--effect", type=_parse_effect, action="append", default=[], metavar="NAME[=SCALE]",
                     help="add a physical effect at its typical size times SCALE (repeatable); e.g. dac_inl=2")
    sim.add_argument("--noise-free", action="store_true", help="no measurement noise, no turn-on bias")
    sim.add_argument("--seed", type=int, default=0, help="PRNG seed for the lot and the noise (default 0)")
    sim.add_argument("--out", required=True, help="output file, .csv or .parquet")
    sim.set_defaults(func=_cmd_simulate)

    met = sub.add_parser("metrics", help="scale factor, nonlinearity, asymmetry, repeatability of a data file",
                         description="Scale-factor metrics of every device/run/sweep of a data file.")
    met.add_argument("data", help="a tidy data file (.csv or .parquet)")
    met.add_argument("--json", help="write the report as JSON here")
    met.set_defaults(func=_cmd_metrics)

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
    comp.set_defaults(func=_cmd_compensate)

    diag = sub.add_parser("diagnose", help="compare model and data, find the missing physical effect, add it",
                          description="Fit the preset's baseline (per device: its gains free, a bias per run), "
                                      "rank every candidate effect by a score test, add the significant ones one "
                                      "at a time (likelihood-ratio confirmed) and report the error falling.")
    diag.add_argument("data", help="a tidy data file (.csv or .parquet): rate_table, vcf_static, vcf_dynamic, dac")
    diag.add_argument("--model", choices=sorted(PRESETS), default="paper-qmg",
                      help="baseline device preset (default paper-qmg)")
    diag.add_argument("--alpha", type=float, default=0.01,
                      help="family-wise significance per step (default 0.01)")
    diag.add_argument("--json", help="write the diagnosis as JSON here (DESIGN.md §7 keys)")
    diag.add_argument("--report", metavar="DIR", help="write a Markdown report with PNG plots into DIR")
    diag.set_defaults(func=_cmd_diagnose)

    idf = sub.add_parser("identify", help="fit the model's physical parameters to every sweep of a data file",
                         description="Fit the free parameters of a preset (plus any effects) to all sweeps of "
                                     "every device jointly, with standard errors; parameters the data cannot "
                                     "fix are named and held. Exit 1 if a fit does not converge.")
    idf.add_argument("data", help="a tidy data file (.csv or .parquet)")
    idf.add_argument("--model", choices=sorted(PRESETS), default="paper-qmg",
                     help="the preset the fit starts from (default paper-qmg)")
    idf.add_argument("--free", type=_name_list, default=None, metavar="LIST",
                     help="comma-separated names of gyrojax.PARAMETERS to fit per device (default: "
                          "k_vf,sense_gain,vcf_gain,dac_gain_error,omega_y,q_y, those the device has)")
    idf.add_argument("--effect", action="append", default=[], metavar="NAME",
                     help="add an effect (from zero) and fit its parameters too (repeatable), e.g. dac_inl")
    idf.add_argument("--json", help="write the report (DESIGN.md §7 identify keys) as JSON here")
    idf.add_argument("--save", metavar="FIT", help="save the fit here (read back with gyrojax.load_fit)")
    idf.set_defaults(func=_cmd_identify)

    demo = sub.add_parser("demo", help="the main job on the embedded default data (seed 000 Table 2, presets)",
                          description="Simulate a lot with a hidden effect and find it (fit, rank candidates, "
                                      "add, watch the error fall); reproduce seed 000 Table 2's DAC "
                                      "nonlinearity; compare the tiers on paper-qmg with a DAC INL; compare "
                                      "vcf-2018's bandwidth with seed 003. Writes report.md, summary.json, "
                                      "plots and a diagnosis/ report. A few minutes on a 2-core CPU.")
    demo.add_argument("--out", default="gyrojax-demo", help="output folder (default ./gyrojax-demo)")
    demo.add_argument("--full", action="store_true",
                      help="also run the (slow, ~1 min) full-waveform tier in the three-tier comparison")
    demo.add_argument("--no-full", action="store_true", help="skip the full-waveform tier (the default)")
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError, IsADirectoryError, PermissionError) as e:
        print(f"gyrojax {args.command}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except RuntimeError as e:
        print(f"gyrojax {args.command}: failed: {e}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
