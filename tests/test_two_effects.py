"""Two hidden effects at once (experiments/two_effect_benchmark.py): a library effect beside a misfit of another
shape is confirmed, and the other misfit is left where it lives. The guards read beyond the other misfit: a probe
more flexible than the candidate, a flexible description made before the refit that spans the candidate, and a
rival formula with a term for the other misfit each refused the tempco in these lots before."""

import os
import sys

import pytest

import gyrojax as gj


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from two_effect_benchmark import score, two_effect_lot  # noqa: E402


@pytest.mark.slow
@pytest.mark.parametrize("other, design, coordinate", [("bias_step", "c", "time_s"), ("per_run_gain", "a", "run")])
def test_a_tempco_beside_another_misfit_is_confirmed_and_the_other_left_where_it_lives(other, design, coordinate):
    d = gj.diagnose("paper-qmg", two_effect_lot("zro_tempco", other, snr="mid", design=design, seed=0),
                    progress=False)
    assert d.selected == ("zro_tempco",)
    assert d.remaining[0].coordinate == coordinate
    assert score(d, "zro_tempco", other) == {"libraries": 1, "found": 1, "wrong": False, "outside_located": True}


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
