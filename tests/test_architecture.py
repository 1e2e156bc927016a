"""The package's layers: each stage imports only the stages below it (ARCHITECTURE.md).

The imports are read from the source (every ``import`` statement, at module level or
inside a function, as import-linter reads them; only those under ``if TYPE_CHECKING:``,
which never run, are left out), so a lazy import pointing up the stages fails too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "sandbox"

#: The stages, lowest first: a module may import its own stage and those listed before.
LAYERS: tuple[tuple[str, ...], ...] = (
    (
        "sandbox.errors",
        "sandbox._startup",
        "sandbox._about",
        "sandbox._version",
        "sandbox._moved",
        "sandbox.accel",
    ),
    ("sandbox.geometry",),
    ("sandbox.plugins",),
    ("sandbox.model",),
    ("sandbox.scenario",),
    ("sandbox.run",),
    ("sandbox.physics",),
    ("sandbox.behaviour",),
    ("sandbox.loop",),
    ("sandbox.render",),
    ("sandbox.study", "sandbox.envs", "sandbox.testing"),
    ("sandbox.cli", "sandbox.__main__"),
)
#: Modules outside the stages: the public face (imports anything, lazily) and the
#: table of moved paths.
FACE = ("sandbox",)


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer_of(module: str) -> int | None:
    for level, stages in enumerate(LAYERS):
        if any(module == s or module.startswith(s + ".") for s in stages):
            return level
    return None


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return skip


def imports_of(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every sandbox import of a file that can run."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _type_checking_nodes(tree)
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            if base == "sandbox":  # from sandbox import x: the submodule x, or the face
                for alias in node.names:
                    sub = f"sandbox.{alias.name}"
                    found.append(
                        (node.lineno, sub if layer_of(sub) is not None else base)
                    )
            else:
                found.append((node.lineno, base))
    return [
        (line, m) for line, m in found if m == "sandbox" or m.startswith("sandbox.")
    ]


MODULES = sorted(PACKAGE.rglob("*.py"))


def test_every_module_has_a_stage() -> None:
    homeless = [
        module_name(p)
        for p in MODULES
        if layer_of(module_name(p)) is None and module_name(p) not in FACE
    ]
    assert homeless == []


@pytest.mark.parametrize("path", MODULES, ids=lambda p: module_name(p))
def test_imports_point_down_the_stages(path: Path) -> None:
    me = module_name(path)
    mine = layer_of(me)
    if mine is None:
        return
    upward = []
    for line, target in imports_of(path):
        theirs = layer_of(target)
        if target == "sandbox" or theirs is None or theirs > mine:
            upward.append(f"{path.name}:{line} imports {target}")
    assert upward == []


def test_the_top_of_the_package_is_small() -> None:
    top = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(top) <= 12, top


def test_the_registry_imports_nothing_that_registers_into_it() -> None:
    from sandbox.plugins.builtin import BUILTIN_MODULES

    registering = set(BUILTIN_MODULES)
    for path in sorted((PACKAGE / "plugins").glob("*.py")):
        targets = {m for _, m in imports_of(path)}
        assert not any(
            t == r or t.startswith(r + ".") for t in targets for r in registering
        )
