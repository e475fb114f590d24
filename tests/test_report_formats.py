"""The reporting wing (gyrojax/_report): every result is an `AbstractResult` (a `kind`, a JSON-safe `to_json()`,
a `summary()`), and an output format is one object in one registry, written by `write_result` and by the command
line's `--out FILE [--format NAME]`."""

import csv
import io
import json
import typing

import numpy as np
import pytest

import gyrojax as gj
from gyrojax.cli import main
from gyrojax.identification import IdentifyReport
from gyrojax.io import FORMATS, AbstractFormat, AbstractResult, register_format, write_result


# The verbs whose return values are results; their return annotations name the result types.
VERBS = (gj.identify, gj.diagnose, gj.plan, gj.rate_table_plan, gj.compensate, gj.metrics.metrics_report)


def _returned_types():
    types = []
    for verb in VERBS:
        hint = typing.get_type_hints(verb)["return"]
        types += list(typing.get_args(hint)) or [hint]
    return types


def test_every_verbs_result_type_declares_the_result_contract():
    types = _returned_types() + [IdentifyReport]
    names = {t.__name__ for t in types}
    assert names >= {"Fit", "PopulationFit", "Diagnosis", "Plan", "RateTablePlan", "CompensationResult",
                     "MetricsReport", "IdentifyReport"}, names
    kinds = []
    for t in types:
        assert isinstance(getattr(t, "kind", None), str), f"{t.__name__} has no kind name"
        assert callable(getattr(t, "to_json", None)) and callable(getattr(t, "summary", None)), t.__name__
        kinds.append(t.kind)
    assert len(set(kinds)) == len(kinds), kinds  # a kind names one type


def _round_trips(result):
    assert isinstance(result, AbstractResult)
    form = result.to_json()
    assert json.loads(json.dumps(form, allow_nan=False)) == form  # plain JSON: no NaN, no NumPy scalars
    text = result.summary()
    assert isinstance(text, str) and text.strip()
    return form


def _rate_table(runs=2):
    rates = np.array([-200.0, -100.0, -10.0, 10.0, 100.0, 200.0])
    out = [13700.0 * rates + 120.0 + 0.3 * rates**2 / 200, 13701.0 * rates - 80.0 + 0.2 * rates**2 / 200][:runs]
    return gj.Table({"device": ["A"] * 6 * runs, "run": np.repeat(np.arange(runs), 6),
                     "sweep": ["rate_table"] * 6 * runs, "input": np.tile(rates, runs),
                     "output": np.concatenate(out)}, source="rates.csv")


def test_fast_results_round_trip_through_json():
    metrics = gj.metrics.metrics_report(_rate_table())
    assert isinstance(metrics, dict) and metrics["points"][0]["device"] == "A"  # still read as a dict
    assert _round_trips(metrics) == dict(metrics)
    comp = gj.compensate(_rate_table(), method="polynomial", progress=False)
    assert _round_trips(comp)["method"] == "polynomial"
    assert "repeatability over 2 runs" in comp.summary()
    rtp = gj.rate_table_plan(0.005, 0.002, devices=64)
    assert _round_trips(rtp) == rtp.report()  # the old name still works


@pytest.fixture(scope="module")
def lot():
    return gj.simulate_table(gj.paper_qmg(), devices=3, runs=1, sweeps=("rate_table", "dac"), seed=2, progress=False)


@pytest.mark.slow
def test_fitted_results_round_trip_through_json(lot):
    fit = gj.identify("paper-qmg", lot, progress=False)
    assert _round_trips(fit) == {k: v for k, v in gj.fit_report(fit).items() if k != "compare"}
    report = IdentifyReport(fit)
    assert _round_trips(report) == gj.fit_report(fit)
    assert report.summary().startswith(fit.summary() + "\n")
    diagnosis = gj.diagnose("paper-qmg", lot, fit=fit, progress=False)
    assert _round_trips(diagnosis)["verdict"] == diagnosis.verdict
    plan = gj.plan("paper-qmg", lot, fit=fit, progress=False)
    assert set(_round_trips(plan)) >= {"candidates", "scale_factor", "experiments"}
    population = gj.identify("paper-qmg", lot, lot_solve=gj.PopulationSolve(random=("k_vf",)), progress=False)
    form = _round_trips(population)
    assert form["population"] == json.loads(json.dumps(population.report())) and form["devices"]
    assert _round_trips(IdentifyReport(population.fit, population)) == {**gj.fit_report(population.fit),
                                                                        "population": form["population"]}
