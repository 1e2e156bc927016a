"""No import circle and no private name across modules, in the packages that say so.

Every ``import`` statement counts: at module level, inside a function and under
``if TYPE_CHECKING:`` (a circle there is still a circle of the design). A name
another module imports is public: no ``from x import _name`` between the modules of
``sandbox.scenario``, ``sandbox.study`` and ``sandbox.cli`` or into them.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "sandbox"
#: The packages held to it (the others are being brought to it).
CLEAN = ("sandbox.scenario", "sandbox.study", "sandbox.cli")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports(name: str) -> list[tuple[str, list[str]]]:
    """``(module, names)`` of every import of a module, lazy and typing ones too."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.append((sub, []) if sub in MODULES else (base, [a.name]))
    return out


def graph() -> dict[str, set[str]]:
    return {
        name: {m for m, _ in imports(name) if m in MODULES and m != name}
        for name in MODULES
    }


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def test_the_check_finds_a_circle() -> None:
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [
        ["a", "b", "c"]
    ]


def test_no_import_circle_reaches_the_clean_packages() -> None:
    touching = [c for c in circles(graph()) if any(m.startswith(CLEAN) for m in c)]
    assert touching == []


@pytest.mark.parametrize("name", [m for m in MODULES if m.startswith(CLEAN)])
def test_no_private_name_is_imported_across_modules(name: str) -> None:
    private = [
        f"{module}.{n}"
        for module, names in imports(name)
        for n in names
        if n.startswith("_") and not n.startswith("__")
    ]
    assert private == []
