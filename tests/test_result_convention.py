"""Results in one convention (issue 37, point 3): every result gyrojax returns, and every record type inside one,
is a final `equinox.Module` with typed fields (no record kept as a dict, no bare `tuple`/`dict` hiding what it
holds), and the package constructs them by keyword. Read from the classes' annotations and the source (`ast`)."""

import ast
import dataclasses
import importlib
import inspect
import pathlib
import types
import typing

import equinox as eqx
import pytest

import gyrojax
import gyrojax.compensation
import gyrojax.metrics


ROOT = pathlib.Path(__file__).parent.parent
PACKAGE = ROOT / "gyrojax"

# The public entry functions, each with the results it returns.
ENTRY_FUNCTIONS = (gyrojax.identify, gyrojax.diagnose, gyrojax.plan, gyrojax.compare, gyrojax.compensate,
                   gyrojax.rate_table_plan, gyrojax.metrics.metrics_report, gyrojax.nonlinearity_budget,
                   gyrojax.describe)

# Types a result holds that are no records of it: the inputs it keeps (a model, the data, a sweep kind, a timing),
# and the fitted compensations (extension points, abstract).
INPUT_TYPES = ("Model", "FitData", "Entry", "AbstractSweep", "Protocol", "AbstractCompensation")

# Not converted yet (empty: every result and record follows the convention); an entry names why.
PENDING_CLASSES: dict[str, str] = {}
PENDING_FIELDS: set[tuple[str, str]] = set()  # (class, field) not typed yet, each with why
PENDING_CALLS: set[tuple[str, str]] = set()  # (file, class) constructed positionally, each with why


def _result_classes() -> set[type]:
    """The classes the entry functions return (their return annotations), and every class in the package with a
    `kind` of `gyrojax.io.AbstractResult`."""
    out = set()
    for fn in ENTRY_FUNCTIONS:
        out |= _classes_in(typing.get_type_hints(fn)["return"])
    for cls in _all_gyrojax_classes():  # the contract of gyrojax.io.AbstractResult
        if isinstance(cls.__dict__.get("kind"), str) and callable(getattr(cls, "to_json", None)) \
                and callable(getattr(cls, "summary", None)):
            out.add(cls)
    return {c for c in out if c.__module__.startswith("gyrojax")}


def _all_gyrojax_classes() -> set[type]:
    found = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        module = importlib.import_module(".".join(parts))
        found |= {obj for obj in vars(module).values()
                  if inspect.isclass(obj) and obj.__module__ == module.__name__}
    return found


def _classes_in(annotation) -> set[type]:
    """The gyrojax classes an annotation names, through unions, tuples, dicts and lists."""
    if inspect.isclass(annotation) and not typing.get_args(annotation):
        return {annotation} if annotation.__module__.startswith("gyrojax") else set()
    out = set()
    for arg in typing.get_args(annotation):
        if arg is not Ellipsis:
            out |= _classes_in(arg)
    return out


def _records(results: set[type]) -> set[type]:
    """Every gyrojax class reachable through the results' field annotations, the inputs they keep left out."""
    seen, todo = set(), list(results)
    while todo:
        cls = todo.pop()
        if cls in seen or cls.__name__ in INPUT_TYPES:
            continue
        seen.add(cls)
        if dataclasses.is_dataclass(cls):
            hints = typing.get_type_hints(cls)
            for f in dataclasses.fields(cls):
                todo += _classes_in(hints[f.name])
    return seen - results


RESULTS = _result_classes()
RECORDS = _records(RESULTS)


def test_the_results_are_found():
    names = {c.__name__ for c in RESULTS}
    assert {"Fit", "PopulationFit", "Diagnosis", "Plan", "RateTablePlan", "CompensationResult", "MetricsReport",
            "Comparison", "IdentifyReport"} <= names
    assert {"Step", "CandidateScore", "CandidatePlan", "ExperimentGain", "CompensatedRun", "CompensatedDevice",
            "LookAlike", "Finding", "Misfit"} <= {c.__name__ for c in RECORDS}


def _subclasses(cls: type) -> list[type]:
    return [s for s in cls.__subclasses__() if s.__module__.startswith("gyrojax")]


@pytest.mark.parametrize("cls", sorted(RESULTS | RECORDS, key=lambda c: c.__name__), ids=lambda c: c.__name__)
def test_each_result_and_record_is_a_final_equinox_module(cls):
    if cls.__name__ in PENDING_CLASSES:
        pytest.skip(PENDING_CLASSES[cls.__name__])
    assert issubclass(cls, eqx.Module), (f"{cls.__module__}.{cls.__name__} is a result or a record inside one: it "
                                          "must be an equinox.Module (frozen, a pytree, built by keyword)")
    assert not inspect.isabstract(cls), f"{cls.__name__}: a result is concrete"
    assert not _subclasses(cls), f"{cls.__name__} is subclassed by {_subclasses(cls)}: a concrete module is final"


def _untyped(annotation, inside: bool = False) -> str | None:
    """Why an annotation hides what it holds, or None: a bare tuple/list/dict, Any inside a container, or a dict
    inside a container (records kept as dicts)."""
    origin = typing.get_origin(annotation)
    if annotation in (tuple, list, dict, typing.Tuple, typing.List, typing.Dict):  # noqa: UP006
        return f"a bare {getattr(annotation, '__name__', annotation)}"
    if annotation is typing.Any and inside:
        return "Any inside a container"
    if inside and (annotation is dict or origin is dict):
        return "dicts inside a container (records kept as dicts)"
    if origin in (tuple, list):
        return next((w for a in typing.get_args(annotation) if a is not Ellipsis
                     if (w := _untyped(a, inside=True))), None)
    if origin is dict:
        args = typing.get_args(annotation)
        value = args[1] if len(args) == 2 else None
        return "a dict of dicts (records kept as dicts)" if typing.get_origin(value) is dict else None
    if origin in (typing.Union, types.UnionType):
        return next((w for a in typing.get_args(annotation) if (w := _untyped(a, inside))), None)
    return None


def test_result_fields_are_typed_records_not_dicts():
    bad = []
    for cls in sorted(RESULTS | RECORDS, key=lambda c: c.__name__):
        if not dataclasses.is_dataclass(cls):
            continue
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            why = _untyped(hints[f.name])
            if why and cls.__name__ not in PENDING_CLASSES and (cls.__name__, f.name) not in PENDING_FIELDS:
                bad.append(f"{cls.__name__}.{f.name}: {hints[f.name]} ({why})")
    assert not bad, "result fields that do not say what they hold:\n" + "\n".join(bad)


def _imported_names(tree: ast.Module, module: str, is_package: bool) -> dict[str, object]:
    """Name -> the object it is bound to by the module's `from ... import ...` statements."""
    out = {}
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom):
            continue
        base = module.split(".") if is_package else module.split(".")[:-1]
        if node.level:
            base = base[: len(base) - (node.level - 1)]
            target = ".".join(base + ([node.module] if node.module else []))
        else:
            target = node.module or ""
        try:
            source = importlib.import_module(target)
        except ImportError:
            continue
        for alias in node.names:
            out[alias.asname or alias.name] = getattr(source, alias.name, None)
    return out


def test_results_are_constructed_by_keyword():
    classes = {c.__name__: c for c in RESULTS | RECORDS}
    bad = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        module = ".".join(parts[:-1] if is_package else parts)
        tree = ast.parse(path.read_text(), filename=rel)
        bound = _imported_names(tree, module, is_package)
        mod = importlib.import_module(module)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.args):
                continue
            name = node.func.id
            cls = classes.get(name)
            if cls is None or (bound.get(name) is not cls and getattr(mod, name, None) is not cls):
                continue  # another class of that name (e.g. the distributed lot's chunk `Plan`)
            if (rel, name) not in PENDING_CALLS:
                bad.append(f"{rel}:{node.lineno}: {name}(...) with {len(node.args)} positional argument(s)")
    assert not bad, "results constructed with positional arguments (name each field):\n" + "\n".join(bad)
