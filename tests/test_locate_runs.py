"""A misfit that changes from run to run is reported with the coordinates that are constant within each run but
differ between a device's runs (`gyrojax._diagnose.locate.run_properties`): a chamber held at one temperature per
run, or stepped between runs, makes the run and that coordinate the same thing on the data."""

import os
import sys

import numpy as np

import gyrojax as gj
from gyrojax._diagnose.locate import run_properties
from gyrojax._model.fitdata import fit_data


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


def _block(table, sweep="rate_table"):
    return fit_data(table).blocks[sweep]


def test_a_temperature_held_per_run_is_a_property_of_the_runs():
    table, _ = discovery_lot(None, snr="mid", design="a", seed=0)
    cols = dict(table.columns)
    cols["temperature_c"] = np.where(np.asarray(cols["run"]) == 0, 25.0, 45.0)  # one set point per run
    names = run_properties(_block(gj.Table(cols, source="<held per run>")))
    assert "temperature_c" in names
    assert "time_s" not in names and "input" not in names  # they move within each run


def test_coordinates_that_move_within_runs_are_not():
    table, _ = discovery_lot(None, snr="mid", design="a", seed=0)  # a half-sine cycle within each run
    assert run_properties(_block(table)) == ()


def test_a_coordinate_constant_over_the_whole_device_is_not():
    # the same set point in every run tells the runs nothing apart
    table, _ = discovery_lot(None, snr="mid", design="a", seed=0)
    cols = dict(table.columns)
    device = np.asarray(cols["device"])
    cols["temperature_c"] = np.where(device == device[0], 30.0, 25.0)
    assert "temperature_c" not in run_properties(_block(gj.Table(cols, source="<held per device>")))
