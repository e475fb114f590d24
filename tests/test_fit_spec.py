"""`FitSpec`: how a fit is made, given whole to identify, diagnose and plan, reaches every fit they make."""

import importlib

import pytest

import gyrojax as gj
from gyrojax._cli.demo_job import DEMO_LOT


identify_module = importlib.import_module("gyrojax._identify.identify")  # the module, not the function it exports


class _Stop(Exception):
    pass


@pytest.fixture(scope="module")
def small_table():
    return gj.simulate_table(gj.paper_qmg(), devices=2, runs=1, sweeps=("rate_table",), seed=0, progress=False)


def _spy_solvers(monkeypatch, stop: bool):
    """Record the solver (and tolerances) of every fit `identify` composes; with `stop`, stop at the first."""
    seen = []
    original = identify_module.solver_from

    def spy(solver, rtol, atol):
        seen.append((solver, rtol, atol))
        if stop:
            raise _Stop
        return original(solver, rtol, atol)

    monkeypatch.setattr(identify_module, "solver_from", spy)
    return seen


def test_a_solver_choice_given_to_diagnose_reaches_its_baseline_fit(monkeypatch, small_table):
    seen = _spy_solvers(monkeypatch, stop=True)
    with pytest.raises(_Stop):
        gj.diagnose("paper-qmg", small_table, spec=gj.FitSpec(solver="gauss-newton", rtol=1e-6), progress=False)
    assert seen == [("gauss-newton", 1e-6, 1e-8)]


def test_a_solver_choice_given_to_plan_reaches_its_baseline_fit(monkeypatch, small_table):
    seen = _spy_solvers(monkeypatch, stop=True)
    with pytest.raises(_Stop):
        gj.plan("paper-qmg", small_table, spec=gj.FitSpec(solver="bfgs"), scale_factor=False, progress=False)
    assert seen == [("bfgs", 1e-8, 1e-8)]


def test_identify_takes_the_spec_whole(monkeypatch, small_table):
    seen = _spy_solvers(monkeypatch, stop=True)
    with pytest.raises(_Stop):
        gj.identify("paper-qmg", small_table, spec=gj.FitSpec(solver="gauss-newton", atol=1e-7), progress=False)
    assert seen == [("gauss-newton", 1e-8, 1e-7)]


@pytest.mark.parametrize("verb", ["identify", "diagnose", "plan"])
def test_a_fit_setting_given_twice_is_refused(verb, small_table):
    spec = gj.FitSpec(solver="gauss-newton")
    with pytest.raises(ValueError, match=rf"{verb}: free given as keyword\(s\) beside spec"):
        if verb == "identify":
            gj.identify("paper-qmg", small_table, spec=spec, free=("k_vf",), progress=False)
        elif verb == "diagnose":
            gj.diagnose("paper-qmg", small_table, spec=spec, free=("k_vf",), progress=False)
        else:
            gj.plan("paper-qmg", small_table, spec=spec, free=("k_vf",), progress=False)


def test_spec_must_be_a_fit_spec(small_table):
    with pytest.raises(TypeError, match="diagnose: spec must be a gyrojax.FitSpec, got dict"):
        gj.diagnose("paper-qmg", small_table, spec={"solver": "bfgs"}, progress=False)


@pytest.mark.parametrize("field,value,match", [
    ("max_steps", 0, "max_steps must be an integer >= 1, got 0"),
    ("reject_alpha", 1.5, r"reject_alpha must be a significance level in \(0, 1\), got 1.5"),
    ("start", 3, "start must be a gyrojax.MultiStart, got int"),
    ("recovery", gj.RestartRunoffs(), "recovery must be a tuple of gyrojax.AbstractRecovery policies"),
])
def test_fit_spec_checks_its_fields(field, value, match):
    with pytest.raises((ValueError, TypeError), match=match):
        gj.FitSpec(**{field: value})


@pytest.mark.slow
def test_every_fit_of_a_diagnosis_uses_the_spec_solver(monkeypatch):
    """The baseline and every refit (the hidden dac_inl is refitted and confirmed) use the spec's solver."""
    table = gj.simulate_table(gj.add_effect(gj.paper_qmg(), "dac_inl"), **DEMO_LOT)
    seen = _spy_solvers(monkeypatch, stop=False)
    d = gj.diagnose("paper-qmg", table, spec=gj.FitSpec(solver="gauss-newton"), progress=False)
    assert "dac_inl" in d.selected
    assert len(seen) >= 2 and all(s == "gauss-newton" for s, _, _ in seen), seen


def test_diagnose_holds_its_candidates_on_top_of_the_spec_hold(monkeypatch, small_table):
    candidates = importlib.import_module("gyrojax._diagnose.candidates")
    given = []

    def stop(model, data, **kwargs):
        given.append(kwargs["spec"])
        raise _Stop

    monkeypatch.setattr(candidates, "identify", stop)
    spec = gj.FitSpec(hold=("q_y",), recovery=())
    with pytest.raises(_Stop):
        gj.diagnose("paper-qmg", small_table, candidates=("dac_inl", "thermal_drift"), spec=spec, progress=False)
    (used,) = given
    assert used.hold == ("q_y", "dac_inl", "thermal_drift")
    assert used.recovery == () and used.free == spec.free
