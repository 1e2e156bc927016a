"""Package citizenship: the distribution's name, its version from git, install hints."""

from __future__ import annotations

import builtins
import importlib.metadata
import re
import subprocess
import tomllib
from pathlib import Path

import pytest

import sandbox
from sandbox import _about

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def test_the_distribution_has_its_own_name_and_the_import_stays_sandbox() -> None:
    project = PYPROJECT["project"]
    assert project["name"] == _about.DISTRIBUTION == "platoon-sandbox"
    assert project["scripts"] == {"sandbox": "sandbox.cli:main"}
    # the dev extra refers to the distribution by its own name
    assert "platoon-sandbox[test]" in project["optional-dependencies"]["dev"]
    assert importlib.metadata.version("platoon-sandbox") == sandbox.__version__


def test_the_version_comes_from_git_with_a_fallback() -> None:
    scm = PYPROJECT["tool"]["setuptools_scm"]
    assert scm["version_file"] == "sandbox/_version.py"
    assert scm["fallback_version"] == "0.1.0"  # the last release (CHANGELOG.md)
    assert "version" in PYPROJECT["project"]["dynamic"]
    assert any(
        r.startswith("setuptools-scm") for r in PYPROJECT["build-system"]["requires"]
    )
    # the generated file is not tracked (a constant version would be)
    ignored = (ROOT / ".gitignore").read_text(encoding="utf-8").splitlines()
    assert "sandbox/_version.py" in ignored
    if (ROOT / ".git").exists():
        tracked = subprocess.run(
            ["git", "ls-files", "sandbox/_version.py"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        assert tracked == ""
        assert sandbox.__version__ != "0.1.0"  # from git: not the fallback


def test_a_source_tree_without_metadata_says_unknown(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    real_import = builtins.__import__

    def no_version_file(name, *args, **kwargs):
        if name == "sandbox._version":
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    def no_metadata(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(builtins, "__import__", no_version_file)
    monkeypatch.setattr(importlib.metadata, "version", no_metadata)
    assert _about._find_version() == "0+unknown"
    monkeypatch.setattr(importlib.metadata, "version", lambda name: "9.9")
    assert _about._find_version() == "9.9"


def test_every_install_hint_names_the_distribution() -> None:
    assert _about.install_hint("video") == "pip install 'platoon-sandbox[video]'"
    stale = []
    for path in sorted((ROOT / "sandbox").rglob("*.py")):
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if re.search(r"pip install\W+sandbox\[", line):
                stale.append(f"{path.relative_to(ROOT)}:{n}")
    assert stale == []
