"""The registry of compiled paths, its one switch, ``sandbox info`` and run's warning.

``sandbox.accel`` is the only importer of the C extensions: every path is on where
its extension imports, ``SANDBOX_ACCEL=0`` turns them all off (read once, in a new
process here), and a path whose extension was not built says so, in ``sandbox info``
and in one line of ``sandbox run``'s output (not where the user chose
``SANDBOX_ACCEL=0``).
"""

from __future__ import annotations

import ast
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

from sandbox import accel
from sandbox.cli import main

ROOT = Path(__file__).resolve().parents[1]

#: Run ``sandbox`` in a new process with some extensions made unimportable, as an
#: install without a C compiler has them (``sys.argv[1]``: their names, with commas).
WITHOUT = """
import sys

class NotBuilt:
    missing = set(sys.argv[1].split(",")) - {""}

    @classmethod
    def find_spec(cls, name, path=None, target=None):
        if name in cls.missing:  # as where no file of the module exists
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

sys.meta_path.insert(0, NotBuilt)
from sandbox.cli import main
sys.exit(main(sys.argv[2:]))
"""


def sandbox(*args: str, missing: str = "", accel_env: str | None = None):
    """``sandbox ARGS`` in a new process, the paths' modules ``missing`` not built."""
    env = {k: v for k, v in os.environ.items() if k != accel.ENV}
    if accel_env is not None:
        env[accel.ENV] = accel_env
    return subprocess.run(
        [sys.executable, "-c", WITHOUT, missing, *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=300,
    )


def module_of(name: str) -> str:
    return next(p.module for p in accel.PATHS if p.name == name)


def test_every_path_is_on_where_its_extension_imports():
    for name, on, why in accel.status():
        built = importlib.util.find_spec(module_of(name)) is not None
        if os.environ.get(accel.ENV, "").strip() == "0":
            assert not on and why == "SANDBOX_ACCEL=0"
        else:
            assert on == built, (name, why)
            assert why == ("" if built else accel.NOT_BUILT)


def test_switched_off_turns_paths_off_within_its_block_only():
    before = {name: on for name, on, _ in accel.status()}
    with accel.switched_off("controller", "filter"):
        assert accel.module("controller") is None
        assert accel.module("filter") is None
        assert (accel.module("laws") is not None) == before["laws"]
        with accel.switched_off():
            assert all(not on for _, on, _ in accel.status())
    assert {name: on for name, on, _ in accel.status()} == before
    with pytest.raises(KeyError, match="not compiled paths: turbo"):
        with accel.switched_off("turbo"):
            pass


@pytest.mark.slow
def test_only_the_registry_imports_the_extensions():
    extensions = {p.module for p in accel.PATHS}
    found = []
    for path in sorted((ROOT / "sandbox").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                names = {f"{node.module}.{a.name}" for a in node.names}
            elif isinstance(node, ast.Import):
                names = {a.name for a in node.names}
            else:
                continue
            if names & extensions:
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert found == []


def test_every_extension_of_the_build_is_a_registered_path():
    sources = {
        str(p.relative_to(ROOT).with_suffix("")).replace("/", ".")
        for p in (ROOT / "sandbox").rglob("_*.c")
    }
    assert sources == {p.module for p in accel.PATHS}


def test_info_prints_the_versions_and_every_path(capsys):
    assert main(["info"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("platoon-sandbox ")
    assert [line.split()[0] for line in out[1:4]] == ["python", "numpy", "pymunk"]
    rows = {line.split()[0]: line.split(None, 1)[1] for line in out[5:]}
    assert list(rows) == [p.name for p in accel.PATHS]
    for name, on, why in accel.status():
        assert rows[name] == ("on" if on else f"off ({why})")


def test_the_switch_turns_every_path_off_and_says_so():
    done = sandbox("info", accel_env="0")
    assert done.returncode == 0, done.stderr
    rows = done.stdout.splitlines()[5:]
    assert len(rows) == len(accel.PATHS)
    assert all(row.split(None, 1)[1] == "off (SANDBOX_ACCEL=0)" for row in rows)


def test_a_value_of_the_switch_that_is_neither_0_nor_1_is_named():
    done = sandbox("info", accel_env="off")
    assert done.returncode == 0
    assert "SANDBOX_ACCEL='off' is neither 0" in done.stderr


@pytest.mark.slow
def test_a_path_not_built_is_named_by_info_and_run(tmp_path):
    missing = f"{module_of('controller')},{module_of('filter')}"
    done = sandbox("info", missing=missing)
    assert done.returncode == 0, done.stderr
    rows = dict(line.split(None, 1) for line in done.stdout.splitlines()[5:])
    assert rows["controller"] == f"off ({accel.NOT_BUILT})"
    assert rows["filter"] == f"off ({accel.NOT_BUILT})"
    assert rows["laws"] == "on" or accel.module("laws") is None
    run = ["run", "paper/stabilization", "--duration", "0.2", "--out"]
    done = sandbox(*run, str(tmp_path / "a"), missing=missing)
    assert done.returncode == 0, done.stderr
    warned = [x for x in done.stderr.splitlines() if "not built" in x]
    gone = [p.name for p in accel.PATHS if p.module in missing.split(",")]
    assert warned == [
        f"warning: compiled paths not built ({', '.join(gone)}): this install runs "
        "their numpy forms, several times slower for small fleets; reinstall with a "
        "C compiler (sandbox info)"
    ]
    # the user's own choice is not warned about, nor is a complete build
    done = sandbox(*run, str(tmp_path / "b"), missing=missing, accel_env="0")
    assert "not built" not in done.stderr
    if not accel.not_built():
        done = sandbox(*run, str(tmp_path / "c"))
        assert done.returncode == 0 and "not built" not in done.stderr
