"""Two hidden effects at once (experiments/two_effect_benchmark.py): a library effect beside a misfit of another
shape located apart is confirmed, and the other misfit is left where it lives. The guards read beyond it: a probe
more flexible than the candidate, a spline along its own coordinate and a rival formula with a term for the other
misfit each refused the tempco here before."""

import os
import sys

import pytest

import gyrojax as gj


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from two_effect_benchmark import score, two_effect_lot  # noqa: E402


@pytest.mark.slow
def test_a_tempco_beside_a_bias_step_is_confirmed_and_the_step_left_on_time():
    d = gj.diagnose("paper-qmg", two_effect_lot("zro_tempco", "bias_step", snr="mid", design="c", seed=0),
                    progress=False)
    assert d.selected == ("zro_tempco",)
    left = d.remaining[0]
    assert left.coordinate == "time_s" and left.located_on == ("rate_table",)
    assert score(d, "zro_tempco", "bias_step") == {"libraries": 1, "found": 1, "wrong": False,
                                                   "outside_located": True}


def test_the_pair_lot_adds_both_effects_to_the_same_noise():
    import numpy as np

    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
    from _discovery_lot import discovery_lot

    pair = two_effect_lot("zro_tempco", "bias_step", snr="mid", design="a", seed=1)
    null, _ = discovery_lot(None, snr="mid", design="a", seed=1)
    a, _ = discovery_lot("zro_tempco", snr="mid", design="a", seed=1)
    b, _ = discovery_lot("bias_step", snr="mid", design="a", seed=1)
    expected = (np.asarray(a.columns["output"]) + np.asarray(b.columns["output"])
                - np.asarray(null.columns["output"]))
    np.testing.assert_allclose(np.asarray(pair.columns["output"]), expected, rtol=0, atol=1e-9)
    assert not np.array_equal(np.asarray(pair.columns["output"]), np.asarray(a.columns["output"]))
