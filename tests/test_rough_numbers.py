"""Numbers that are not measurements (issue 36): metrics that do not apply to a sweep kind, a sign check that
refuses what a library effect can do, one rule for a dead output, scale-invariant noise estimates, diagnose's
undetermined figures, effect sizes and verdict text."""

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._fitdata import fit_data
from gyrojax._identify.plausibility import check_signs


# ---------------------------------------------------------------------------------------------------------------
# The sign check allows what a library effect at its typical size does (the planner's revealing path).


@pytest.mark.slow
def test_sign_check_allows_a_typical_duffing_drive_on_the_drive_frequency():
    """The revealing lot of `gyrojax simulate --preset paper-qmg --sweeps rate_table,...,drive_frequency --effect
    duffing_drive --seed 13`: a cubic drive spring of typical size turns the drive frequency's slope against the
    set-point over (5.6e-8 against the design's -2.1e-8 Hz/LSB). Its sign is the effect's, not a convention's, so
    the check lets it through; a rate table read with the opposite polarity is still refused."""
    gyro = gj.add_effect(gj.preset("paper-qmg"), "duffing_drive")
    sweeps = ("rate_table", "drive_frequency")
    data = gj.simulate_table(gyro, devices=2, runs=2, sweeps=sweeps, seed=13, progress=False)
    model = gj.simulate_table(gj.preset("paper-qmg"), devices=2, runs=2, sweeps=sweeps, seed=13, noise_free=True,
                              progress=False)
    fd, predictions = fit_data(data), {s: np.asarray(model.to_arrays(s).outputs) for s in sweeps}
    check_signs(fd, predictions, "paper-qmg")
    flipped = {"rate_table": -predictions["rate_table"], "drive_frequency": predictions["drive_frequency"]}
    with pytest.raises(ValueError, match=r"opposite sign of the model 'paper-qmg'.*sweep 'rate_table', device "):
        check_signs(fd, flipped, "paper-qmg")
