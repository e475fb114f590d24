"""`gyrojax simulate`: a lot of simulated sweeps written as a data file."""

import argparse

from .common import (
    EXIT_OK,
    check_finite_effects,
    check_outputs,
    device_and_free,
    effects_module_option,
    load_effects,
    model_arg,
    positive_int,
)


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


def handle(args):
    from .._data.files import table_format

    table_format(args.out, "--out")
    check_outputs(("--out", args.out, False))
    load_effects(args)

    import gyrojax as gj

    from .._data.files import write_table
    from .._lots.campaign import simulate_table

    tiers = {"steady": gj.CAMPAIGN_TIER, "averaged": gj.Averaged(), "full": gj.FullWaveform()}
    gyro, _ = device_and_free(args.preset)
    check_finite_effects(args.effect, gyro)
    for name, scale in args.effect:
        gyro = gj.add_effect(gyro, name, scale)
    table = simulate_table(gyro, devices=args.devices, runs=args.runs, sweeps=args.sweeps,
                           tier=tiers[args.tier], noise_free=args.noise_free, seed=args.seed,
                           protocol=gj.Protocol(order=args.order), progress=not args.quiet)
    write_table(table, args.out)
    print(f"wrote {len(table)} points ({args.devices} device(s) x {args.runs} run(s), sweeps "
          f"{', '.join(args.sweeps)}, tier {args.tier}) to {args.out}")
    return EXIT_OK


def add_parser(sub) -> None:
    """`gyrojax simulate`: a lot of simulated sweeps written as a data file."""
    from .._sweeps.registry import SWEEP_KINDS

    sim = sub.add_parser("simulate", help="simulate a lot of devices on rate-table, virtual-Coriolis and DAC sweeps",
                         description="Simulate sweeps of a preset device (or a lot around it) and write "
                                     "them in the tidy data format.")
    sim.add_argument("--preset", required=True, type=model_arg,
                     help="paper-qmg: seed 000's closed-loop QMG; vcf-2018: seed 003's open-loop gyro; or a "
                          "device file FILE.toml (docs/own_device.md)")
    sim.add_argument("--devices", type=positive_int("--devices"), default=1,
                     help="lot size (default 1: the nominal device)")
    sim.add_argument("--runs", type=positive_int("--runs"), default=1, help="repeated runs per device (default 1)")
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
    effects_module_option(sim)
    sim.set_defaults(func=handle)
