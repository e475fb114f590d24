"""The candidate effects that diagnose and plan test: one check for both, before anything is fitted."""

import pytest

import gyrojax as gj
from gyrojax._diagnose import candidate_effects
from gyrojax._model.parameters import Model, as_model, zero_effect


def test_default_candidates_are_the_supported_effects_not_in_the_baseline():
    base = as_model("paper-qmg")
    everything = candidate_effects(base, None, "diagnose")
    assert everything[0] == "dac_inl" and len(everything) == 10 and set(everything) <= set(gj.EFFECTS)
    held = Model(base.device, (zero_effect("dac_inl"),))
    assert candidate_effects(held, None, "plan") == everything[1:]
    assert candidate_effects(base, ["thermal_drift", "dac_inl"], "plan") == ("thermal_drift", "dac_inl")


@pytest.mark.parametrize("who", ["diagnose", "plan"])
def test_bad_candidates_are_refused_in_the_callers_words(who):
    base = Model(as_model("paper-qmg").device, (zero_effect("dac_inl"),))
    with pytest.raises(ValueError, match="unknown candidate effect 'dac-inl'; expected names of gyrojax.EFFECTS"):
        candidate_effects(base, ("dac-inl",), who)
    with pytest.raises(ValueError, match=f"'dac_inl' is already fitted in the baseline; {who} tests the others"):
        candidate_effects(base, ("dac_inl",), who)
    with pytest.raises(ValueError, match=f"^{who} needs at least one candidate effect not already in the model"):
        candidate_effects(base, (), who)
