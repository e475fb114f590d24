"""Load a script of experiments/ as a module, for the tests that run it at a small size."""

import importlib.util
import pathlib


EXPERIMENTS = pathlib.Path(__file__).parent.parent / "experiments"


def load_experiment(name: str):
    spec = importlib.util.spec_from_file_location(name, EXPERIMENTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
