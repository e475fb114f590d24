"""The discovery benchmark on the new user's protocol: lots made by `gyrojax simulate`, hidden effects added by hand.

Run: python experiments/simulate_protocol_benchmark.py [--protocols 0-4] [--effects all] [--chi2 300]
     [--without-sigma] [--out DIR]

The other discovery sets (`discovery_benchmark.py`) share one generator and its chamber cycles. A lab's first lot
is more likely what `gyrojax simulate` writes: a die warming after each power-on, the rates listed in one
direction (input, time and temperature confounded), or a chamber stepped through plateaus, any number of devices
and runs. Here each protocol's clean lot is simulated once (`gyrojax.simulate_table` from `paper-qmg`, noise on),
and each hidden effect is written onto its outputs in plain NumPy (closed forms of the table's own columns; no
gyrojax physics), scaled so that its chi2 beyond a turn-on bias per (device, run, sweep) and a gain per (device,
sweep) is `--chi2` over the lot (300: the discovery benchmark's middle SNR). Library effects are simulated with
`gyrojax.add_effect` at their typical size instead (these lots are gyrojax's own model: they measure whether the
effect is found on this protocol, not the model's blind spots). Null lots are the clean lots.

Scored as the discovery benchmark scores (`discovery_benchmark.score`): library found, wrong confirmation (any
confirmation for an outside effect or a null lot), localised (the located sweeps and coordinate), localised or
named as confounded, formula (one of the declared canonical terms), null explained. DIR/simulate_protocol.json and
.md are rewritten atomically after every lot.
"""

import argparse
import dataclasses
import datetime
import math
import os
import sys
import time
from collections.abc import Callable

import numpy as np


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from discovery_benchmark import (  # noqa: E402
    GyrojaxMethod,
    _git_describe,
    _parse_seeds,
    markdown,
    score,
    score_rows,
    write_results,
)


RV = ("rate_table", "vcf_static")
RVD = RV + ("dac",)

PROTOCOLS = (
    # the demo's campaign: rates listed upward while the die warms after power-on
    {"devices": 3, "runs": 2, "sweeps": RVD, "order": "listed", "plateaus": None},
    {"devices": 4, "runs": 2, "sweeps": RVD, "order": "alternating", "plateaus": None},
    {"devices": 6, "runs": 2, "sweeps": RVD, "order": "shuffled", "plateaus": None},
    {"devices": 3, "runs": 3, "sweeps": RV, "order": "listed", "plateaus": None},
    # a chamber stepped 15 -> 35 C within each power-on (the rates twice per run)
    {"devices": 4, "runs": 2, "sweeps": RVD, "order": "shuffled", "plateaus": (15.0, 35.0)},
)
"""Each protocol's clean lot is simulated with seed = its index + 11."""

LIBRARY = ("dac_inl", "feedback_compression", "zro_tempco")
"""Library effects simulated at their typical size (`gyrojax.add_effect`)."""
LIBRARY_COORDINATE = {"dac_inl": "input", "feedback_compression": "input", "zro_tempco": "temperature_c"}


@dataclasses.dataclass(frozen=True)
class Hand:
    """A hidden effect written by hand: `fn(c)` the output change per row at unit size from the table's columns
    `c` (a dict of arrays plus `sf`, each row's device's rate scale factor in LSB/(deg/s)); `sweeps` the kinds it
    changes, `coordinate` the recorded column it varies with, `formula` canonical dictionary terms expressing it
    (None: no simple term)."""

    name: str
    sweeps: tuple
    coordinate: str
    formula: tuple | None
    fn: Callable
    description: str


def _on(c, *sweeps):
    return np.isin(c["sweep"], sweeps).astype(float)


def _fs(c):
    """Each row's input over its sweep's largest |input|."""
    x = np.asarray(c["input"], dtype=float)
    out = np.zeros_like(x)
    for s in np.unique(c["sweep"]):
        m = c["sweep"] == s
        out[m] = x[m] / np.max(np.abs(x[m]))
    return out


def _device_index(c):
    return np.unique(c["device"], return_inverse=True)[1]


def _run_blocks(c, sweeps):
    """Row indices of each (device, run, sweep) of `sweeps`, in time order."""
    for d in np.unique(c["device"]):
        for r in np.unique(c["run"]):
            for s in sweeps:
                i = np.flatnonzero((c["device"] == d) & (c["run"] == r) & (c["sweep"] == s))
                if i.size:
                    yield i[np.argsort(c["time_s"][i])]


def _telegraph(c):
    """Two-level bias switching (a charge trap near the sense electrode): in every (device, run) the bias flips
    between 0 and 1 at two times drawn per power-on (shared by the rate and VCF sessions' clocks)."""
    rng = np.random.default_rng(5)
    out = np.zeros(len(c["output"]))
    t = np.asarray(c["time_s"], dtype=float)
    tmax = np.nanmax(t)
    for d in np.unique(c["device"]):
        for r in np.unique(c["run"]):
            on, off = np.sort(rng.uniform(0.15, 0.85, 2)) * tmax
            m = (c["device"] == d) & (c["run"] == r) & np.isin(c["sweep"], RV)
            out[m] = ((t[m] >= on) & (t[m] < off)).astype(float)
    return c["sf"] * out


def _soft_dead_band(c):
    """A lock-in near zero rate (sense-mode coupling at rest): the rate output loses exp(-(rate / 1 deg/s)^2) of
    itself."""
    x = np.asarray(c["input"], dtype=float)
    return -c["output"] * np.exp(-(x / 1.0) ** 2) * _on(c, "rate_table")


def _one_device_gain_drift(c):
    """One device's gain drifts in time since power-on (a leaking getter in its package): the last device's rate
    and VCF gain 1 + t / 1 h."""
    last = _device_index(c) == _device_index(c).max()
    return c["output"] * (np.nan_to_num(c["time_s"]) / 3600.0) * last * _on(c, *RV)


def _dac_range_switch(c):
    """The DAC's output stage switches range at a quarter of full scale: words beyond it read a gain 1 + g on the
    excess (an odd hinge)."""
    s = _fs(c)
    excess = np.sign(s) * np.maximum(np.abs(s) - 0.25, 0.0)
    return np.abs(c["output"]).max() * excess * _on(c, "dac") / np.max(np.abs(excess) + 1e-300)


HAND = (
    Hand("vcf_gain_tempco_only", ("vcf_static",), "temperature_c", ("lin(temperature_c)*model",),
         lambda c: c["output"] * (np.nan_to_num(c["temperature_c"]) - 25.0) * _on(c, "vcf_static"),
         "the VCF electrode's gap expands with the die: its gain 1 + c (T - 25 C), rate table untouched"),
    Hand("bias_warmup_relax", RV, "time_s", ("relax(time_s)",),
         lambda c: c["sf"] * np.exp(-np.nan_to_num(c["time_s"]) / 600.0) * _on(c, *RV),
         "a bias settling after power-on, exp(-t / 10 min), rate and VCF"),
    Hand("vcf_gain_positive_only", ("vcf_static",), "input", ("sign(input)*model", "step(input)*model", "abs(input)"),
         lambda c: c["output"] * (np.asarray(c["input"]) > 0) * _on(c, "vcf_static"),
         "the VCF's positive-polarity relay path has its own gain: 1 + c for V > 0"),
    Hand("rate_quintic", ("rate_table",), "input", None,
         lambda c: c["output"] * _fs(c) ** 4 * _on(c, "rate_table"),
         "a quintic of the sense pick-off at high rates: the rate output (1 + c (rate / FS)^4)"),
    Hand("bias_telegraph", RV, "time_s", None, _telegraph,
         "a two-level bias switching twice per power-on (a charge trap), rate and VCF"),
    Hand("one_device_gain_drift", RV, "time_s", ("lin(time_s)*model",), _one_device_gain_drift,
         "one device's gain drifting linearly after power-on, rate and VCF"),
    Hand("dac_even_bow", ("dac",), "input", ("sq(input)", "abs(input)"),
         lambda c: np.abs(c["output"]).max() * _fs(c) ** 2 * _on(c, "dac"),
         "an even bow of the DAC bench (its rectifying detector): + c (w / W)^2"),
    Hand("rate_bias_sq", ("rate_table",), "input", ("sq(input)",),
         lambda c: c["sf"] * _fs(c) ** 2 * _on(c, "rate_table"),
         "a bias growing with the rate squared (the table's centripetal acceleration on the die)"),
    Hand("gain_step_run1", RV, "time_s", None,
         lambda c: c["output"] * ((np.asarray(c["run"]) == 1)
                                  & (np.nan_to_num(c["time_s"]) > 0.5 * np.nanmax(c["time_s"]))) * _on(c, *RV),
         "a supply switching half-way through run 1 of every device: the gain steps by c, rate and VCF"),
    Hand("soft_dead_band", ("rate_table",), "input", None, _soft_dead_band,
         "a soft lock-in near zero rate: the output loses exp(-(rate / 1 deg/s)^2) of itself"),
    Hand("gain_periodic_time", RV, "time_s", ("periodic(time_s)*model",),
         lambda c: c["output"] * np.sin(2 * np.pi * np.nan_to_num(c["time_s"]) / 900.0) * _on(c, *RV),
         "the lab's air conditioning cycling every 15 min on the reference: a gain sin(2 pi t / 15 min)"),
    Hand("dac_range_switch", ("dac",), "input", ("hinge(input)",), _dac_range_switch,
         "the DAC's output stage switches range at a quarter of full scale: an odd hinge of the DAC bench"),
)
HAND_BY_NAME = {h.name: h for h in HAND}


def _scale_factor_per_row(c):
    """Each row's device's rate-table scale factor (least-squares slope of its rate rows), LSB/(deg/s)."""
    sf = np.zeros(len(c["output"]))
    for d in np.unique(c["device"]):
        m = (c["device"] == d) & (c["sweep"] == "rate_table")
        sf[c["device"] == d] = np.polyfit(np.asarray(c["input"])[m], np.asarray(c["output"])[m], 1)[0]
    return sf


def beyond_baseline(c, delta):
    """Per sweep, the chi2 of `delta` / sigma beyond a turn-on bias per (device, run) (sweeps with a time axis) and
    a gain per device (the output): what the baseline's free biases and gains cannot take up."""
    z = delta / np.asarray(c["output_sigma"], dtype=float)
    chi2 = {}
    for s in np.unique(c["sweep"]):
        total = 0.0
        for d in np.unique(c["device"]):
            m = (c["sweep"] == s) & (c["device"] == d)
            cols = [np.asarray(c["output"], dtype=float)[m] / np.asarray(c["output_sigma"], dtype=float)[m]]
            if np.isfinite(np.asarray(c["time_s"], dtype=float)[m]).any():
                cols += [(np.asarray(c["run"])[m] == r) / np.asarray(c["output_sigma"], dtype=float)[m]
                         for r in np.unique(np.asarray(c["run"])[m])]
            a = np.stack(cols, axis=1)
            coef = np.linalg.lstsq(a, z[m], rcond=None)[0]
            total += float(np.sum((z[m] - a @ coef) ** 2))
        chi2[str(s)] = total
    return chi2


def hidden_lot(clean, hand: Hand, target_chi2: float):
    """`clean` with `hand` written onto its outputs at the size whose chi2 beyond the baseline is `target_chi2`,
    and the answer the scores read."""
    import gyrojax as gj

    c = {k: np.asarray(v) for k, v in clean.columns.items()}
    c["sf"] = _scale_factor_per_row(c)
    unit = np.asarray(hand.fn(c), dtype=float)
    per_sweep = beyond_baseline(c, unit)
    total = sum(per_sweep.values())
    raw = float(np.sum((unit / np.asarray(c["output_sigma"], dtype=float)) ** 2))
    if not total > 1e-9 * raw:  # what is left is rounding: the baseline takes the effect whole
        raise ValueError(f"{hand.name}: leaves no chi2 beyond the baseline on this protocol")
    size = math.sqrt(target_chi2 / total)
    cols = dict(clean.columns)
    cols["output"] = np.asarray(clean.columns["output"], dtype=float) + size * unit
    info = {"hidden": hand.name, "class": "outside", "library": None, "coordinate": hand.coordinate,
            "formula": None if hand.formula is None else list(hand.formula), **_visible(per_sweep), "size": size}
    return gj.Table(cols, source=f"<simulated lot + {hand.name}, post-processed>"), info


def library_lot(index: int, name: str, clean):
    """Protocol `index`'s lot with the library effect `name` at its typical size, and the answer the scores read
    (its sweep shares from the change against the `clean` lot of the same seed)."""
    table = clean_lot(index, name)
    c = {k: np.asarray(v) for k, v in table.columns.items()}
    per_sweep = beyond_baseline(c, c["output"] - np.asarray(clean.columns["output"], dtype=float))
    return table, {"hidden": name, "class": "library", "library": name, "coordinate": LIBRARY_COORDINATE[name],
                   "formula": None, **_visible(per_sweep)}


def _visible(per_sweep: dict) -> dict:
    """Each sweep's share of an effect's chi2 beyond the baseline (those >= 1 %), and the sweeps carrying >= 20 %
    (the discovery benchmark's `sweep_shares` and `visible_sweeps`)."""
    total = sum(per_sweep.values()) or 1.0
    shares = {s: v / total for s, v in per_sweep.items() if v / total >= 0.01}
    return {"sweep_shares": shares, "visible_sweeps": sorted(s for s, v in shares.items() if v >= 0.2)}


def clean_lot(index: int, effect: str | None = None):
    """Protocol `index`'s lot from `paper-qmg` (with a library `effect` at its typical size)."""
    import gyrojax as gj

    p = PROTOCOLS[index]
    gyro = gj.paper_qmg() if effect is None else gj.add_effect(gj.paper_qmg(), effect)
    protocol = gj.Protocol(order=p["order"], chamber_plateaus_c=p["plateaus"])
    return gj.simulate_table(gyro, devices=p["devices"], runs=p["runs"], sweeps=p["sweeps"], seed=11 + index,
                             protocol=protocol, progress=False)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--protocols", default="0-4")
    ap.add_argument("--effects", default="all", help="'all', 'hand', 'library', or names")
    ap.add_argument("--chi2", type=float, default=300.0, help="the hand-written effects' chi2 beyond the baseline")
    ap.add_argument("--without-sigma", action="store_true",
                    help="drop the output_sigma column (the diagnosis then estimates the noise from the residuals)")
    ap.add_argument("--out", default="simulate-protocol-out")
    args = ap.parse_args(argv)
    protocols = _parse_seeds(args.protocols)
    if any(i < 0 or i >= len(PROTOCOLS) for i in protocols):
        ap.error(f"--protocols: indices 0-{len(PROTOCOLS) - 1}, got {args.protocols!r}")
    if args.effects == "all":
        names = [h.name for h in HAND] + list(LIBRARY)
    elif args.effects == "hand":
        names = [h.name for h in HAND]
    elif args.effects == "library":
        names = list(LIBRARY)
    else:
        names = [n.strip() for n in args.effects.split(",") if n.strip()]
        unknown = [n for n in names if n not in HAND_BY_NAME and n not in LIBRARY]
        if unknown:
            ap.error(f"--effects: unknown {unknown}; known: {[h.name for h in HAND] + list(LIBRARY)}")
    os.makedirs(args.out, exist_ok=True)
    method = GyrojaxMethod()
    records = []
    import gyrojax as gj

    meta = {"git": _git_describe(), "date": datetime.date.today().isoformat(), "chi2": args.chi2,
            "without_sigma": args.without_sigma,
            "protocols": [PROTOCOLS[i] for i in protocols]}

    def record(index, info, table):
        if args.without_sigma:  # the size was set with the stated sigmas; the file then omits them
            table = gj.Table({k: v for k, v in table.columns.items() if k != "output_sigma"},
                             source=table.source + ", without output_sigma")
        out = method.run(table)
        # this generator does not compute the noise-free separations of the library effects (`look_alike_chi2`):
        # the scores read from them are left out, not counted as separable
        s = {**score(out, info), "wrong_separable": None, "found_or_indistinct": None}
        snr = "mid" if args.chi2 == 300.0 else f"chi2 {args.chi2:g}"  # the discovery benchmark's middle SNR
        records.append({"method": method.name, "class": info["class"], "snr": snr, "protocol": index,
                        "hidden": info["hidden"], "scores": s,
                        "outcome": {**dataclasses.asdict(out), "located": sorted(out.located),
                                    "ambiguous": {k: sorted(v) for k, v in out.ambiguous.items()}},
                        "info": info})
        print(f"p{index} {info['hidden'] or 'null'}: confirmed {out.confirmed} verdict {out.verdict} at "
              f"{out.coordinate} on {sorted(out.located)} formula {out.formula} ({out.seconds:.1f} s) "
              f"wrong={s['wrong']} localised={s['localised']}", flush=True)
        rows = score_rows(records)
        write_results(args.out, "simulate_protocol", {"meta": meta, "records": records, "rows": rows},
                      markdown(rows))

    for index in protocols:
        t0 = time.perf_counter()
        clean = clean_lot(index)
        print(f"p{index}: {PROTOCOLS[index]} simulated in {time.perf_counter() - t0:.0f} s", flush=True)
        record(index, {"hidden": None, "class": "null", "library": None}, clean)
        for name in names:
            if name in HAND_BY_NAME:
                if not set(HAND_BY_NAME[name].sweeps) & set(PROTOCOLS[index]["sweeps"]):
                    print(f"p{index} {name}: skipped (its sweeps are not in this protocol)", flush=True)
                    continue
                table, info = hidden_lot(clean, HAND_BY_NAME[name], args.chi2)
            else:
                table, info = library_lot(index, name, clean)
            record(index, info, table)
    print(markdown(score_rows(records)))


if __name__ == "__main__":
    main()
