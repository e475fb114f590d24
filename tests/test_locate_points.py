"""Narrow misfits are located as what they are: one point of one device off the model (an outlier) or an error at
one input value in every device (a missing code), each with its own look-elsewhere correction
(`gyrojax._diagnose.descriptions._point_scans`), not as a step, a periodic error or a smooth curve."""

import os
import sys

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._diagnose.locate import locate


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


def _with(seed, change):
    """A null lot of the independent generator with `change(columns)` applied to its outputs."""
    table, _ = discovery_lot(None, snr="mid", design="a", seed=seed)
    cols = {k: np.array(v) for k, v in table.columns.items()}
    info = change(cols)
    return gj.Table.from_columns(cols, source="<narrow misfit>"), info


def _glitch(seed, sigmas=12.0, sweep="rate_table"):
    def change(cols):
        rows = np.flatnonzero(cols["sweep"] == sweep)
        k = int(np.random.default_rng(seed).choice(rows))
        cols["output"][k] += sigmas * cols["output_sigma"][k]
        return {"device": str(cols["device"][k]), "run": int(cols["run"][k]), "input": float(cols["input"][k]),
                "time_s": float(cols["time_s"][k]), "size": sigmas * float(cols["output_sigma"][k])}
    return _with(seed, change)


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow)])
def test_a_glitch_is_one_point_of_one_device(seed):
    table, glitch = _glitch(seed)
    first = locate(gj.identify("paper-qmg", table, progress=False)).locations[0]
    assert first.family == "single point" and first.coordinate == "point"
    assert first.location["runs"] == [[glitch["device"], glitch["run"]]]
    assert first.location["point"]["input"] == glitch["input"]
    assert first.location["point"]["time_s"] == glitch["time_s"]
    # the run bias takes 1/22 of it; the rest is the size, within its standard error
    assert first.size is not None and first.size["unit"] == "LSB"
    assert abs(first.size["value"] - glitch["size"]) < 3 * first.size["stderr"] + 0.1 * glitch["size"]


def test_an_error_at_one_dac_word_in_every_device_is_at_one_input():
    def change(cols):
        dac = cols["sweep"] == "dac"
        word = np.unique(cols["input"][dac])[7]
        at = dac & (cols["input"] == word)
        cols["output"][at] += 8.0 * cols["output_sigma"][at]  # a code that reads 8 voltmeter sigma high
        return float(word)
    table, word = _with(0, change)
    first = locate(gj.identify("paper-qmg", table, progress=False)).locations[0]
    assert (first.family, first.coordinate) == ("at one input", "input")
    assert first.location["at"] == word
    assert first.located_on == ("dac",)


@pytest.mark.slow
def test_no_narrow_misfit_is_found_in_null_lots():
    # the scans' look-elsewhere corrections (points, input values) hold on lots with nothing hidden
    for seed in (0, 1):
        table, _ = discovery_lot(None, snr="mid", design="a", seed=seed)
        found = locate(gj.identify("paper-qmg", table, progress=False)).locations
        assert not [f for f in found if f.family in ("single point", "at one input")]


@pytest.mark.slow
def test_a_glitch_confirms_nothing_and_gets_no_formula():
    table, glitch = _glitch(1)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert d.selected == ()
    assert d.remaining[0].family == "single point" and d.formula is None
    text = d.verdict_text()
    assert "a single point off the model" in text and f"time_s {glitch['time_s']:.4g}" in text
    out = d.to_json()
    assert out["discrepancy"][0]["location"]["point"]["input"] == glitch["input"]
