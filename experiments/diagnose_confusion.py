"""Finding a hidden effect: the confusion table of `diagnose` over every candidate effect.

Run: python experiments/diagnose_confusion.py [--out DIR] [--effects NAME,...] [--presets NAME,...]
                                              [--devices 3] [--runs 2] [--seed 7] [--plan [--max-repeats 2]]

Each candidate effect is hidden in turn, at its typical size (`gyrojax.effect(name, 1.0)`), in a simulated lot
(`gyrojax.simulate_table`: noise on, the default `ProcessSpread`, a fixed seed shared by every case, so each
case is the same lot with a different hidden effect) on the preset where the effect can act
(`AbstractEffect.supports`): seed 000's closed-loop `paper-qmg` (rate table + static VCF + DAC sweeps) for all
but the effects that act only on an open-loop readout, which go on seed 003's `vcf-2018` (rate table + static
and dynamic VCF sweeps); comb_gap, which needs a residual sense motion, on `qmg-leaky` (paper-qmg with a leaky
rebalance integrator, see `base_device`). `gyrojax.diagnose` then starts from the *plain* preset,
every supported candidate considered, without being told what was hidden or the true parameters. Also: nothing hidden
(on each preset), and two effects hidden at once (dac_inl + vref_drift on paper-qmg).

Each row: hidden -> selected (in order), the ambiguity groups reported, the candidates the baseline absorbs
(not testable on this data), rejected candidates, chi2_red before and after, and a verdict:

- `found`: every hidden effect is selected or in a reported ambiguity group together with a selected one;
- `absorbed`: a hidden effect is not testable (the baseline's free parameters take it up, as they should);
- `missed`: a hidden, testable effect is neither selected nor in a group;
- `+spurious`: something was selected that was not hidden and is not grouped with a hidden effect;
- `chi2 ok` when the final chi2_red is within [0.7, 1.4] (issue 5's acceptance band).

**With the planner (`--plan`).** Each case is then taken one step further, as a lab would: `gyrojax.plan` runs on
the diagnosis's baseline fit of the standard sweeps (every candidate at zero; default experiments, at most
`--max-repeats` runs of each), and the experiments it recommends for every candidate it finds untestable (the
union over candidates, the most runs any one asks for: `Plan.runs`) are simulated for the same devices (the
lot of the standard sweeps, one device at a time with its own seed, an independent noise draw:
`Plan.simulate`) and appended to the table as further runs; `diagnose` then runs again on the standard +
recommended data, freeing what the added runs read (`Plan.free`: `omega_x` with the drive frequency).
A row of the second table adds what was recommended (and for which candidates), the hidden effect's
planned expected chi2 (its own recommended set, typical size: the noncentrality of its test) against what
the second diagnosis's score test sees at its baseline (`typical_chi2`, the same quantity at the joint
fit, and the statistic minus its df, one noise draw of it), and the verdict on the added data.

Every case on one preset shares data shapes and the candidate set, so `identify` compiles once per preset;
the simulation compiles once per hidden effect. Results are written after every case (atomic JSON and
Markdown), so a long run can be read while it goes on.
"""

import argparse
import os
import sys
import time
import traceback

import equinox as eqx
import jax.numpy as jnp

import gyrojax as gj


SWEEPS = {
    "paper-qmg": ("rate_table", "vcf_static", "dac"),  # issue 5: rate table + VCF + DAC on the closed loop
    # open loop: no FTR DAC to sweep; seed 003's three sweeps (the dynamic VCF sweep fixes the sense resonance:
    # split and damping, which the static sweeps see only through the low-frequency gain).
    "vcf-2018": ("rate_table", "vcf_static", "vcf_dynamic"),
    # paper-qmg with a leaky rebalance integrator (see base_device), for the effects that need the residual
    # sense motion an ideal integrator removes (comb_gap); paper-qmg's sweeps.
    "qmg-leaky": ("rate_table", "vcf_static", "dac"),
}
# ASSUMPTION: leak 1e4/s >> ki/kp makes paper-qmg's rebalance loop nearly proportional: the largest residual
# sense motion its gains allow (19 nm at 200 deg/s), where comb_gap's typical size is a few ppm of odd cubic
# (gyrojax/_effects/comb_gap.py; tests/test_effects.py uses the same device).
LEAKY_LEAK = 1e4
BASE_FREE = gj.identification.DEFAULT_FREE  # the baseline's free parameters on the standard sweeps
PAIR = ("dac_inl", "vref_drift")  # issue 5: "two effects hidden at once"
CHI2_BAND = (0.7, 1.4)  # issue 5's acceptance band for the final reduced chi2


def base_device(name):
    """The plain device of a case: a preset, or paper-qmg with the leaky rebalance loop for "qmg-leaky"."""
    if name == "qmg-leaky":
        g = gj.preset("paper-qmg")
        return eqx.tree_at(lambda d: d.rebalance_loop.leak, g, jnp.asarray(LEAKY_LEAK, dtype=float))
    return gj.preset(name)


def cases(effects=None, presets=None):
    """(preset, hidden effects) for every case (only those on `presets`, if given), and the effects no preset
    supports."""
    plain = {p: base_device(p) for p in SWEEPS}
    supported = {p: gj.supported_effects(g) for p, g in plain.items()}
    names = tuple(gj.EFFECTS) if effects is None else tuple(effects)
    for n in names:
        if n not in gj.EFFECTS and n != "none" and n != "+".join(PAIR):
            raise ValueError(f"--effects: unknown effect {n!r}; expected names of gyrojax.EFFECTS "
                             f"({', '.join(gj.EFFECTS)}), 'none' or {'+'.join(PAIR)!r}.")
    out, unsupported = [], []
    if effects is None or "none" in names:
        out += [("paper-qmg", ())]
    for n in names:
        if n not in gj.EFFECTS:
            continue
        # closed loop first (issue 5's sweeps), the open-loop preset for effects that act only there
        where = next((p for p in SWEEPS if n in supported[p]), None)
        if where is None:
            unsupported.append(n)
        else:
            out.append((where, (n,)))
    if effects is None or "+".join(PAIR) in names:
        out.append(("paper-qmg", PAIR))
    if effects is None or "none" in names:
        out.append(("vcf-2018", ()))
    if presets is not None:
        for p in presets:
            if p not in SWEEPS:
                raise ValueError(f"--presets: unknown preset {p!r}; expected {', '.join(SWEEPS)}.")
        out = [c for c in out if c[0] in presets]
    # closed-loop cases first, open-loop ones last: they share one compiled model per preset
    out.sort(key=lambda c: list(SWEEPS).index(c[0]))
    return out, unsupported


def verdict(hidden, d) -> dict:
    selected = list(d.selected)
    groups = [list(g) for g in d.ambiguous]
    untestable = list(d.untestable)
    found, absorbed, missed = [], [], []
    for h in hidden:
        if h in selected or any(h in g and set(g) & set(selected) for g in groups):
            found.append(h)
        elif h in untestable:
            absorbed.append(h)
        else:
            missed.append(h)
    spurious = [s for s in selected if s not in hidden
                and not any(s in g and set(g) & set(hidden) for g in groups)]
    chi2 = d.final.chi2_red_total
    words = []
    if hidden:
        words.append("found" if not (absorbed or missed) else
                     "missed" if missed else "absorbed")
    else:
        words.append("nothing selected" if not selected else "selected on clean data")
    if spurious and hidden:
        words.append("+spurious")
    chi2_ok = CHI2_BAND[0] <= chi2 <= CHI2_BAND[1]
    words.append("chi2 ok" if chi2_ok else "chi2 out of band")
    return {"found": found, "absorbed": absorbed, "missed": missed, "spurious": spurious,
            "chi2_ok": chi2_ok, "verdict": ", ".join(words)}


def run_case(preset, hidden, *, devices, runs, seed, progress=None):
    """One row of the confusion table (see `case_and_data`)."""
    return case_and_data(preset, hidden, devices=devices, runs=runs, seed=seed, progress=progress)[0]


def case_and_data(preset, hidden, *, devices, runs, seed, progress=None):
    """Hide `hidden` on `preset`, simulate the standard sweeps, diagnose: (row, table, diagnosis)."""
    g = base_device(preset)
    for h in hidden:
        g = gj.add_effect(g, h, 1.0)
    t0 = time.perf_counter()
    table = gj.simulate_table(g, devices=devices, runs=runs, sweeps=SWEEPS[preset], seed=seed)
    t1 = time.perf_counter()
    d = gj.diagnose(base_device(preset), table, progress=progress)
    t2 = time.perf_counter()
    report = d.to_json()
    row = {"preset": preset, "hidden": list(hidden), "selected": list(d.selected),
           "ambiguous": [list(g) for g in d.ambiguous], "untestable": list(d.untestable),
           "look_alikes": {s.effect: [a.probe for a in s.look_alikes] for s in d.steps if s.look_alikes},
           "rejected": report["rejected"], "ranking": report["ranking"],
           "baseline_chi2_red": d.baseline.chi2_red_total, "final_chi2_red": d.final.chi2_red_total,
           "baseline_nonlinearity_ppm": d.baseline_nonlinearity_ppm,
           "final_nonlinearity_ppm": report["final"]["nonlinearity_ppm"],
           "seconds_simulate": t1 - t0, "seconds_diagnose": t2 - t1}
    row.update(verdict(hidden, d))
    # why an absorbed hidden effect could not be tested, in the diagnosis's own words
    row["absorption"] = {h: d.absorptions[h] for h in row["absorbed"]}
    return row, table, d


PLAN_NOISE_SEED = 1000  # the recommended runs of device i are simulated with seed + PLAN_NOISE_SEED + i (Plan.simulate)


def run_plan_case(preset, hidden, first, d, *, devices, runs, seed, max_repeats, progress=None):
    """The planner step of a case (see the module notes): plan on the first diagnosis's baseline, simulate the
    recommended runs, diagnose again. `first`: the case's table of the standard sweeps; `d` its diagnosis."""
    g = base_device(preset)
    for h in hidden:
        g = gj.add_effect(g, h, 1.0)
    t0 = time.perf_counter()
    p = gj.plan(fit=d.baseline, max_repeats=max_repeats, scale_factor=False, progress=progress)
    t1 = time.perf_counter()
    recs = p.runs()
    both = p.simulate(g, first, devices=devices, runs=runs, seed=seed, noise_seed=PLAN_NOISE_SEED) if recs else None
    t2 = time.perf_counter()
    # what the added runs read beyond the baseline (omega_x from the drive frequency) is freed, as planned
    free = p.free(BASE_FREE)
    d2 = gj.diagnose(base_device(preset), both, free=free, progress=progress) if recs else d
    t3 = time.perf_counter()
    report = d2.to_json()
    scores = {s.effect: s for s in d2.ranking}
    first_scores = {s.effect: s for s in d.ranking}
    planned = {}
    for h in hidden:
        c = next((c for c in p.candidates if c.effect == h), None)
        # an effect testable on the standard sweeps is planned on them: compare with the first diagnosis
        s2 = first_scores.get(h) if c is not None and c.testable else scores.get(h)
        planned[h] = {
            "planned_testable": None if c is None else bool(c.testable),
            "planned_df": None if c is None else c.df,
            "planned_chi2_now": None if c is None else c.expected_chi2,
            "planned_chi2": None if c is None else c.recommended_chi2,
            "planned_power": None if c is None else c.recommended_power,
            "planned_runs": None if c is None else {r.experiment.name: r.runs for r in c.recommended},
            "planned_reason": None if c is None else c.reason,
            "seen_typical_chi2": None if s2 is None else float(s2.typical_chi2),
            "seen_statistic": None if s2 is None else float(s2.statistic),
            "seen_df": None if s2 is None else int(s2.df),
        }
    row = {"preset": preset, "hidden": list(hidden), "free": list(free),
           "recommended": {n: {"runs": k, "minutes": k * e.minutes, "for": list(who)}
                           for n, (e, k, who) in recs.items()},
           "unreachable": [c.effect for c in p.candidates if not c.testable and not c.recommended],
           "selected": list(d2.selected), "ambiguous": [list(x) for x in d2.ambiguous],
           "untestable": list(d2.untestable), "rejected": report["rejected"], "ranking": report["ranking"],
           "baseline_chi2_red": d2.baseline.chi2_red_total, "final_chi2_red": d2.final.chi2_red_total,
           "planned": planned, "seconds_plan": t1 - t0, "seconds_simulate": t2 - t1, "seconds_diagnose": t3 - t2}
    row.update(verdict(hidden, d2))
    row["absorption"] = {h: d2.absorptions[h] for h in row["absorbed"]}
    row["ambiguity_reasons"] = {"; ".join(x): r for x, r in zip(row["ambiguous"], _ambiguity_reasons(d2))}
    return row


def _ambiguity_reasons(d):
    """Why each ambiguity group stands, in the diagnosis's words (its steps' `separated_by`)."""
    out = []
    steps = d.to_json()["steps"]
    for grp in d.ambiguous:
        step = next((s for s in steps if s.get("effect") == grp[0]), {})
        sep = step.get("separated_by")
        out.append(f"{sep} separates them" if sep else "no sweep in these data separates them")
    return out


def _fmt(x):
    return "-" if not x else ", ".join(x)


def _num(x, spec):
    return "-" if x is None else format(x, spec)


def markdown(rows, unsupported, settings) -> str:
    lines = ["# Finding a hidden effect: confusion table", "",
             f"Lot of {settings['devices']} devices x {settings['runs']} runs, seed {settings['seed']}, noise on, "
             "default `ProcessSpread`; `diagnose` from the plain preset with every supported candidate. "
             + "; ".join(f"{p} sweeps: " + " + ".join(sw) for p, sw in SWEEPS.items())
             + f" (qmg-leaky: paper-qmg with rebalance_loop.leak = {LEAKY_LEAK:g}/s).", "",
             "| hidden | preset | selected | ambiguity group | untestable (absorbed) | chi2_red before -> after "
             "| NL residual ppm before -> after | s | verdict |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {' + '.join(r['hidden']) or 'none'} | {r['preset']} | {_fmt(r['selected'])} | "
                     f"{'; '.join(_fmt(g) for g in r['ambiguous']) or '-'} | {_fmt(r['untestable'])} | "
                     f"{_num(r['baseline_chi2_red'], '.3g')} -> {_num(r['final_chi2_red'], '.3f')} | "
                     f"{_num(r['baseline_nonlinearity_ppm'], '.2f')} -> {_num(r['final_nonlinearity_ppm'], '.2f')} | "
                     f"{r['seconds_simulate'] + r['seconds_diagnose']:.0f} | {r['verdict']} |")
    if unsupported:
        lines += ["", f"Not simulated (no preset's device supports them): {', '.join(unsupported)}."]
    absorbed = [(r, h, why) for r in rows for h, why in r.get("absorption", {}).items()]
    if absorbed:
        lines += ["", "Absorbed, in the diagnosis's words (what hid it; what would reveal it):"]
        lines += [f"- {h} on {r['preset']}: {why}" for r, h, why in absorbed]
    rej = [(r, x) for r in rows for x in r["rejected"]]
    if rej:
        lines += ["", "Rejected after refit:"]
        lines += [f"- hidden {' + '.join(r['hidden']) or 'none'}: {x['effect']} ({x['reason']})" for r, x in rej]
    return "\n".join(lines) + "\n"


def plan_markdown(rows, settings) -> str:
    lines = ["", "## With the planner's recommended runs", "",
             f"`gyrojax.plan(fit=baseline, max_repeats={settings['max_repeats']})` on each case's standard sweeps; "
             "the union of its recommendations for the candidates it finds untestable simulated for the same "
             f"devices (noise seed = seed + {PLAN_NOISE_SEED} + device) and `diagnose` run again on standard + "
             "recommended.", "",
             "| hidden | preset | recommended (runs, for) | selected | ambiguity group (why) | untestable "
             "| chi2_red before -> after | s | verdict |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.get("error"):
            lines.append(f"| {' + '.join(r['hidden']) or 'none'} | {r['preset']} | | | | | | | {r['verdict']} |")
            continue
        rec = "; ".join(f"{v['runs']} x {n} ({', '.join(v['for'])})" for n, v in r["recommended"].items()) or "-"
        amb = "; ".join(f"{_fmt(g)} ({r['ambiguity_reasons'].get('; '.join(g), '')})" for g in r["ambiguous"]) or "-"
        secs = r["seconds_plan"] + r["seconds_simulate"] + r["seconds_diagnose"]
        lines.append(f"| {' + '.join(r['hidden']) or 'none'} | {r['preset']} | {rec} | {_fmt(r['selected'])} | "
                     f"{amb} | {_fmt(r['untestable'])} | {_num(r['baseline_chi2_red'], '.3g')} -> "
                     f"{_num(r['final_chi2_red'], '.3f')} | {secs:.0f} | {r['verdict']} |")
    lines += ["", "Planned against seen (the hidden effect at its typical size; planned: the expected chi2 with "
              "its own recommended runs added, at the standard sweeps' baseline; seen: the diagnosis's `typical_chi2` "
              "at its baseline, of standard + recommended data (of the standard sweeps for an effect they test "
              "already), and its score statistic minus df, one noise draw):", "",
              "| hidden | recommended for it | df | planned chi2 now -> with them (power) | seen typical_chi2 "
              "| seen statistic - df | seen / planned |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        for h, x in r.get("planned", {}).items():
            if x["planned_chi2"] is None:
                continue
            ratio = (x["seen_typical_chi2"] / x["planned_chi2"]) if x["seen_typical_chi2"] is not None and \
                x["planned_chi2"] > 0 else None
            runs = ", ".join(f"{k} x {n}" for n, k in (x["planned_runs"] or {}).items()) or (
                "testable already" if x["planned_testable"] else x["planned_reason"])
            stat = None if x["seen_statistic"] is None else x["seen_statistic"] - x["seen_df"]
            lines.append(f"| {h} | {runs} | {x['planned_df']} | {_num(x['planned_chi2_now'], '.3g')} -> "
                         f"{_num(x['planned_chi2'], '.3g')} ({_num(x['planned_power'], '.2f')}) | "
                         f"{_num(x['seen_typical_chi2'], '.3g')} | {_num(stat, '.3g')} | {_num(ratio, '.2f')} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="folder for diagnose_confusion.json and .md (written after every case)")
    ap.add_argument("--effects", help="comma-separated subset of effect names ('none' and "
                                      f"'{'+'.join(PAIR)}' allowed); default every effect, none and the pair")
    ap.add_argument("--presets", help=f"comma-separated subset of {', '.join(SWEEPS)}: only the cases on these")
    ap.add_argument("--devices", type=int, default=3, help="lot size (default 3)")
    ap.add_argument("--runs", type=int, default=2, help="runs per device and sweep (default 2)")
    ap.add_argument("--seed", type=int, default=7, help="PRNG seed of the lot and the noise, shared by all cases")
    ap.add_argument("--plan", action="store_true", help="also plan on each case's baseline, simulate the "
                                                        "recommended runs and diagnose again (see the notes)")
    ap.add_argument("--max-repeats", type=int, default=2, help="the plan's max_repeats (default 2)")
    ap.add_argument("--quiet", action="store_true", help="no progress messages")
    args = ap.parse_args(argv)
    effects = None if args.effects is None else tuple(e.strip() for e in args.effects.split(",") if e.strip())
    presets = None if args.presets is None else tuple(p.strip() for p in args.presets.split(",") if p.strip())
    todo, unsupported = cases(effects, presets)
    settings = {"devices": args.devices, "runs": args.runs, "seed": args.seed}
    if args.plan:
        settings.update({"plan": True, "max_repeats": args.max_repeats, "plan_noise_seed": PLAN_NOISE_SEED})
    rows, plan_rows = [], []
    say = None if args.quiet else (lambda m: print("   ", m, file=sys.stderr, flush=True))
    if args.out:
        os.makedirs(args.out, exist_ok=True)
    print(f"{'hidden':<22} {'preset':<10} {'selected':<28} {'ambiguous':<24} {'chi2 before':>11} {'after':>7}  "
          "verdict", flush=True)
    for preset, hidden in todo:
        if say:
            say(f"case: hidden {' + '.join(hidden) or 'none'} on {preset}")
        try:
            r, table, d = case_and_data(preset, hidden, devices=args.devices, runs=args.runs, seed=args.seed,
                                        progress=say)
            if args.plan:
                if say:
                    say("planning on its baseline, simulating the recommended runs, diagnosing again")
                try:
                    pr = run_plan_case(preset, hidden, table, d, devices=args.devices, runs=args.runs,
                                       seed=args.seed, max_repeats=args.max_repeats, progress=say)
                except Exception as e:
                    if args.out:
                        with open(os.path.join(args.out, "errors.log"), "a") as f:
                            f.write(f"=== plan: {' + '.join(hidden) or 'none'} on {preset}\n"
                                    f"{traceback.format_exc()}\n")
                    msg = " ".join(str(e).strip().splitlines()[-6:])
                    pr = {"preset": preset, "hidden": list(hidden), "error": True,
                          "verdict": f"error: {type(e).__name__}: {msg}"[:400]}
                plan_rows.append(pr)
                print(f"  + plan: {_fmt(list(pr.get('recommended', {})))} -> {_fmt(pr.get('selected'))}; "
                      f"{pr['verdict']}", flush=True)
        except Exception as e:  # recorded, not hidden: one failing case must not lose the others
            # JAX runtime errors put the stack first: keep the message's last lines, the full trace in a log
            msg = " ".join(str(e).strip().splitlines()[-6:])
            if args.out:
                with open(os.path.join(args.out, "errors.log"), "a") as f:
                    f.write(f"=== {' + '.join(hidden) or 'none'} on {preset}\n{traceback.format_exc()}\n")
            r = {"preset": preset, "hidden": list(hidden), "selected": [], "ambiguous": [], "untestable": [],
                 "rejected": [], "baseline_chi2_red": None, "final_chi2_red": None,
                 "baseline_nonlinearity_ppm": None, "final_nonlinearity_ppm": None,
                 "seconds_simulate": 0.0, "seconds_diagnose": 0.0,
                 "verdict": f"error: {type(e).__name__}: {msg}"[:400], "error": True}
        rows.append(r)
        print(f"{' + '.join(hidden) or 'none':<22} {preset:<10} {_fmt(r['selected']):<28} "
              f"{'; '.join(_fmt(g) for g in r['ambiguous']) or '-':<24} {_num(r['baseline_chi2_red'], '11.4g')} "
              f"{_num(r['final_chi2_red'], '7.3f')}  {r['verdict']}   (untestable: {_fmt(r['untestable'])}; "
              f"{r['seconds_simulate'] + r['seconds_diagnose']:.0f} s)", flush=True)
        out = {"settings": settings, "sweeps": {k: list(v) for k, v in SWEEPS.items()}, "rows": rows,
               "plan_rows": plan_rows,
               "unsupported": unsupported, "complete": len(rows) == len(todo),
               "versions": {"gyrojax": gj.__version__}}
        if args.out:
            gj.io.atomic_write_json(out, os.path.join(args.out, "diagnose_confusion.json"))
            gj.io.atomic_write_bytes(os.path.join(args.out, "diagnose_confusion.md"),
                               (markdown(rows, unsupported, settings)
                                + (plan_markdown(plan_rows, settings) if args.plan else "")).encode())
    if unsupported:
        print(f"not simulated (no preset supports them): {', '.join(unsupported)}")
    return out


if __name__ == "__main__":
    main()
