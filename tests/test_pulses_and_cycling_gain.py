"""Two shapes along time that no list names: a bias that switches on and back off at its own times in each power-on
(a two-level charge trap: the change-point scan's pulse reading), and a gain that cycles in time (a reference
following the lab's air conditioning: the spectral scan along time read as a gain, and `periodic(time_s)*model` in
the formula's dictionary). The lots are the independent NumPy generator's null lots on the shuffled protocol
(design c, where the time is not the input's order), post-processed by hand."""

import os
import sys

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._diagnose import changepoints
from gyrojax._diagnose.descriptions import coordinates, describe
from gyrojax._diagnose.space import ResidualSpace


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


RV = ("rate_table", "vcf_static")
PULSE_SIGMA = 8.0  # each pulse's height in output sigmas: every (device, run) pulse stands alone
CYCLE_PERIOD_S = 900.0
CYCLE_GAIN = 4e-6  # relative gain amplitude


def _pulsed(n_devices=3):
    """A design-c null lot with a pulse of the bias in every (device, run) of the rate and VCF rows, from one
    dwell to a later one drawn per power-on (the same times on both sweeps' clocks), and the pulses' times."""
    table, _ = discovery_lot(None, snr="mid", design="c", n_devices=n_devices, seed=3)
    cols = {k: np.asarray(v) for k, v in table.columns.items()}
    out = np.array(cols["output"], dtype=float)
    t = np.asarray(cols["time_s"], dtype=float)
    rng = np.random.default_rng(4)
    times = {}
    for d in np.unique(cols["device"]):
        for r in np.unique(cols["run"]):
            rows = (cols["device"] == d) & (cols["run"] == r) & (cols["sweep"] == "rate_table")
            dwells = np.sort(t[rows])
            a = int(rng.integers(3, dwells.size // 2))
            b = int(rng.integers(a + 3, dwells.size - 2))
            on, off = dwells[a], dwells[b]
            times[(str(d), int(r))] = (on, off)
            hit = (cols["device"] == d) & (cols["run"] == r) & np.isin(cols["sweep"], RV) & (t >= on) & (t < off)
            out[hit] += PULSE_SIGMA * cols["output_sigma"][hit]
    cols["output"] = out
    return gj.Table(cols, source="<design c + bias pulses>"), times


@pytest.fixture(scope="module")
def pulsed_fit():
    table, times = _pulsed()
    return gj.identify("paper-qmg", table, progress=False), times


def test_a_pulse_is_the_difference_of_two_projected_steps(pulsed_fit):
    # the pulse reading's statistic, read from the projected step columns, is the score of the pulse's own column
    fit, _ = pulsed_fit
    space = ResidualSpace(fit)
    block = fit.data.blocks["rate_table"]
    mask = np.asarray(block.mask)
    t = np.where(mask, np.asarray(coordinates(block)["time_s"], float), 0.0)
    n_dev, n_run, n_pt = mask.shape
    stats, projected = {}, {}
    for j in range(2, n_pt - 1):
        g = np.zeros((n_dev, n_run, n_pt, 1))
        for dv in range(n_dev):
            g[dv, 0, :, 0] = changepoints._from_position(t[dv, 0], mask[dv, 0], j)
        cols = space.columns({"rate_table": g})
        pc = space.project(cols)[..., 0]
        ok = np.einsum("dr,dr->d", pc, pc) > 0
        stats[(0, j)] = (np.zeros(n_dev), ok, cols)
        projected[(0, j)] = pc
    pulses = changepoints._pulses(stats, projected, space.residuals)
    stat, (start, end), tried = pulses[(0, 0)]
    assert end - start >= changepoints.MIN_PULSE_POINTS
    assert tried == (n_pt - 3) + sum(1 for u in range(2, n_pt - 1) for v in range(u + 2, n_pt - 1))
    g = np.zeros((n_dev, n_run, n_pt, 1))
    g[0, 0, :, 0] = (changepoints._from_position(t[0, 0], mask[0, 0], start)
                     - changepoints._from_position(t[0, 0], mask[0, 0], end))
    direct = space.score(space.columns({"rate_table": g})).statistic
    assert stat == pytest.approx(direct, rel=1e-6)


def test_pulses_at_their_own_times_are_read_as_pulses(pulsed_fit):
    fit, times = pulsed_fit
    descs, _ = describe(ResidualSpace(fit))
    (step,) = [d for d in descs if d.family == "step" and d.sweep == "rate_table"]
    assert step.p_value < 1e-10 and "until_each" in step.where
    found = {(str(d), int(r)): (a, e) for (d, r), a, e in zip(step.where["runs"], step.where["at_each"],
                                                              step.where["until_each"])}
    assert len(found) >= 4  # of the 6 (device, run) pairs, capped by the scan's MAX_OWN_STEPS
    dwell = 120.0  # the generator's dwell spacing: each time within one dwell of the truth
    for pair, (a, e) in found.items():
        on, off = times[pair]
        assert abs(a - on) <= dwell and e is not None and abs(e - off) <= dwell, (pair, a, e, on, off)


@pytest.mark.slow
def test_a_gain_cycling_in_time_is_proposed_as_a_periodic_gain():
    table, _ = discovery_lot(None, snr="mid", design="c", seed=5)
    cols = {k: np.asarray(v) for k, v in table.columns.items()}
    t = np.asarray(cols["time_s"], dtype=float)
    on = np.isin(cols["sweep"], RV)
    cols["output"] = np.where(on, np.asarray(cols["output"], float)
                              * (1.0 + CYCLE_GAIN * np.sin(2 * np.pi * np.nan_to_num(t) / CYCLE_PERIOD_S)),
                              cols["output"])
    d = gj.diagnose("paper-qmg", gj.Table(cols, source="<design c + cycling gain>"), progress=False)
    assert d.selected == () and d.verdict == "unexplained", d.summary()
    top = d.discrepancy[0]
    assert top.coordinate == "time_s", top.text if hasattr(top, "text") else top
    names = [term.name for term in d.formula.terms]
    assert "periodic(time_s)*model" in names, names
    (i,) = [k for k, term in enumerate(d.formula.terms)
            if term.name == "periodic(time_s)*model" and "sin" in term.expression]
    period = float(d.formula.terms[i].expression.split("/")[-1].strip(" )"))
    assert abs(period - CYCLE_PERIOD_S) < 0.1 * CYCLE_PERIOD_S
    assert abs(d.formula.coefficients[i] - CYCLE_GAIN) < 3.0 * d.formula.stderr[i] + 0.15 * CYCLE_GAIN
