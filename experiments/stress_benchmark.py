"""The discovery benchmark's lots under departures from its own assumptions: does the diagnosis stay honest when the
noise is not what the lab states, or the lot is not the one the benchmark was tuned on?

Run: python experiments/stress_benchmark.py [--variants all] [--designs a,b] [--seeds 0] [--snr mid] [--out DIR]

A held-out lot differs from the benchmark's in ways no hidden effect names: heavy-tailed or correlated noise, a
noise level that grows with the rate, an output_sigma stated too small, fewer sweeps, fewer devices. Each variant
post-processes the lots of `experiments/_discovery_lot.py` (plain NumPy; the generator's own noise is taken out with
its noise-free truth and replaced), runs `gyrojax.diagnose` on them and scores them as the discovery benchmark does
(`discovery_benchmark.score`). A hidden effect that leaves no visible chi2 on the sweeps a variant keeps turns the
lot into a null lot (nothing may be confirmed).

Variants (`VARIANTS`):

- `t3`: Student-t noise with 3 degrees of freedom, scaled to the stated variance (outliers several sigma out);
- `hetero`: the noise grows with the rate, 0.6 + 0.8 |x| / max |x| times the stated sigma (the stated sigma is the
  lot's mean scatter, as a lab quotes it);
- `ar1`: noise correlated along the dwell order within each run (AR(1), rho = 0.6, the stated variance);
- `sigma_low`: the stated output_sigma 0.8x the true scatter;
- `no_sigma`: no output_sigma column (the diagnosis estimates each sweep's noise per device from the residuals);
- `no_dac`: no DAC bench sweep;
- `rate_only`: the rate table alone;
- `small`: 3 devices of 2 runs.

DIR/stress.json and DIR/stress.md are rewritten atomically after every lot.
"""

import argparse
import dataclasses
import datetime
import math
import os
import sys

import numpy as np


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from _discovery_lot import DESIGNS, discovery_lot, noise_free  # noqa: E402
from discovery_benchmark import (  # noqa: E402
    GyrojaxMethod,
    Outcome,
    _cell,
    _git_describe,
    _list,
    _parse_seeds,
    effect_class,
    effect_names,
    score,
    score_rows,
    write_results,
)


AR1_RHO = 0.6  # ASSUMPTION: a slow thermal or 1/f-like error spanning a few dwells


def _new_noise(kind, cols, sigma, rng):
    """Unit-variance (on average) noise of `kind` times the stated sigma, per row."""
    sweep, x = np.asarray(cols["sweep"]), np.asarray(cols["input"], float)
    if kind == "t3":
        return sigma * rng.standard_t(3, size=x.size) / np.sqrt(3.0)
    if kind == "hetero":
        scale = np.ones_like(x)
        for s in np.unique(sweep):
            m = sweep == s
            scale[m] = 0.6 + 0.8 * np.abs(x[m]) / np.abs(x[m]).max()
        return sigma * scale * rng.normal(size=x.size)
    if kind == "ar1":
        e = np.empty_like(x)
        keys = np.char.add(np.char.add(np.asarray(cols["device"]).astype(str), "|"),
                           np.char.add(np.asarray(cols["run"]).astype(str), "|" + np.asarray(sweep).astype(str)))
        t = np.asarray(cols["time_s"], float)
        for k in np.unique(keys):
            idx = np.flatnonzero(keys == k)
            idx = idx[np.argsort(np.nan_to_num(t[idx]), kind="stable")]
            w = rng.normal(size=idx.size)
            z = np.empty(idx.size)
            z[0] = w[0]
            for i in range(1, idx.size):
                z[i] = AR1_RHO * z[i - 1] + np.sqrt(1.0 - AR1_RHO**2) * w[i]
            e[idx] = z
        return sigma * e
    raise ValueError(kind)


def stress_lot(variant, hidden, *, snr, design, seed):
    """The lot of (`hidden`, `snr`, `design`, `seed`) under `variant`: (table, info)."""
    import gyrojax as gj

    n_devices, n_runs = (3, 2) if variant == "small" else (6, 2)
    table, info = discovery_lot(hidden, snr=snr, design=design, seed=seed, n_devices=n_devices, n_runs=n_runs)
    cols = {k: np.array(v) for k, v in table.columns.items()}
    keep = np.ones(len(cols["output"]), bool)
    if variant in ("t3", "hetero", "ar1"):
        truth, sigma = noise_free(design, seed, n_devices, n_runs)
        null, _ = discovery_lot(None, snr=snr, design=design, seed=seed, n_devices=n_devices, n_runs=n_runs)
        old = np.asarray(null.columns["output"], float) - truth  # the generator's own noise
        rng = np.random.default_rng(10_000 + seed)
        new = _new_noise(variant, cols, sigma, rng)
        force = np.asarray(cols["sweep"]) != "dac"  # the voltmeter's noise is left as it is
        cols["output"] = cols["output"] - np.where(force, old, 0.0) + np.where(force, new, 0.0)
    elif variant == "sigma_low":
        cols["output_sigma"] = cols["output_sigma"] * 0.8
    elif variant == "no_sigma":
        del cols["output_sigma"]
    elif variant == "no_dac":
        keep = np.asarray(cols["sweep"]) != "dac"
    elif variant == "rate_only":
        keep = np.asarray(cols["sweep"]) == "rate_table"
    elif variant != "small":
        raise ValueError(f"unknown variant {variant!r}; expected one of {', '.join(VARIANTS)}.")
    cols = {k: v[keep] for k, v in cols.items()}
    info = dict(info, variant=variant)
    if hidden is not None:
        kept = set(np.unique(cols["sweep"]))
        visible = sorted(set(info["visible_sweeps"]) & kept)
        shares = {s: v for s, v in info["sweep_shares"].items() if s in kept}
        if not visible or sum(shares.values()) < 0.2:  # nothing of it left to see: a null lot
            info.update(hidden=None, visible_sweeps=[], note=f"{hidden} leaves no visible chi2 on {sorted(kept)}")
        else:
            info.update(visible_sweeps=visible)
    source = f"<stress {variant} {hidden or 'null'} {snr} design {design} seed {seed}>"
    return gj.Table.from_columns(cols, source=source), info


VARIANTS = ("t3", "hetero", "ar1", "sigma_low", "no_sigma", "no_dac", "rate_only", "small")


def markdown(variant_rows):
    lines = ["| variant | class | lots | library effect found | wrong confirmation | confirmed as declared ambiguous | "
             "localised | localised or named as confounded | null explained | chi2_red (median) | s per lot |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for variant, r in variant_rows:
        lines.append(f"| {variant} | {r['class']} | {r['lots']} | {_cell(r['found'])} | {_cell(r['wrong'])} | "
                     f"{_cell(r['ambiguous'])} | {_cell(r['localised'])} | {_cell(r['confounded'])} | "
                     f"{_cell(r['explained'])} | {r['chi2_red']:.3f} | {r['seconds']:.1f} |")
    return "\n".join(lines) + "\n"


def _rows_by_variant(records):
    out = []
    for v in VARIANTS:
        rs = [r for r in records if r["variant"] == v]
        out += [(v, row) for row in score_rows(rs)] if rs else []
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--variants", default="all")
    p.add_argument("--designs", default="a,b")
    p.add_argument("--seeds", default="0")
    p.add_argument("--snr", default="mid")
    p.add_argument("--effects", default="all", help="'all' (the benchmark's 26), 'held-out' (12 more) or names")
    p.add_argument("--preset", default="paper-qmg")
    p.add_argument("--out", default="stress_out")
    a = p.parse_args(argv)
    import gyrojax as gj

    variants = list(VARIANTS) if a.variants == "all" else _list(a.variants, list(VARIANTS), "variants")
    effects = [None] + effect_names(a.effects)
    designs = _list(a.designs, list(DESIGNS), "designs")
    os.makedirs(a.out, exist_ok=True)
    method = GyrojaxMethod(a.preset)
    settings = {"variants": variants, "designs": a.designs, "seeds": a.seeds, "snr": a.snr,
                "gyrojax": gj.__version__, "tree": _git_describe(),
                "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
    lots = [(v, d, s, e) for v in variants for d in designs for s in _parse_seeds(a.seeds)
            for e in effects]
    records = []
    for i, (variant, design, seed, hidden) in enumerate(lots):
        table, info = stress_lot(variant, hidden, snr=a.snr, design=design, seed=seed)
        try:
            out = method.run(table)
        except Exception as exc:  # recorded as failing, never skipped
            out = Outcome([], "failed", set(), None, [], math.nan, math.nan, note=f"{type(exc).__name__}: {exc}")
        eff = info["hidden"]
        rec = {"method": method.name, "variant": variant, "design": design, "seed": seed, "hidden": hidden,
               "snr": a.snr, "class": effect_class(eff), "info": info,
               "outcome": {**dataclasses.asdict(out), "located": sorted(out.located)}, "scores": score(out, info)}
        records.append(rec)
        print(f"[{i + 1}/{len(lots)}] {variant} design {design} seed {seed} {hidden or 'null'}: {out.verdict}, "
              f"confirmed {out.confirmed or '-'}, located {sorted(out.located) or '-'} on {out.coordinate}, "
              f"chi2_red {out.chi2_red:.3f}, {out.seconds:.1f} s; wrong={rec['scores']['wrong']}", flush=True)
        vr = _rows_by_variant(records)
        write_results(a.out, "stress", {"settings": settings, "rows": vr, "records": records}, markdown(vr))
    print(markdown(_rows_by_variant(records)))


if __name__ == "__main__":
    main()
