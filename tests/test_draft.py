"""The pieces of Open world II that need no fit: false-discovery control and the drafted effect module."""

import importlib.util

import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj
from gyrojax._diagnose.draft import DraftError, draft_effect_source, write_draft
from gyrojax._diagnose.fdr import bh_q_values, selection_p
from gyrojax._diagnose.formula import Formula, Term
from gyrojax.sweeps import Dac, RateTable, VcfStatic


def test_bh_q_values_by_hand():
    p = np.array([0.01, 0.04, 0.03, 0.005])
    # sorted 0.005, 0.01, 0.03, 0.04 -> x 4/rank: 0.02, 0.02, 0.04, 0.04 (monotone from the top)
    assert np.allclose(bh_q_values(p), [0.02, 0.04, 0.04, 0.02])
    assert bh_q_values([]).size == 0 and bh_q_values([0.9, 0.95]).max() <= 1.0
    assert selection_p(6e-4, 9) == pytest.approx(5.4e-3) and selection_p(0.5, 9) == 1.0


def _formula(*terms, coefficients, complete=True):
    n = len(terms)
    return Formula(tuple(terms), np.asarray(coefficients, float), np.full(n, 1e-7), 100.0, n, 0.9, 40,
                   1.0, 1, 0.3, complete)


GAIN_T = Term("lin(temperature_c)*model", (VcfStatic(),), "output * ((T - 25.0))", True, {}, "1/K",
              "temperature_c")
STEP = Term("step(time_s)", (RateTable(),), "(where(t >= 1440, 1, 0))", False, {}, "LSB", "time_s")


def _load(text, tmp_path):
    path = tmp_path / "drafted.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("drafted_test_module", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_drafted_term_is_nested_at_zero_and_acts_only_where_it_was_found(tmp_path):
    text = draft_effect_source(_formula(GAIN_T, STEP, coefficients=[2e-5, 13.0]), name="drafted_check")
    module = _load(text, tmp_path)
    cls = module.DraftedCheck
    gyro = gj.paper_qmg()
    at = dict(input=jnp.asarray(1.0), temperature=jnp.asarray(35.0), time=jnp.asarray(2000.0))
    vcf, rate = gj.PointConditions("vcf_static", **at), gj.PointConditions("rate_table", **at)
    zero = cls(jnp.zeros(2))
    assert float(zero(gyro, 1000.0, vcf)) == 1000.0 and float(zero(gyro, 1000.0, rate)) == 1000.0
    typical = cls.typical()
    assert float(typical(gyro, 1000.0, vcf)) == pytest.approx(1000.0 * (1 + 2e-5 * 10.0))
    assert float(typical(gyro, 1000.0, rate)) == pytest.approx(1013.0)
    early = gj.PointConditions("rate_table", input=jnp.asarray(1.0), temperature=jnp.asarray(35.0),
                               time=jnp.asarray(100.0))
    assert float(typical(gyro, 1000.0, early)) == 1000.0


def test_a_draft_is_refused_where_a_readout_term_cannot_hold_it(tmp_path):
    with pytest.raises(DraftError, match="leaves part of the located misfit unexplained"):
        draft_effect_source(_formula(GAIN_T, coefficients=[1e-5], complete=False))
    dac = Term("cube(input)", (Dac(),), "(x**3)", False, {}, "V/LSB^3", "input")
    with pytest.raises(DraftError, match="acts on the dac sweep, which is not read through the readout"):
        draft_effect_source(_formula(dac, coefficients=[1e-12]))
    freq = Term("lin(drive_freq_hz)*model", (RateTable(),), "output * (f)", True, {}, "1/Hz", "drive_freq_hz")
    with pytest.raises(DraftError, match="drive-frequency reading, the run or the rate"):
        draft_effect_source(_formula(freq, coefficients=[1e-6]))
    with pytest.raises(DraftError, match="lower-case Python identifier"):
        draft_effect_source(_formula(GAIN_T, coefficients=[1e-5]), name="Bad Name")
    with pytest.raises(DraftError, match="ending in .py"):
        write_draft(_formula(GAIN_T, coefficients=[1e-5]), tmp_path / "draft.txt")
    assert not (tmp_path / "draft.txt").exists()
