"""`gyrojax.coverage` (issue 38 point 3): the coverage audit of a fit's 95 % intervals by simulated draws refitted in
one vmapped identify; its refusals."""

import jax
import numpy as np
import pytest

import gyrojax as gj
from gyrojax._identify.coverage import simulated_data


@pytest.fixture(scope="module")
def fit():
    table = gj.simulate_table(gj.paper_qmg(), devices=2, runs=1, sweeps=("rate_table", "vcf_static"), seed=21,
                              progress=False)
    return gj.identify("paper-qmg", table, progress=False)


def test_draws_are_the_fit_plus_the_data_noise(fit):
    """The simulated outputs scatter about the fitted predictions plus run biases with the points' sigmas."""
    data = simulated_data(fit, 200, jax.random.PRNGKey(1))
    assert len(data.devices) == 400 and data.devices[2] == f"{fit.devices[0]}#1"
    b, b0 = data.blocks["rate_table"], fit.data.blocks["rate_table"]
    mean = np.asarray(fit.predictions["rate_table"]) + np.asarray(fit.biases["rate_table"])[..., None]
    z = (np.asarray(b.outputs).reshape((200,) + mean.shape) - mean) / np.asarray(b0.sigmas)
    z = z[:, np.asarray(b0.mask)]
    assert abs(z.mean()) < 0.05 and abs(z.std() - 1) < 0.05


@pytest.mark.slow
def test_coverage_of_a_right_model_is_near_95_percent(fit):
    """40 draws of 2 devices: k_vf, vcf_gain and the scale factor each cover in 80 intervals; the coverage within
    4 binomial standard errors (2.4 %) of 95 % and z RMS near 1."""
    audit = gj.coverage(fit, draws=40, seed=3)
    print("\n" + audit.summary())
    assert audit.failed == 0
    assert {"k_vf", "vcf_gain", "scale_factor"} <= set(audit.names)
    for name, c, k, z in zip(audit.names, audit.coverage, audit.count, audit.z_rms):
        assert k == 80
        assert abs(c - 0.95) < 4 * np.sqrt(0.95 * 0.05 / k), (name, c)
        assert 0.75 < z < 1.3, (name, z)
    assert set(audit.report()["intervals"]) == set(audit.names)


def test_coverage_refuses_what_it_cannot_audit(fit):
    with pytest.raises(ValueError, match="draws must be an integer >= 2"):
        gj.coverage(fit, draws=1)
    with pytest.raises(TypeError, match="coverage needs a gyrojax.Fit"):
        gj.coverage("fit.json")


@pytest.mark.slow
def test_coverage_with_a_dac_inl_fitted():
    """The demo's lot (3 paper-qmg devices x 2 runs, rate table, static VCF and DAC sweeps, seed 7, a typical DAC
    INL hidden) fitted with the INL added from zero: over 40 draws every reported interval (k_vf, vcf_gain, the
    DAC gain error, the INL coefficients the data fix, the scale factor) covers within 4 binomial standard errors
    (8 %) of 95 %, z RMS near 1 (experiments/coverage_audit.py, 3 x 100 draws: 93.8-95.0 % of 900 each)."""
    table = gj.simulate_table(gj.add_effect(gj.paper_qmg(), "dac_inl"), devices=3, runs=2,
                              sweeps=("rate_table", "vcf_static", "dac"), seed=7, progress=False)
    fit = gj.identify(gj.Model(gj.paper_qmg(), (gj.effect("dac_inl", 0.0),)), table, progress=False)
    audit = gj.coverage(fit, draws=40, seed=5)
    print("\n" + audit.summary())
    assert audit.failed == 0
    assert any(n.startswith("dac_inl.coefficients") for n in audit.names) and "scale_factor" in audit.names
    for name, c, k, z in zip(audit.names, audit.coverage, audit.count, audit.z_rms):
        assert k == 120, (name, k)
        assert abs(c - 0.95) < 4 * np.sqrt(0.95 * 0.05 / k), (name, c)
        assert 0.8 < z < 1.25, (name, z)
