"""The planner's scale-factor design against a Monte Carlo of actual fits.

`gyrojax.plan` predicts, from the Fisher information of a baseline fit, the scale factor's standard error of
seed 000's 22-rate protocol and of its own design at equal test time. Here both protocols are simulated on
`DEVICES` identical paper-qmg devices (no process spread: each device is an independent noise draw of the
same truth), each device is fitted with `gyrojax.identify`, and the spread of the fitted scale factors over
the devices is compared with the prediction (its Monte Carlo uncertainty: std / sqrt(2 (N - 1))).

Run: `python experiments/plan_validation.py` (about 15 minutes on a 2-core CPU, most of it compiling).
"""

import math
import time

import numpy as np

import gyrojax as gj


DEVICES = 16


def spread(protocol, runs, seed):
    table = gj.simulate_table(gj.preset("paper-qmg"), devices=DEVICES, runs=runs, protocol=protocol, seed=seed,
                              spread=gj.ProcessSpread(omega=0.0, q=0.0, mass=0.0, electrode=0.0, angular_gain=0.0,
                                                      split=0.0, vcf_electrode=0.0), progress=False)
    fit = gj.identify("paper-qmg", table, progress=False)
    sf = np.asarray(fit.scale_factor)
    return float(np.std(sf, ddof=1)), float(np.mean(np.asarray(fit.scale_factor_stderr))), fit.status


def main():
    t0 = time.time()
    given = gj.simulate_table(gj.preset("paper-qmg"), runs=2, seed=1, progress=False)
    plan = gj.plan(given, "paper-qmg", max_repeats=2, progress=False)
    design = plan.scale_factor
    print(plan.summary())
    print(f"[{time.time() - t0:.0f} s] Monte Carlo, {DEVICES} devices per protocol")
    rows = []
    for name, protocol, runs, predicted in (
            ("seed 000", gj.Protocol(), design.seed000_runs, float(np.mean(design.seed000_stderr))),
            ("design", gj.Protocol(rates_dps=design.rates_dps), design.rate_runs, float(np.mean(design.stderr)))):
        sd, fit_se, status = spread(protocol, runs, seed=11)
        mc = sd / math.sqrt(2 * (DEVICES - 1))
        rows.append((name, runs, predicted, sd, mc, fit_se))
        print(f"[{time.time() - t0:.0f} s] {name}: {runs} run(s); predicted stderr {predicted:.4g}, Monte Carlo "
              f"std {sd:.4g} +/- {mc:.2g} ({(sd - predicted) / mc:+.2f} sigma), the fits' own stderr "
              f"{fit_se:.4g}; statuses {sorted(set(status))}")
    ratio_pred = rows[1][2] / rows[0][2]
    ratio_mc = rows[1][3] / rows[0][3]
    ratio_unc = ratio_mc * math.sqrt((rows[0][4] / rows[0][3]) ** 2 + (rows[1][4] / rows[1][3]) ** 2)
    print(f"stderr ratio design / seed 000: predicted {ratio_pred:.3f}, Monte Carlo {ratio_mc:.3f} +/- "
          f"{ratio_unc:.2f}")


if __name__ == "__main__":
    main()
