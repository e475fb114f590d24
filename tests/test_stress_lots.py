"""The stress lots (experiments/stress_benchmark.py): the discovery benchmark's lots with the noise replaced
(heavy-tailed, heteroscedastic, correlated) or sweeps and devices left out, scored as the benchmark scores."""

import os
import sys

import numpy as np
import pytest


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))


def test_stress_lots_replace_the_noise_and_keep_what_the_sweeps_can_see():
    from _discovery_lot import discovery_lot, noise_free
    from stress_benchmark import stress_lot

    t3, info = stress_lot("t3", None, snr="mid", design="a", seed=0)
    truth, sigma = noise_free("a", 0, 6, 2)
    z = (np.asarray(t3.columns["output"]) - truth) / sigma
    force = np.asarray(t3.columns["sweep"]) != "dac"
    assert 0.6 < np.mean(z[force] ** 2) < 1.6 and np.abs(z[force]).max() > 4.5  # unit variance, heavy tails
    null, _ = discovery_lot(None, snr="mid", design="a", seed=0)
    assert not np.allclose(z[force], ((np.asarray(null.columns["output"]) - truth) / sigma)[force])
    only, info = stress_lot("rate_only", "vcf_gain_tempco", snr="mid", design="a", seed=0)
    assert set(np.unique(only.columns["sweep"])) == {"rate_table"} and info["hidden"] is None
    kept, info = stress_lot("no_dac", "zro_tempco", snr="mid", design="a", seed=0)
    assert info["hidden"] == "zro_tempco" and info["visible_sweeps"] == ["rate_table", "vcf_static"]
    bare, _ = stress_lot("no_sigma", None, snr="mid", design="a", seed=0)
    assert "output_sigma" not in bare.columns
    np.testing.assert_array_equal(bare.columns["output"], null.columns["output"])
    with pytest.raises(ValueError, match="unknown variant 'gauss'"):
        stress_lot("gauss", None, snr="mid", design="a", seed=0)


@pytest.mark.slow
def test_a_compression_under_correlated_noise_is_not_refused_for_want_of_a_direction_of_its_own():
    # noise correlated along the sweep leaves a misfit along the input that differs from run to run; with it and a
    # bias linear in time (the probe) both beside the compression, nothing of the compression's own direction was
    # left, it "added nothing beyond the probe (S = 0, df 0)" and a DAC INL was confirmed in its place
    from stress_benchmark import stress_lot

    import gyrojax as gj

    table, _ = stress_lot("ar1", "feedback_compression", snr="mid", design="b", seed=0)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert d.selected == ("feedback_compression",)
    assert not any("df 0" in r.reason for r in d.rejected)


def test_an_unknown_variant_on_the_command_line_is_named_with_the_ones_there_are():
    from stress_benchmark import main

    with pytest.raises(SystemExit, match="--variants: unknown gauss; expected some of t3, hetero, ar1"):
        main(["--variants", "gauss", "--out", os.devnull])
