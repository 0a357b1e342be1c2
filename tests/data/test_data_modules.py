"""The module structure of abco_data: no import cycles, no private names across modules."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "abco_data"


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(tree: ast.AST) -> list[tuple[str, list[str]]]:
    """``(module, names)`` of every import at any depth, ``if TYPE_CHECKING`` blocks included
    (a module naming another's types depends on it as much as one calling it)."""
    found: list[tuple[str, list[str]]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.extend((alias.name, []) for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.module, [alias.name for alias in node.names]))
    return found


def _graph() -> tuple[dict[str, set[str]], list[str]]:
    """Module -> the abco_data modules it imports; and every private name imported."""
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {name: set() for name in modules}
    private: list[str] = []
    for name, path in modules.items():
        for module, names in _imports(ast.parse(path.read_text())):
            if module not in modules:
                continue
            targets = {module}
            for imported in names:
                if f"{module}.{imported}" in modules:  # ``from package import submodule``
                    targets.add(f"{module}.{imported}")
                elif imported.startswith("_"):
                    private.append(f"{name} imports {module}.{imported}")
            graph[name] |= targets - {name}
    return graph, private


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        state[node] = 2
        stack.pop()
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_no_import_cycles() -> None:
    graph, _ = _graph()
    assert "abco_data.torch_view" in graph["abco_data.dataset"]  # the graph sees lazy imports
    assert _cycle(graph) is None, " -> ".join(_cycle(graph) or [])


def test_no_private_names_imported_across_modules() -> None:
    _, private = _graph()
    assert private == []
