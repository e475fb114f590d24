"""Lots with two hidden effects at once: a library effect beside an effect outside the library, or two library
effects. A real device rarely has one missing effect; a diagnosis that finds a library effect only when it is
alone misses it there, and one that blames the library for the other effect's misfit confirms a wrong one.

Run: python experiments/two_effect_benchmark.py [--designs a,c] [--seeds 0-1] [--snr mid] [--out DIR]

Each lot is the discovery benchmark's lot (`experiments/_discovery_lot.py`, plain NumPy, its own closed forms) with
both effects' output changes added, each at its own size for the SNR level (the same noise and devices: the lots
of one seed differ only by the effects). Scores per pair kind (library + outside, library + library): library
effects found (confirmed, or declared ambiguous with the one confirmed), wrong confirmations (an effect confirmed
that is neither hidden nor declared ambiguous with a hidden one), the outside effect's sweeps located among the
misfit left, seconds per lot. DIR/two_effects.json and DIR/two_effects.md are rewritten atomically after every lot.
"""

import argparse
import datetime
import os
import sys
import time

import numpy as np


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from _discovery_lot import HIDDEN, discovery_lot  # noqa: E402
from discovery_benchmark import _git_describe, _parse_seeds, write_results  # noqa: E402


LIBRARY = ("zro_tempco", "feedback_compression", "vref_drift", "thermal_drift", "dac_inl_s_curve")
OUTSIDE = ("bias_step", "per_run_gain", "sign_gain_rate", "time_quadratic")
LIBRARY_PAIRS = (("zro_tempco", "feedback_compression"), ("vref_drift", "dac_inl_s_curve"))
PAIRS = tuple((a, b) for a in LIBRARY for b in OUTSIDE) + LIBRARY_PAIRS


def two_effect_lot(a: str, b: str, *, snr: str, design: str, seed: int):
    """The lot of `seed` with effects `a` and `b` both hidden (each at its own size for `snr`)."""
    import gyrojax as gj

    null, _ = discovery_lot(None, snr=snr, design=design, seed=seed)
    ta, _ = discovery_lot(a, snr=snr, design=design, seed=seed)
    tb, _ = discovery_lot(b, snr=snr, design=design, seed=seed)
    base = {k: np.asarray(v) for k, v in null.columns.items()}
    cols = {k: np.array(v) for k, v in ta.columns.items()}
    for column in ("output", "drive_freq_hz"):  # b's change on top of a's (a drive-frequency shift too)
        cols[column] = cols[column] + (np.asarray(tb.columns[column]) - base[column])
    return gj.Table.from_columns(cols, source=f"<two effects {a} + {b} {snr} design {design} seed {seed}>")


def score(diagnosis, a: str, b: str) -> dict:
    libs = {HIDDEN[x].library for x in (a, b)} - {None}
    ambiguous = {s.effect: set(s.ambiguous_with) for s in diagnosis.steps}
    named = set(diagnosis.selected) | {x for c in diagnosis.selected for x in ambiguous.get(c, ())}
    found = sum(lib in named for lib in libs)
    wrong = any(c not in libs and not (ambiguous.get(c, set()) & libs) for c in diagnosis.selected)
    outside = [x for x in (a, b) if HIDDEN[x].library is None]
    located = None
    if outside:
        want = set(HIDDEN[outside[0]].sweeps)
        located = any(set(d.located_on) & want for d in diagnosis.remaining) if hasattr(diagnosis, "remaining") \
            else None
    return {"libraries": len(libs), "found": found, "wrong": wrong, "outside_located": located}


def rows(records: list) -> list:
    out = []
    for kind in ("library + outside", "library + library"):
        rs = [r for r in records if r["kind"] == kind]
        if not rs:
            continue
        libs = sum(r["scores"]["libraries"] for r in rs)
        found = sum(r["scores"]["found"] for r in rs)
        wrong = sum(r["scores"]["wrong"] for r in rs)
        loc = [r["scores"]["outside_located"] for r in rs if r["scores"]["outside_located"] is not None]
        secs = float(np.median([r["seconds"] for r in rs]))
        out.append({"kind": kind, "lots": len(rs), "found": (found, libs), "wrong": (wrong, len(rs)),
                    "outside_located": (sum(loc), len(loc)), "seconds": secs})
    return out


def markdown(table: list) -> str:
    def cell(kn):
        k, n = kn
        return f"{k}/{n} ({100 * k / n:.0f} %)" if n else "-"
    lines = ["| pair | lots | library effects found | wrong confirmation | outside effect's sweeps located | s/lot |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['kind']} | {r['lots']} | {cell(r['found'])} | {cell(r['wrong'])} | "
              f"{cell(r['outside_located'])} | {r['seconds']:.1f} |" for r in table]
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--designs", default="a,c")
    p.add_argument("--seeds", default="0-1")
    p.add_argument("--snr", default="mid")
    p.add_argument("--preset", default="paper-qmg")
    p.add_argument("--out", default="two_effects_out")
    args = p.parse_args(argv)
    import gyrojax as gj

    os.makedirs(args.out, exist_ok=True)
    records = []
    lots = [(d, s, a, b) for d in args.designs.split(",") for s in _parse_seeds(args.seeds) for a, b in PAIRS]
    settings = {"designs": args.designs, "seeds": args.seeds, "snr": args.snr, "preset": args.preset,
                "gyrojax": gj.__version__, "commit": _git_describe(),
                "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
    for i, (design, seed, a, b) in enumerate(lots):
        table = two_effect_lot(a, b, snr=args.snr, design=design, seed=seed)
        t0 = time.perf_counter()
        d = gj.diagnose(args.preset, table, progress=False)
        seconds = time.perf_counter() - t0
        kind = "library + library" if HIDDEN[b].library is not None else "library + outside"
        sc = score(d, a, b)
        records.append({"design": design, "seed": seed, "effects": [a, b], "kind": kind, "selected": list(d.selected),
                        "verdict": d.verdict, "scores": sc, "seconds": seconds})
        print(f"[{i + 1}/{len(lots)}] design {design} seed {seed} {a} + {b}: selected {list(d.selected)} "
              f"{d.verdict}; {sc}; {seconds:.1f} s", flush=True)
        table_rows = rows(records)
        write_results(args.out, "two_effects", {"settings": settings, "rows": table_rows, "records": records},
                      markdown(table_rows))
    print(markdown(rows(records)))


if __name__ == "__main__":
    main()
