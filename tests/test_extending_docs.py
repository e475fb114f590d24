"""The "Extending" pages (docs/extending/, and docs/adding_an_effect.md for effects) cannot rot: every page's
Python code runs as written, in order, and the `test_*` functions a page defines in its "Testing it" section are
called; every contract type a page names is importable from a public module (no private segment on the way).
Effects' page code runs in tests/test_effects.py (`test_guide_code_runs`); its names are checked here.
"""

import pathlib
import re

import pytest

import gyrojax as gj


ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGES = ROOT / "docs" / "extending"

# The contract types of each extension point: the classes a page tells a user to subclass or to read, each by a
# public path.
CONTRACTS = {
    "sweep_kind.md": ("gyrojax.sweeps.AbstractSweep", "gyrojax.sweeps.AbstractSettledSweep",
                      "gyrojax.sweeps.AbstractSteadySweep", "gyrojax.sweeps.AbstractSetpointSweep",
                      "gyrojax.sweeps.points_field", "gyrojax.sweeps.timing_field", "gyrojax.sweeps.register_sweep",
                      "gyrojax.sweeps.LotCampaign", "gyrojax.physics.Stimulus"),
    "term.md": ("gyrojax.AbstractTerm", "gyrojax.AbstractRateTerm", "gyrojax.AbstractFeedbackTerm",
                "gyrojax.AbstractOutputTerm", "gyrojax.PointConditions", "gyrojax.TemperatureCoefficient"),
    "probe.md": ("gyrojax.AbstractProbe", "gyrojax.PROBES", "gyrojax.Fit", "gyrojax.io.FitData",
                 "gyrojax.io.SweepArrays"),
    "recovery.md": ("gyrojax.AbstractRecovery", "gyrojax.identification.AbstractRecovery",
                    "gyrojax.identification.Solving", "gyrojax.identification.Solution",
                    "gyrojax.identification.Evaluation", "gyrojax.identification.result_code",
                    "gyrojax.identification.RECOVERY"),
    "compensator.md": ("gyrojax.compensation.AbstractCompensator", "gyrojax.compensation.AbstractCompensation",
                       "gyrojax.compensation.RatePoints"),
    "output_format.md": ("gyrojax.io.AbstractFormat", "gyrojax.io.AbstractResult", "gyrojax.io.register_format",
                         "gyrojax.io.write_result", "gyrojax.io.FORMATS", "gyrojax.io.atomic_write_bytes"),
    "../adding_an_effect.md": ("gyrojax.AbstractEffect", "gyrojax.effects.AbstractEffect",
                               "gyrojax.effects.register_effect"),
}

# Pages whose code fits a lot (a compile of identify): over 20 s.
SLOW = {"probe.md", "recovery.md"}

DOTTED = re.compile(r"`[^`]*?\b((?:gyrojax|gj)(?:\.\w+)+)")


def _blocks(page: pathlib.Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), flags=re.S)


def _resolve(dotted: str):
    """The object at a dotted public path (`gj.` is `gyrojax.`); an AssertionError for a private segment."""
    parts = dotted.split(".")
    assert not any(p.startswith("_") for p in parts), f"{dotted} goes through a private name"
    obj = gj
    for part in parts[1:]:
        obj = getattr(obj, part)
    return obj


def test_every_page_is_in_the_index_the_navigation_and_the_contracts():
    pages = sorted(p.name for p in PAGES.glob("*.md") if p.name != "index.md")
    assert pages == sorted(k for k in CONTRACTS if not k.startswith("..")), pages
    index = (PAGES / "index.md").read_text(encoding="utf-8")
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for name in (*pages, "../adding_an_effect.md"):
        assert f"]({name})" in index, name
    for name in ("extending/index.md", *(f"extending/{p}" for p in pages), "adding_an_effect.md"):
        assert f": {name}\n" in nav, name


@pytest.mark.parametrize("page", sorted(CONTRACTS))
def test_contract_types_are_public(page):
    text = (PAGES / page).read_text(encoding="utf-8")
    for dotted in CONTRACTS[page]:
        assert dotted.split(".")[-1] in text, f"{page} does not name {dotted}"
        obj = _resolve(dotted)
        if dotted.split(".")[-1].startswith("Abstract"):
            assert isinstance(obj, type) and getattr(obj, "__abstractmethods__", None) is not None, dotted
    # every gyrojax path the page quotes resolves through public modules
    for dotted in set(DOTTED.findall(text)):
        _resolve(dotted.rstrip("."))


def _run_page(name: str):
    page = PAGES / name
    blocks = _blocks(page)
    assert len(blocks) >= 2, f"{name}: expected the example and its test, found {len(blocks)} blocks"
    kinds, effects, formats = dict(gj.sweeps.SWEEP_KINDS), dict(gj.EFFECTS), dict(gj.io.FORMATS)
    namespace = {"__name__": f"extending_{page.stem}"}
    try:
        for block in blocks:
            exec(compile(block, str(page), "exec"), namespace)
        tests = [f for n, f in namespace.items() if n.startswith("test_") and callable(f)]
        assert tests, f"{name} defines no test_* function in its 'Testing it' section"
        for test in tests:
            test()
    finally:  # what a page registered is not left for the next test
        for registry, before in ((gj.sweeps.SWEEP_KINDS, kinds), (gj.EFFECTS, effects), (gj.io.FORMATS, formats)):
            for key in [k for k in registry if k not in before]:
                del registry[key]
    return namespace


@pytest.mark.parametrize("name", sorted(p for p in CONTRACTS if not p.startswith("..") and p not in SLOW))
def test_page_code_runs(name):
    _run_page(name)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SLOW))
def test_page_code_with_a_fit_runs(name):
    _run_page(name)

