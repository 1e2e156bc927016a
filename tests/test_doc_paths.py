"""Every source path the documentation gives exists in the tree.

The pages of ``docs/``, ``README.md``, ``ARCHITECTURE.md``, ``scenarios/reference.yaml``
and the generated text (the scenario reference from the declarations, the help of
every command) name files as ``sandbox/...``; a module that moves leaves such a path
pointing nowhere. A path of the installed package that the build maps from another
folder (``setup.py``: ``sandbox/scenarios/`` is the repository's ``scenarios/``) is
looked for there; a Gymnasium id (``sandbox/Vehicle-v0``) is not a path.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: A path under sandbox/: folders and a file name, maybe a trailing slash.
PATH = re.compile(r"(?<![\w./-])sandbox/(?:[\w-]+/)*[\w-]+(?:\.[A-Za-z]\w*)?/?")
#: Gymnasium environment ids (``sandbox/Vehicle-v0``), which look like paths.
GYM_ID = re.compile(r"sandbox/[A-Z]\w*-v\d+")
#: Folders of the installed package that the build maps from the repository's.
MAPPED = {"sandbox/scenarios": "scenarios"}


def _generated() -> dict[str, str]:
    spec = importlib.util.spec_from_file_location(
        "gen_reference_paths", ROOT / "docs" / "gen_reference.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {
        "scenario reference": module.scenario_reference(),
        "command help": module.cli_reference(),
    }


def _written() -> dict[str, str]:
    files = [*sorted((ROOT / "docs").rglob("*.md")), ROOT / "README.md"]
    files += [ROOT / "ARCHITECTURE.md", ROOT / "scenarios" / "reference.yaml"]
    return {str(p.relative_to(ROOT)): p.read_text(encoding="utf-8") for p in files}


def missing(text: str) -> list[str]:
    """The sandbox/... paths of ``text`` that do not exist in the tree."""
    out = []
    for found in PATH.finditer(text):
        path = found.group().rstrip(".")
        if GYM_ID.fullmatch(path):
            continue
        for installed, source in MAPPED.items():
            if path == installed or path.startswith(installed + "/"):
                path = source + path[len(installed) :]
        if not (ROOT / path).exists():
            out.append(found.group())
    return sorted(set(out))


def test_the_check_finds_a_stale_path() -> None:
    assert missing("see sandbox/sensing.py and sandbox/behaviour/sensing.py.") == [
        "sandbox/sensing.py"
    ]
    assert missing("the env sandbox/Vehicle-v0, sandbox/scenarios/paper/") == []


@pytest.mark.parametrize("name", sorted(_written()))
def test_a_page_names_only_paths_that_exist(name: str) -> None:
    assert missing(_written()[name]) == []


@pytest.mark.parametrize("name", ["scenario reference", "command help"])
def test_the_generated_text_names_only_paths_that_exist(name: str) -> None:
    found = missing(_generated()[name])
    assert found == []
