"""nonlinearity_budget: per-effect nonlinearity, shares of the stack-up, gradients against differences."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj
from gyrojax import Model


RATES = (-200.0, -50.0, -5.0, 5.0, 50.0, 200.0)  # a few of seed 000's rates: one compiled shape for the file


@pytest.fixture(scope="module")
def gyro():
    return gj.paper_qmg()


@pytest.fixture(scope="module")
def budget(gyro):
    # pushpull_mismatch at 30x its typical size: alone it is (nearly) a pure gain change, but it moves the
    # DAC word and so interacts with the INL
    return gj.nonlinearity_budget(gyro, [gj.effect("dac_inl", 1.0), gj.effect("pushpull_mismatch", 30.0)],
                                  rates_dps=RATES)


@pytest.mark.slow
def test_joint_matches_a_direct_simulation(gyro, budget):
    g = gj.add_effect(gj.add_effect(gyro, "dac_inl", 1.0), "pushpull_mismatch", 30.0)
    out = gj.rate_sweep(g, jnp.asarray(RATES) * gj.units.DEG).rate
    fit = gj.fit_scale_factor(np.asarray(RATES), np.asarray(out))
    assert budget.joint_max_ppm == pytest.approx(float(fit.nonlinearity_max_ppm), rel=1e-6)
    assert budget.joint_rms_ppm == pytest.approx(float(fit.nonlinearity_rms_ppm), rel=1e-6)
    # the INL dominates: hundreds of ppm (seed 000's DAC stage: 460.679 ppm on its 22 rates)
    assert 100.0 < budget.joint_max_ppm < 2000.0


@pytest.mark.slow
def test_shares_are_consistent(budget):
    dac, pp = budget.effects
    assert (dac.name, pp.name) == ("dac_inl", "pushpull_mismatch")
    for e in budget.effects:
        assert e.own_max_ppm == pytest.approx(np.max(np.abs(budget.residual_ppm[e.name] - budget.residual_ppm["base"])))
    # the ideal FTR loop is linear: the base carries (almost) no nonlinearity, so the INL's own curve is its alone
    assert budget.base_max_ppm < 1e-2
    assert dac.own_max_ppm == pytest.approx(dac.alone_max_ppm, abs=2e-2)
    # joint = base + sum of own curves + interaction, and the interaction is what the report says
    gap = budget.residual_ppm["joint"] - budget.residual_ppm["base"] - dac.own_residual_ppm - pp.own_residual_ppm
    assert budget.interaction_ppm == pytest.approx(np.max(np.abs(gap)))
    # the push-pull gain change moves the word, so the two interact: the joint figure is not the DAC's alone
    assert budget.interaction_ppm > 1.0
    assert abs(budget.joint_max_ppm - dac.own_max_ppm) > 1.0
    # shares are of the stack-up (base + own maxima + interaction): each between 0 and 100 %, adding to 100 %,
    # and the joint max is at most the stack-up
    stack = budget.base_max_ppm + dac.own_max_ppm + pp.own_max_ppm + budget.interaction_ppm
    assert budget.stack_ppm == pytest.approx(stack)
    assert budget.joint_max_ppm <= stack
    for e in budget.effects:
        assert e.share_pct == pytest.approx(100.0 * e.own_max_ppm / stack)
        assert 0.0 <= e.share_pct <= 100.0
    assert budget.interaction_share_pct == pytest.approx(100.0 * budget.interaction_ppm / stack)
    total = budget.base_share_pct + dac.share_pct + pp.share_pct + budget.interaction_share_pct
    assert total == pytest.approx(100.0, abs=1e-9)


@pytest.mark.slow
def test_table_says_what_the_shares_are_of(gyro):
    # pushpull_mismatch at its typical size does not bend the curve (its own figure is round-off, ~1e-10 ppm)
    # but moves the word the INL acts at: the INL's own max is above the joint max, so seed 000's ratio
    # (own / joint) would exceed 100 %; the stack-up shares do not, and round-off reads "< 0.001"
    b = gj.nonlinearity_budget(gyro, [gj.effect("dac_inl", 1.0), gj.effect("pushpull_mismatch", 1.0)],
                               rates_dps=RATES, gradients=False)
    dac, pp = b.effects
    assert pp.own_max_ppm < 1e-6 and b.interaction_ppm > 1e-3
    assert dac.own_max_ppm > b.joint_max_ppm  # own / joint > 100 %
    assert 99.0 < dac.share_pct < 100.0
    text = b.table()
    rows = {line.split()[0]: line for line in text.splitlines()[2:]}
    assert rows["pushpull_mismatch"].count("< 0.001") == 4  # alone, own max, own rms, share
    assert rows["base"].count("< 0.001") == 4
    assert f"{dac.share_pct:8.3f}" in rows["dac_inl"] and "100." not in rows["dac_inl"]
    assert f"{b.interaction_ppm:9.3f}" in rows["interaction"]
    assert "% stack" in text and f"{b.stack_ppm:.3f} ppm" in text
    assert b.to_json()["stack_ppm"] == pytest.approx(b.stack_ppm)


def test_one_effect_has_the_whole_share_and_scales(gyro):
    full = gj.nonlinearity_budget(gyro, [gj.effect("dac_inl", 1.0), gj.effect("pushpull_mismatch", 0.0)],
                                  rates_dps=RATES, gradients=False)
    half = gj.nonlinearity_budget(gyro, [gj.effect("dac_inl", 0.5), gj.effect("pushpull_mismatch", 0.0)],
                                  rates_dps=RATES, gradients=False)
    assert full.effects[0].share_pct == pytest.approx(100.0, abs=1e-2)
    assert full.effects[1].own_max_ppm == 0.0 and full.interaction_ppm < 1e-6
    # the describing function is linear in the INL coefficients: half the INL, half the nonlinearity
    assert half.joint_max_ppm / full.joint_max_ppm == pytest.approx(0.5, rel=1e-2)


@pytest.mark.slow
def test_gradients_against_finite_differences(gyro, budget):
    effs = [gj.effect("dac_inl", 1.0), gj.effect("pushpull_mismatch", 30.0)]

    def joint(g, e=effs):
        return gj.nonlinearity_budget(g, e, rates_dps=RATES, gradients=False).joint_max_ppm

    h = 1e-4
    k = float(gyro.feedback_electrode.k_vf)
    up = joint(eqx.tree_at(lambda g: g.feedback_electrode.k_vf, gyro, k * (1 + h)))
    down = joint(eqx.tree_at(lambda g: g.feedback_electrode.k_vf, gyro, k * (1 - h)))
    fd = (up - down) / (2 * h)
    assert abs(budget.relative_gradient["k_vf"]) > 10.0  # a 1 % K_vf change moves the word and the NL
    assert budget.relative_gradient["k_vf"] == pytest.approx(fd, rel=2e-3)
    assert budget.gradient["k_vf"] * k == pytest.approx(budget.relative_gradient["k_vf"])

    c = np.asarray(effs[0].coefficients, dtype=float)
    step = 1e-3 * max(abs(c[1]), 1e-3)

    def with_c1(v):
        return [eqx.tree_at(lambda e: e.coefficients, effs[0], jnp.asarray(c).at[1].set(v)), effs[1]]

    fd_c = (joint(gyro, with_c1(c[1] + step)) - joint(gyro, with_c1(c[1] - step))) / (2 * step)
    assert budget.gradient["dac_inl.coefficients"][1] == pytest.approx(fd_c, rel=2e-3)
    # every physical parameter of the catalogue that the closed-loop device has is there
    assert {"k_vf", "omega_x", "angular_gain", "mass"} <= set(budget.gradient)
    assert "sense_gain" not in budget.gradient  # open-loop only


@pytest.mark.slow
def test_model_input_and_errors(gyro):
    model = Model(gyro, (gj.effect("dac_inl", 1.0), gj.effect("pushpull_mismatch", 0.0)))
    b = gj.nonlinearity_budget(model, rates_dps=RATES, gradients=False)
    assert [e.name for e in b.effects] == ["dac_inl"]  # the zero effect is not active
    with pytest.raises(ValueError, match="unknown effect 'nope'"):
        gj.nonlinearity_budget(gyro, ["nope"], rates_dps=RATES)
    with pytest.raises(ValueError, match="more than once"):
        gj.nonlinearity_budget(gyro, ["dac_inl", "dac_inl"], rates_dps=RATES)
    with pytest.raises(ValueError, match="no active"):
        gj.nonlinearity_budget(gyro, rates_dps=RATES)
    with pytest.raises(ValueError, match="rates_dps must be at least 3"):
        gj.nonlinearity_budget(gyro, ["dac_inl"], rates_dps=(1.0, 2.0))
    with pytest.raises(ValueError, match="cannot act on device"):
        gj.nonlinearity_budget(gj.vcf_2018(), ["dac_inl"], rates_dps=RATES)
    lot = gj.make_lot(gyro, 2, __import__("jax").random.key(0))
    with pytest.raises(ValueError, match="pass device=INDEX"):
        gj.nonlinearity_budget(Model(lot, ()), ["dac_inl"], rates_dps=RATES)
