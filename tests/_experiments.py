"""Load a script of experiments/ as a module, for the tests that run it at a small size."""

import importlib.util
import pathlib


EXPERIMENTS = pathlib.Path(__file__).parent.parent / "experiments"


def load_experiment(name: str):
    spec = importlib.util.spec_from_file_location(name, EXPERIMENTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def discovery_diagnosis(hidden: str, *, design: str, seed: int, snr: str = "mid"):
    """The diagnosis, from the plain preset, of the independent generator's lot (experiments/_discovery_lot.py,
    plain NumPy) with `hidden` hidden."""
    import sys

    import gyrojax as gj

    if str(EXPERIMENTS) not in sys.path:
        sys.path.insert(0, str(EXPERIMENTS))  # the generator imports its siblings
    from _discovery_lot import discovery_lot

    table, _ = discovery_lot(hidden, snr=snr, design=design, seed=seed)
    return gj.diagnose("paper-qmg", table, progress=False)
