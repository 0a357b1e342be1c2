"""The shape of the code: layers envs -> data -> train, no import cycles, no private names
imported across modules. Read from the source with ``ast``: every import counts, inside
functions, under ``if TYPE_CHECKING:`` (a module that names another's types depends on it as
much as one that calls it) and in docstring examples (doctests run as tests of the module)."""

from __future__ import annotations

import ast
import doctest
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("abco_envs", "abco_data", "abco_train")
LAYER = {name: i for i, name in enumerate(PACKAGES)}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}


MODULES = _modules()


def _resolve(target: str) -> str | None:
    """The project module that ``target`` names (a module, or a name inside a package)."""
    while target and target not in MODULES:
        target = target.rpartition(".")[0]
    return target or None


def _import_nodes(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement of ``tree``, at any depth (``if TYPE_CHECKING:`` blocks too)."""
    return [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))]


def _doctest_imports(tree: ast.Module) -> list[ast.Import | ast.ImportFrom]:
    """The import statements of the examples in every docstring of ``tree``."""
    parser = doctest.DocTestParser()
    out: list[ast.Import | ast.ImportFrom] = []
    for node in [tree, *ast.walk(tree)]:
        if not isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                 ast.AsyncFunctionDef)):
            continue
        docstring = ast.get_docstring(node, clean=False)
        for example in parser.get_examples(docstring or ""):
            out += _import_nodes(ast.parse(example.source))
    return out


def _targets(module: str, nodes: list[ast.Import | ast.ImportFrom]
             ) -> list[tuple[str, str | None]]:
    """(imported project module, imported name or None) for each import of ``module``."""
    is_package = MODULES[module].name == "__init__.py"
    out: list[tuple[str, str | None]] = []
    for node in nodes:
        if isinstance(node, ast.Import):
            out += [(m, None) for a in node.names if (m := _resolve(a.name))]
            continue
        base = node.module or ""
        if node.level:
            anchor = module.split(".")
            anchor = anchor if is_package else anchor[:-1]
            anchor = anchor[: len(anchor) - node.level + 1]
            base = ".".join([*anchor, base] if base else anchor)
        for alias in node.names:
            sub = _resolve(f"{base}.{alias.name}")
            if sub is not None and sub == f"{base}.{alias.name}":
                out.append((sub, None))  # ``from pkg import module``
            elif (m := _resolve(base)) is not None:
                out.append((m, alias.name))
    return out


def _imports(module: str) -> list[tuple[str, str | None]]:
    """(imported project module, imported name or None) for every import in ``module``'s code."""
    return _targets(module, _import_nodes(ast.parse(MODULES[module].read_text())))


def _example_imports(module: str) -> list[str]:
    """The project modules (packages included) that ``module``'s docstring examples import."""
    tree = ast.parse(MODULES[module].read_text())
    return [t for t, _ in _targets(module, _doctest_imports(tree))]


def _is_package(module: str) -> bool:
    return MODULES[module].name == "__init__.py"


#: Module -> the project modules it depends on: its code's imports and its examples'.
DEPENDS = {m: sorted(({t for t, _ in _imports(m)} | {*_example_imports(m)}) - {m})
           for m in MODULES}
#: The graph that must have no cycle: every import of the code, and the examples' imports of
#: modules. An example importing a package (``import abco_data``) uses it as a user does, once
#: the package is whole, so that is no edge here (it still counts for the layers).
GRAPH = {m: sorted(({t for t, _ in _imports(m)}
                    | {t for t in _example_imports(m) if not _is_package(t)}) - {m})
         for m in MODULES}


def test_layers_point_one_way() -> None:
    upward = [f"{m} -> {t}" for m, targets in DEPENDS.items() for t in targets
              if LAYER[t.split(".")[0]] > LAYER[m.split(".")[0]]]  # fmt: skip
    assert upward == []


def test_no_import_cycles() -> None:
    # Packages' __init__ re-export their modules: an edge into a package's __init__ from its
    # own modules would be a cycle through the package, so those count too.
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in GRAPH[node]:
            if state.get(nxt) == 1:
                cycles.append([*stack[stack.index(nxt):], nxt])
            elif nxt not in state:
                visit(nxt, [*stack, nxt])
        state[node] = 2

    for module in GRAPH:
        if module not in state:
            visit(module, [module])
    assert cycles == []


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_private_name_crosses_a_module(module: str) -> None:
    private = [f"{target}.{name}" for target, name in _imports(module)
               if name and name.startswith("_") and not name.startswith("__") and target != module]
    assert private == []


#: Rooms of a size a reader can hold: modules of at most ~400 lines, functions that fit a
#: screen, and a package's top level that shows its subpackages rather than hiding them.
MAX_MODULE_LINES, MAX_FUNCTION_LINES, MAX_TOP_LEVEL_MODULES = 420, 85, 8


@pytest.mark.parametrize("module", sorted(MODULES))
def test_modules_and_functions_fit(module: str) -> None:
    source = MODULES[module].read_text()
    assert len(source.splitlines()) <= MAX_MODULE_LINES
    long = [f"{node.name}: {(node.end_lineno or 0) - node.lineno + 1} lines"
            for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and (node.end_lineno or 0) - node.lineno + 1 > MAX_FUNCTION_LINES]
    assert long == []


def test_the_trainer_shows_its_rooms() -> None:
    top = sorted(p.name for p in (ROOT / "abco_train").glob("*.py"))
    rooms = sorted(p.parent.name for p in (ROOT / "abco_train").glob("*/__init__.py"))
    assert len(top) <= MAX_TOP_LEVEL_MODULES, top
    assert rooms == ["bench", "config", "harness", "methods", "networks", "report", "tune"]


#: abco_data's rooms, and the most modules beside them at its top level (the dataset API,
#: its registry, errors, command line, progress, torch view and verification).
DATA_ROOMS = ["checks", "format", "generation", "hub", "interop", "user"]
MAX_DATA_TOP_LEVEL_MODULES = 10


def test_the_datasets_package_shows_its_rooms() -> None:
    top = sorted(p.name for p in (ROOT / "abco_data").glob("*.py"))
    rooms = sorted(p.parent.name for p in (ROOT / "abco_data").glob("*/__init__.py"))
    assert len(top) <= MAX_DATA_TOP_LEVEL_MODULES, top
    assert rooms == DATA_ROOMS


def test_the_file_format_stands_on_its_own() -> None:
    """``abco_data.format`` reads and writes files: it knows no registry, Hub or user data
    (it may draw maze frames with ``abco_envs``, the layer below)."""
    outside = [f"{m} -> {t}" for m, targets in DEPENDS.items() if m.startswith("abco_data.format")
               for t in targets if t.startswith("abco_data") and not t.startswith(
                   ("abco_data.format", "abco_data.errors"))]  # fmt: skip
    assert outside == []


def test_minari_is_reached_through_the_command_line_and_the_api_only() -> None:
    """The optional extra's code (``abco_data.interop``) is imported by the package's API and
    command lines only, so nothing else needs Minari installed."""
    users = sorted(m for m, targets in DEPENDS.items() if not m.startswith("abco_data.interop")
                   and any(t.startswith("abco_data.interop") for t in targets))  # fmt: skip
    assert set(users) <= {"abco_data", "abco_data.cli", "abco_data.user.cli"}, users
