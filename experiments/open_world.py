"""Effects outside the library: the out-of-library confusion table of `diagnose`.

Run: python experiments/open_world.py [--out DIR] [--cases NAME,...] [--devices 3] [--runs 2] [--seed 7]

A plain paper-qmg lot (`gyrojax.simulate_table`, the demo's campaign: rate table + static VCF + DAC, noise on)
is post-processed by hand, outside gyrojax's model, with an effect a real device may have. The diagnosis then
runs from the plain preset:

1. **outside**: with a candidate library that does not hold the effect (for `zro` and `amp`: the library
   without `zro_tempco` and `feedback_compression`, i.e. as it was before they were added; for the others:
   the full library). It must confirm nothing that is absent, end `unexplained` (or `partly explained`), and
   name the coordinate and shape of the misfit, with the size of the term;
2. **with it**: the effect added to the candidates, from the library (`zro`, `amp`) or from the user's own
   module file (`time`: a zero-rate output drifting with time since power-on, `experiments/user_effects.py`,
   written in one file as `docs/adding_an_effect.md` shows). It must be found with chi2_red in [0.7, 1.4] and its size
   within 3 sigma of the truth on every device.

Cases (`--cases`): `zro` (a zero-rate output linear in the die temperature, 2e-3 (deg/s)/K on the rate and VCF
rows), `amp` (a cubic compression of the feedback amplifier after the DAC: rate and VCF words raised by
3e-4 (w/W)^3 W, the DAC sweep untouched: ~3.7 sigma apart from a DAC INL on this DAC sweep, which reaches a
third of full scale), `amp_small` (the same at 1e-4, ~1.2 sigma apart: the data cannot refuse the DAC INL, and
the diagnosis must name the cubic after the DAC as its look-alike; outside only), `time` (a zero-rate output
growing 0.05 (deg/s)/h after power-on),
`sign` (a gain 20 ppm higher for positive inputs: K+ != K-, which no library effect and no slot term here
models; only located). Results go to DIR/open_world.json and .md after every case.
"""

import argparse
import os
import sys
import time

import numpy as np

import gyrojax as gj


TRUTH = {"zro": 2e-3, "amp": 3e-4, "amp_small": 1e-4, "time": 0.05, "sign": 20e-6}
NEW = ("zro_tempco", "feedback_compression")
W = 2.0**23  # paper-qmg's full-scale rebalance word

USER_EFFECTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "user_effects.py")
"""The user's own module defining `zro_time_drift` (loaded as `--effects-module` would)."""


def post_process(table, case):
    """`table` with the case's effect added to its outputs by hand (not by gyrojax's model)."""
    cols = table.columns
    rows = np.isin(cols["sweep"], ["rate_table", "vcf_static"])
    sf = np.zeros(len(table))
    for d in np.unique(cols["device"]):
        m = (cols["sweep"] == "rate_table") & (cols["device"] == d) & (cols["run"] == 0)
        sf[cols["device"] == d] = np.polyfit(cols["input"][m], cols["output"][m], 1)[0]
    out = np.array(cols["output"], dtype=float)
    x = TRUTH[case]
    if case == "zro":
        out[rows] += x * sf[rows] * (cols["temperature_c"][rows] - 25.0)
    elif case in ("amp", "amp_small"):
        out[rows] += x * out[rows] ** 3 / W**2
    elif case == "time":
        out[rows] += x * sf[rows] * cols["time_s"][rows] / 3600.0
    elif case == "sign":
        out[rows] *= np.where(cols["input"][rows] > 0, 1.0 + x, 1.0)
    cols["output"] = out
    return gj.Table(cols, source=f"<demo lot + {case}, post-processed>")


def _library_without(case):
    everything = gj.supported_effects(gj.paper_qmg())
    return tuple(c for c in everything if c not in NEW) if case in ("zro", "amp", "amp_small") else everything


# The library effect, its parameter and the true value in its own units, for the "with it" half.
FOUND_AS = {"zro": ("zro_tempco", TRUTH["zro"] * gj.units.DEG),
            "amp": ("feedback_compression", TRUTH["amp"] / 0.75),  # fundamental compression 3c/4 (w/W)^2
            "time": ("zro_time_drift", TRUTH["time"] * gj.units.DEG)}


def _sizes(d, effect, truth):
    fit = d.final
    name = next((n for n in fit.names if n.startswith(effect + ".")), None)
    if name is None or effect not in d.selected:
        return None
    value = np.asarray(fit.value(name))
    err = np.asarray(fit.stderr)[:, fit.names.index(name)]
    return {"value": value.tolist(), "stderr": err.tolist(), "truth": truth,
            "z": ((value - truth) / err).tolist()}


def row(case, half, d, seconds, spurious_of=()):
    top = d.remaining[0] if d.remaining else None
    r = {"case": case, "half": half, "selected": list(d.selected), "verdict": d.verdict,
         "baseline_chi2_red": d.baseline.chi2_red_total, "final_chi2_red": d.final.chi2_red_total,
         "rejected": [{"effect": x.effect, "kind": x.kind} for x in d.rejected], "seconds": seconds,
         "wrongly_confirmed": [s for s in d.selected if s in spurious_of],
         "look_alikes": [{"effect": s.effect, "probe": a.probe, "separation_sigma": a.separation_sigma,
                          "sweep": a.sweeps[0][0] if a.sweeps else None, "information_factor": a.information_factor}
                         for s in d.steps for a in s.look_alikes]}
    if top is not None:
        r["top"] = {"coordinate": top.coordinate, "shape": top.shape, "share": top.share,
                    "coefficient": top.coefficient, "unit": top.unit, "same_shape_as": list(top.same_shape_as),
                    "library": top.library, "description": top.description}
    return r


def markdown(rows, settings) -> str:
    lines = ["# Effects outside the library: out-of-library confusion table", "",
             f"paper-qmg lot of {settings['devices']} devices x {settings['runs']} runs, seed {settings['seed']}, "
             "rate table + static VCF + DAC, noise on; outputs post-processed by hand with the hidden effect.", "",
             "| hidden | candidates | selected | wrongly confirmed | look-alike named | verdict | "
             "where the misfit lives (top) | chi2_red before -> after | size z (per device) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        top = r.get("top")
        where = (f"{top['coordinate']}: {top['shape']}, {100 * top['share']:.0f} %, "
                 f"{top['coefficient']:.3g} {top['unit']}" if top else "-")
        z = ", ".join(f"{v:+.2f}" for v in r["size"]["z"]) if r.get("size") else "-"
        alike = "; ".join(f"{a['effect']} ~ {a['probe']} ({a['separation_sigma']:.2g} sigma apart, on {a['sweep']}: "
                          f"~{a['information_factor']:.2g}x its information to separate)"
                          for a in r.get("look_alikes", ())) or "-"
        lines.append(f"| {r['case']} ({TRUTH[r['case']]:g}) | {r['half']} | {', '.join(r['selected']) or '-'} | "
                     f"{', '.join(r['wrongly_confirmed']) or 'none'} | {alike} | {r['verdict']} | {where} | "
                     f"{r['baseline_chi2_red']:.3g} -> {r['final_chi2_red']:.3f} | {z} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="folder for open_world.json and .md (written after every case)")
    ap.add_argument("--cases", default="zro,amp,amp_small,time,sign",
                    help="comma-separated subset of zro, amp, amp_small, time, sign")
    ap.add_argument("--devices", type=int, default=3)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args(argv)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    for c in cases:
        if c not in TRUTH:
            raise SystemExit(f"--cases: unknown case {c!r}; expected some of {', '.join(TRUTH)}.")
    settings = {"devices": args.devices, "runs": args.runs, "seed": args.seed}
    if args.out:
        os.makedirs(args.out, exist_ok=True)
    clean = gj.simulate_table(gj.paper_qmg(), devices=args.devices, runs=args.runs,
                              sweeps=("rate_table", "vcf_static", "dac"), seed=args.seed)
    rows = []

    def record(r):
        rows.append(r)
        top = r.get("top", {})
        print(f"{r['case']:<5} {r['half']:<8} selected {', '.join(r['selected']) or '-':<22} {r['verdict']:<17} "
              f"{top.get('coordinate', '-'):<14} {100 * top.get('share', 0.0):4.0f} %  chi2_red "
              f"{r['baseline_chi2_red']:.3g} -> {r['final_chi2_red']:.3f}  ({r['seconds']:.0f} s)", flush=True)
        if args.out:
            out = {"settings": settings, "rows": rows, "versions": {"gyrojax": gj.__version__}}
            gj.io.atomic_write_json(out, os.path.join(args.out, "open_world.json"))
            gj.io.atomic_write_bytes(os.path.join(args.out, "open_world.md"), markdown(rows, settings).encode())

    for case in cases:
        table = post_process(clean, case)
        t = time.perf_counter()
        absent = _library_without(case)
        d = gj.diagnose("paper-qmg", table, candidates=absent)
        record(row(case, "outside", d, time.perf_counter() - t, spurious_of=absent))
        if case not in FOUND_AS:
            continue
        effect, truth = FOUND_AS[case]
        if case == "time":
            gj.load_effects_module(USER_EFFECTS)
        try:
            t = time.perf_counter()
            d = gj.diagnose("paper-qmg", table)
            r = row(case, "with it", d, time.perf_counter() - t,
                    spurious_of=[c for c in gj.supported_effects(gj.paper_qmg()) if c != effect])
            r["size"] = _sizes(d, effect, truth)
            record(r)
        finally:
            gj.EFFECTS.pop("zro_time_drift", None)
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() is not None else 1)
