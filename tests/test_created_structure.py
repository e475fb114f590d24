"""A library effect fitted where it is not leaves its shape, reversed, on a sweep that does not have it: the
refit's residuals show structure the residuals before it did not, and the step is refused ("contradicted by"
that sweep). A rate-only saturation at high SNR on design b is the case (the independent NumPy generator,
`experiments/_discovery_lot.py`): a DAC INL fitted to it writes an odd cubic on the DAC bench."""

import os
import sys
import types

import pytest

import gyrojax as gj
from gyrojax._diagnose.compare import Finding
from gyrojax._diagnose.guards import new_structure


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


def _finding(sweep, test, p, flagged, coordinate="input"):
    return Finding(sweep=sweep, test=test, statistic=0.0, df=1, p_value=p, flagged=flagged, meaning="",
                   coordinate=coordinate)


def _comparison(*findings):
    return types.SimpleNamespace(findings=findings, flagged=tuple(f for f in findings if f.flagged))


def test_only_structure_absent_before_the_refit_is_new():
    before = _comparison(_finding("dac", "odd cubic", 0.4, False), _finding("rate_table", "odd cubic", 1e-9, True),
                         _finding("vcf_static", "trend", 0.004, False))
    after = _comparison(_finding("dac", "odd cubic", 5e-5, True),  # absent before: new
                        _finding("rate_table", "odd cubic", 1e-5, True),  # there before, not all taken: not new
                        _finding("vcf_static", "trend", 1e-5, True),  # nominally significant before: not new
                        _finding("dac", "trend", 0.3, False))
    assert [(f.sweep, f.test) for f in new_structure(before, after, alpha=0.01)] == [("dac", "odd cubic")]
    # the same test along another coordinate is another finding
    after = _comparison(_finding("dac", "odd cubic", 5e-5, True, coordinate="time_s"))
    assert new_structure(before, after, alpha=0.01) == ()  # never tested before: not evidence of a new shape
    assert new_structure(before, _comparison(), alpha=0.01) == ()


@pytest.mark.slow
def test_an_inl_fitted_to_a_rate_only_saturation_is_refused_by_the_dac_bench():
    table, info = discovery_lot("rate_saturation", snr="high", design="b", seed=1)
    assert info["look_alike_chi2"]["dac_inl"] > 9.0  # noise-free, the DAC bench tells them apart (4.3 sigma)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert "dac_inl" not in d.selected and d.verdict == "unexplained", d.summary()
    (why,) = [r for r in d.rejected if r.effect == "dac_inl"]
    assert why.kind == "contradicted by dac" and why.contradicted_by == ("dac",)
    assert "absent before it" in why.reason
    # what is left is placed on the rate table along the input, with the saturation's closed form
    top = d.discrepancy[0]
    assert top.coordinate == "input" and set(top.located_on) == {"rate_table"}
    assert "hinge(input)" in {t.name for t in d.formula.terms}
