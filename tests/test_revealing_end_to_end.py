"""A revealing sweep kind end to end: a hidden `quadrature_phase` at its typical size, which rate-table and
static-VCF sweeps cannot see, is found by `gj.diagnose` once the quadrature injection is measured, and fitted
at its size."""

import numpy as np
import pytest

import gyrojax as gj


pytestmark = pytest.mark.slow

RATES = (-200.0, -50.0, -5.0, 5.0, 50.0, 200.0)
CANDIDATES = ("quadrature_phase", "damping_coupling")


@pytest.fixture(scope="module")
def hidden():
    effect = gj.effects.QuadraturePhase.typical(1.0)
    gyro = gj.add_effect(gj.paper_qmg(), effect)
    table = gj.simulate_table(gyro, devices=1, runs=2, seed=3, progress=False,
                              sweeps=(gj.sweeps.RateTable(RATES), gj.sweeps.VcfStatic(RATES), "quadrature_injection"))
    return float(effect.phase), table


def test_without_the_injection_it_is_not_testable(hidden):
    _, table = hidden
    old = table.select(np.flatnonzero(np.asarray(table["sweep"]) != "quadrature_injection"))
    d = gj.diagnose("paper-qmg", old, candidates=CANDIDATES, progress=False)
    assert "quadrature_phase" in d.untestable
    assert "quadrature_phase" not in d.selected


def test_with_the_injection_it_is_found_at_its_size(hidden):
    truth, table = hidden
    d = gj.diagnose("paper-qmg", table, candidates=CANDIDATES, progress=False)
    assert d.ranking[0].effect == "quadrature_phase" and d.ranking[0].testable
    assert d.selected[:1] == ("quadrature_phase",)
    fit = d.final
    name = next(n for n in fit.names if n.startswith("quadrature_phase."))
    value, err = float(np.ravel(fit.value(name))[0]), float(np.asarray(fit.stderr)[0, fit.names.index(name)])
    assert abs(value - truth) < 2.0 * err, (value, err, truth)
    assert err < 0.05 * abs(truth)
    assert 0.5 < d.final.chi2_red_total < 2.0
