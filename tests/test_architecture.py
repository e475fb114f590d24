"""The package's shape: no import cycles between its modules, no private names borrowed across modules, and
the scripts a user reads (experiments, notebooks) on the public API only, read from the source with `ast`; and
the public layout (a small top level, re-export-only submodules, moved names that warn), which imports gyrojax."""

import ast
import json
import pathlib
import re

import pytest


ROOT = pathlib.Path(__file__).parent.parent
PACKAGE = ROOT / "gyrojax"


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _top_level_imports(module: str, path: pathlib.Path):
    """(target module, imported name or None, line) of the imports that run when `module` is imported: those at
    the top level and in top-level if/try blocks, not those inside functions (lazy imports) nor under
    `if TYPE_CHECKING:`."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"

    def walk(body):
        for node in body:
            if isinstance(node, ast.If):
                test = ast.unparse(node.test)
                if "TYPE_CHECKING" not in test:
                    yield from walk(node.body)
                yield from walk(node.orelse)
            elif isinstance(node, ast.Try):
                for block in (node.body, node.orelse, node.finalbody, *[h.body for h in node.handlers]):
                    yield from walk(block)
            elif isinstance(node, ast.ImportFrom):
                target = _resolve(module, is_package, node)
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in MODULES:  # `from . import _x` imports a module, not a name
                        yield sub, None, node.lineno
                    else:
                        yield target, alias.name, node.lineno
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    yield alias.name, None, node.lineno

    yield from walk(tree.body)


def _graph():
    graph = {m: set() for m in MODULES}
    for module, path in MODULES.items():
        for target, _, _ in _top_level_imports(module, path):
            if target in MODULES and target != module:
                graph[module].add(target)
    return graph


def _cycles(graph):
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_checker_sees_the_package():
    assert "gyrojax" in MODULES and "gyrojax.cli" in MODULES and len(MODULES) > 40
    # it resolves relative imports: cli imports the package's own modules
    assert any(t.startswith("gyrojax.") for t in _graph()["gyrojax.cli"])


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles():
    cycles = _cycles(_graph())
    assert not cycles, f"modules that import each other (directly or around a circle): {cycles}"


def _every_import(module: str, path: pathlib.Path):
    """(target module, line) of every import in `module`: at the top level, inside functions (lazy imports) and
    under `if TYPE_CHECKING:` alike."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _resolve(module, is_package, node)
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                yield (sub if sub in MODULES else target), node.lineno
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno


def _full_graph():
    graph = {m: set() for m in MODULES}
    for module, path in MODULES.items():
        for target, _ in _every_import(module, path):
            if target in MODULES and target != module:
                graph[module].add(target)
    return graph


def test_no_import_cycles_even_through_lazy_or_type_checking_imports():
    """A cycle hidden in a function's import or under TYPE_CHECKING is still two modules that need each other:
    the layering holds for every import, and no module needs `TYPE_CHECKING` to break one."""
    assert "gyrojax._data.table" in _full_graph()["gyrojax._metrics.report"]  # it sees the imports of every kind
    cycles = _cycles(_full_graph())
    assert not cycles, f"modules that import each other, counting lazy and TYPE_CHECKING imports: {cycles}"
    guarded = [str(p.relative_to(ROOT)) for p in MODULES.values() if "TYPE_CHECKING" in p.read_text()]
    assert not guarded, f"modules that import under TYPE_CHECKING: {guarded}"


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def test_no_private_names_across_modules():
    """A module uses another module's public names only; a helper that two modules share is not private."""
    borrowed = []
    for module, path in MODULES.items():
        for target, name, line in _top_level_imports(module, path):
            if name is not None and _is_private(name) and target.startswith("gyrojax"):
                borrowed.append(f"{path.relative_to(ROOT)}:{line} imports {name} from {target}")
    assert not borrowed, "\n".join(borrowed)


PRIVATE_USE = re.compile(r"\b(?:gyrojax|gj)\._(?!_)")


def _script_sources():
    for path in sorted((ROOT / "experiments").glob("*.py")):
        yield path, path.read_text()
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(path.read_text())["cells"]
        yield path, "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")


@pytest.mark.parametrize("path,source", list(_script_sources()), ids=lambda x: getattr(x, "name", ""))
def test_experiments_and_notebooks_use_the_public_api(path, source):
    private = [line.strip() for line in source.splitlines() if PRIVATE_USE.search(line)]
    assert not private, f"{path.relative_to(ROOT)} reaches into private modules: {private}"


def test_the_package_root_is_small():
    """Every wing is a folder named for what it does; the root keeps the entry points and a few shared modules
    (at most 20 files), beside the public submodules (re-exports only, checked below)."""
    root_files = sorted(p.name for p in PACKAGE.glob("*.py") if p.stem not in PUBLIC_SUBMODULES)
    assert len(root_files) <= 20, f"{len(root_files)} files at the package root: {root_files}"
    lots = sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("lot.py"))
    assert not lots, f"files named for a lot without saying what of it: {lots}"


# The public layout (docs/architecture.md, "Public layout"): a small top level and one file of re-exports per
# family of helpers.
PUBLIC_SUBMODULES = ("compensation", "effects", "identification", "io", "metrics", "physics", "sweeps",
                     "temperature")
MAX_PUBLIC_NAMES = 100


def _public_namespaces():
    import gyrojax

    spaces = {"gyrojax": (gyrojax, list(gyrojax.__all__))}
    for sub in PUBLIC_SUBMODULES:
        module = getattr(gyrojax, sub)
        spaces[f"gyrojax.{sub}"] = (module, list(module.__all__))
    return spaces


def test_public_api_top_level_has_at_most_100_names():
    import gyrojax

    names = [n for n in dir(gyrojax) if not n.startswith("_")]
    assert len(names) <= MAX_PUBLIC_NAMES, f"{len(names)} public names at gyrojax's top level: {names}"
    assert sorted(names) == sorted(gyrojax.__all__)
    for sub in (*PUBLIC_SUBMODULES, "units"):
        assert sub in names, f"the public submodule gyrojax.{sub} is not listed at the top level"


@pytest.mark.parametrize("sub", PUBLIC_SUBMODULES)
def test_public_api_submodule_only_reexports_what_its_all_lists(sub):
    import importlib

    path = PACKAGE / f"{sub}.py"
    tree = ast.parse(path.read_text(), filename=str(path))
    assert ast.get_docstring(tree), f"gyrojax/{sub}.py has no module docstring saying what family it holds"
    imported, listed = [], None
    for node in tree.body[1:]:
        if isinstance(node, ast.ImportFrom) and node.level == 1 and (node.module or "").startswith("_"):
            for alias in node.names:
                assert alias.asname == alias.name, f"gyrojax/{sub}.py:{node.lineno} renames {alias.name}"
                imported.append(alias.name)
        elif isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] == ["__all__"]:
            listed = ast.literal_eval(node.value)
        else:
            raise AssertionError(f"gyrojax/{sub}.py:{node.lineno}: a public submodule only re-exports from "
                                 f"private modules and lists them in __all__, found {ast.dump(node)[:80]}")
    assert listed is not None and sorted(listed) == sorted(set(imported)) == sorted(imported)
    module = importlib.import_module(f"gyrojax.{sub}")
    assert sorted(n for n in vars(module) if not n.startswith("_")) == sorted(module.__all__)


def test_public_api_moved_names_warn_and_name_their_new_home():
    import gyrojax

    assert gyrojax._MOVED, "no moved names recorded"
    top = set(dir(gyrojax))
    for home, names in gyrojax._MOVED.items():
        module = getattr(gyrojax, home)
        for name in names:
            assert name not in top and name in module.__all__, name
            with pytest.warns(DeprecationWarning, match=rf"^gyrojax\.{name} is gyrojax\.{home}\.{name}; import it "
                                                        r"from there"):
                obj = getattr(gyrojax, name)
            assert obj is getattr(module, name)
    with pytest.raises(AttributeError, match="module 'gyrojax' has no attribute 'NotAName'"):
        gyrojax.NotAName  # noqa: B018


def test_public_api_a_leftover_moved_name_fails_the_suite():
    """pyproject's filterwarnings turns the moved names' warning into an error: its pattern matches the message."""
    import tomllib
    import warnings

    import gyrojax

    filters = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]["filterwarnings"]
    patterns = [f.split(":")[1] for f in filters if f.startswith("error:") and f.endswith(":DeprecationWarning")]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gyrojax.DacInl  # noqa: B018
    assert any(re.match(p, str(caught[0].message)) for p in patterns), (patterns, str(caught[0].message))


def test_public_api_no_name_is_two_different_objects():
    seen = {}
    clashes = []
    for where, (module, names) in _public_namespaces().items():
        for name in names:
            obj = getattr(module, name)
            if name in seen and seen[name][1] is not obj:
                clashes.append(f"{name}: {seen[name][0]}.{name} is not {where}.{name}")
            seen.setdefault(name, (where, obj))
    assert not clashes, "\n".join(clashes)


MAX_FUNCTION_LINES = 80
# Functions still longer than MAX_FUNCTION_LINES, with their length today: the list only shrinks. A function split
# below the limit leaves it (the test says so); none may grow, and no other function may pass the limit.
LONG_FUNCTIONS: dict[str, int] = {}


def _function_lengths(tree: ast.AST, prefix: str = ""):
    """(qualified name, lines from `def` to its last line, docstring included) of every function in `tree`,
    methods and nested functions too."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield prefix + node.name, node.end_lineno - node.lineno + 1
            yield from _function_lengths(node, prefix + node.name + ".")
        elif isinstance(node, ast.ClassDef):
            yield from _function_lengths(node, prefix + node.name + ".")
        else:
            yield from _function_lengths(node, prefix)


def _long_functions(limit: int = MAX_FUNCTION_LINES) -> dict:
    return {f"{path.relative_to(ROOT).as_posix()}::{name}": n for path in sorted(PACKAGE.rglob("*.py"))
            for name, n in _function_lengths(ast.parse(path.read_text())) if n > limit}


def test_the_function_length_checker_counts_nested_and_methods():
    tree = ast.parse("class A:\n    def f(self):\n        def g():\n            pass\n\n        return g\n")
    assert dict(_function_lengths(tree)) == {"A.f": 5, "A.f.g": 2}


def test_no_function_over_80_lines():
    """A function longer than a screen is several concepts: each is a well-named helper. Those not split yet are
    listed in `LONG_FUNCTIONS`; the list only shrinks."""
    long = _long_functions()
    new = {k: n for k, n in long.items() if k not in LONG_FUNCTIONS}
    assert not new, f"functions over {MAX_FUNCTION_LINES} lines (split them into helpers): {new}"
    grown = {k: (LONG_FUNCTIONS[k], n) for k, n in long.items() if k in LONG_FUNCTIONS and n > LONG_FUNCTIONS[k]}
    assert not grown, f"listed long functions that grew (listed, now): {grown}"
    done = sorted(k for k in LONG_FUNCTIONS if k not in long)
    assert not done, f"now at most {MAX_FUNCTION_LINES} lines: remove them from LONG_FUNCTIONS: {done}"


MAX_FILE_LINES = 500
# Files still longer than MAX_FILE_LINES, with their length today: the list only shrinks, as LONG_FUNCTIONS does.
LONG_FILES: dict[str, int] = {}


def _line_count(path: pathlib.Path) -> int:
    return len(path.read_text().splitlines())


def test_the_file_length_checker_counts_lines(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n\n# end\n")
    assert _line_count(tmp_path / "a.py") == 3


def test_no_file_over_500_lines():
    """A file is one concept (equinox's habit): past 500 lines it is several, each a file of a folder named for
    what it does. Those not split yet are listed in `LONG_FILES`; the list only shrinks."""
    long = {p.relative_to(ROOT).as_posix(): n for p in sorted(PACKAGE.rglob("*.py"))
            if (n := _line_count(p)) > MAX_FILE_LINES}
    new = {k: n for k, n in long.items() if k not in LONG_FILES}
    assert not new, f"files over {MAX_FILE_LINES} lines (split them, one concept per file): {new}"
    grown = {k: (LONG_FILES[k], n) for k, n in long.items() if k in LONG_FILES and n > LONG_FILES[k]}
    assert not grown, f"listed long files that grew (listed, now): {grown}"
    done = sorted(k for k in LONG_FILES if k not in long)
    assert not done, f"now at most {MAX_FILE_LINES} lines: remove them from LONG_FILES: {done}"
