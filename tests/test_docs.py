"""The docs site builds, and every code block marked runnable runs.

``mkdocs build --strict`` is run into a temporary directory (skipped only when MkDocs,
its Material theme or mkdocstrings is not installed: the ``docs`` extra; CI installs
it). The convention for runnable blocks is told in ``docs/contributing.md``: an HTML
comment right before a fenced block,

- ``<!-- runnable -->`` before a ``python`` block runs it with this interpreter, before
  an ``sh`` block runs it with bash (``set -euo pipefail``, the ``sandbox`` command of
  this interpreter's environment first on the ``PATH``);
- ``<!-- runnable: file NAME -->`` before any block writes it to ``NAME``, for the
  blocks after it.

The blocks of one page run in order, in one empty temporary directory, against the
installed package: they name bundled scenarios (``paper/rotating_circle``), never the
repository's files.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import REPO

DOCS = REPO / "docs"
README = REPO / "README.md"
#: A marker and the fenced block right after it: (file name or None, language, code).
BLOCK = re.compile(
    r"<!-- runnable(?:: file (?P<file>[\w./-]+))? -->\n"
    r"(?P<fence>```+)(?P<lang>\w*)[^\n]*\n(?P<code>.*?)^(?P=fence)[ \t]*$",
    re.S | re.M,
)
MARKER = re.compile(r"^<!-- runnable\b", re.M)
LANGUAGES = {"python", "sh"}


def pages() -> list[Path]:
    """The README and every docs page."""
    return [README, *sorted(DOCS.rglob("*.md"))]


def blocks(page: Path) -> list[re.Match]:
    return list(BLOCK.finditer(page.read_text(encoding="utf-8")))


def name(page: Path) -> str:
    return page.relative_to(REPO).as_posix()


RUNNABLE = [p for p in pages() if blocks(p)]


def test_every_marker_marks_a_block_that_can_run() -> None:
    for page in pages():
        text = page.read_text(encoding="utf-8")
        found = blocks(page)
        assert len(MARKER.findall(text)) == len(found), (
            f"{name(page)}: a <!-- runnable --> marker not right before a fenced block"
        )
        for block in found:
            if block["file"] is None:
                assert block["lang"] in LANGUAGES, (name(page), block["lang"])


def test_the_readme_and_the_getting_started_page_have_runnable_blocks() -> None:
    assert README in RUNNABLE and DOCS / "getting-started.md" in RUNNABLE
    assert len(RUNNABLE) >= 6


@pytest.mark.parametrize("page", RUNNABLE, ids=name)
def test_no_runnable_block_reads_the_repository(page: Path) -> None:
    # The blocks run against the installed package, from an empty directory: a path
    # into the repository's scenarios/ would only work from a clone.
    for block in blocks(page):
        assert "scenarios/" not in block["code"], (name(page), block["code"])


@pytest.mark.slow
@pytest.mark.parametrize("page", RUNNABLE, ids=name)
def test_the_runnable_blocks_of_a_page_run(page: Path, tmp_path: Path) -> None:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join((str(Path(sys.executable).parent), env["PATH"]))
    env.update(MPLBACKEND="Agg", SANDBOX_PROGRESS="0")
    env.pop("PYTHONPATH", None)
    for number, block in enumerate(blocks(page), 1):
        code = block["code"]
        if block["file"] is not None:
            target = tmp_path / block["file"]
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(code, encoding="utf-8")
            continue
        if block["lang"] == "python":
            script = tmp_path / f"block_{number}.py"
            script.write_text(code, encoding="utf-8")
            command = [sys.executable, script.name]
        else:
            command = ["bash", "-euo", "pipefail", "-c", code]
        done = subprocess.run(
            command,
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0, (
            f"{name(page)}, runnable block {number}:\n{code}\n"
            f"--- stdout\n{done.stdout[-3000:]}\n--- stderr\n{done.stderr[-3000:]}"
        )


@pytest.mark.skipif(
    any(
        importlib.util.find_spec(m) is None
        for m in ("mkdocs", "material", "mkdocstrings")
    ),
    reason="needs the docs extra (mkdocs, mkdocs-material, mkdocstrings)",
)
@pytest.mark.slow
def test_the_site_builds_strictly(tmp_path: Path) -> None:
    site = tmp_path / "site"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--config-file",
            str(REPO / "mkdocs.yml"),
            "--site-dir",
            str(site),
        ],
        cwd=tmp_path,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-5000:]
    # the generated references are there, from the declarations and the parser
    scenario = (site / "reference" / "scenario.html").read_text(encoding="utf-8")
    for key in ("record_every", "contact_release", "position_noise", "tangential"):
        assert f"<code>{key}</code>" in scenario, key
    cli = (site / "reference" / "cli.html").read_text(encoding="utf-8")
    assert "sandbox sweep table study/" in cli and "--retry-failed" in cli
    api = (site / "reference" / "api.html").read_text(encoding="utf-8")
    assert "with_overrides" in api and "assert_no_collisions" in api
    # the step API's members are Simulation's own, each with its entry
    for member in ("step", "observe", "result", "results", "done", "t", "status"):
        assert f'id="sandbox.loop.simulation.Simulation.{member}"' in api, member
    assert (site / "renders" / "rotating_circle.gif").is_file()


def generators():
    """``docs/gen_reference.py``, imported from its file."""
    spec = importlib.util.spec_from_file_location(
        "gen_reference", DOCS / "gen_reference.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_scenario_reference_lists_every_declared_key() -> None:
    # The page's tables come from the declarations the loader and the schema read:
    # every key of every section and of every registered plug-in is a row.
    from sandbox.scenario.schema import sections

    text = generators().scenario_reference()
    rows = 0
    for section, params in sections().items():
        for key, p in params.items():
            assert f"| `{key}` |" in text, (section, key)
            if p.unit:
                assert f"| `{key}` | {p.type} | {p.unit} |" in text, (section, key)
            rows += 1
    assert text.count("\n| `") == rows


def test_the_cli_reference_has_every_command() -> None:
    from sandbox.cli import build_parser

    text = generators().cli_reference()
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for command in sub.choices:
        assert f"### `sandbox {command}`" in text, command
        assert f"usage: sandbox {command}" in text, command


def test_the_controller_tutorial_lists_every_observation_field() -> None:
    # The table of docs/tutorials/controller.md against the dataclass: every public
    # field (the loop's own ``near`` is not one) and the ``obstacles`` property.
    import dataclasses

    from sandbox import Observation

    text = (DOCS / "tutorials" / "controller.md").read_text(encoding="utf-8")
    table = text[text.index("| `Observation` field |") :].split("\n\n")[0]
    rows = {
        line.split("|")[1].strip().strip("`")
        for line in table.splitlines()[2:]
        if line.startswith("| `")
    }
    fields = {f.name for f in dataclasses.fields(Observation) if f.repr}
    assert rows == fields | {"obstacles"}


def test_step_describes_each_of_its_overrides() -> None:
    # The API reference shows Simulation.step's docstring: each keyword is described
    # under Parameters.
    import inspect

    from sandbox import Simulation

    doc = inspect.getdoc(Simulation.step)
    params = doc[doc.index("Parameters") : doc.index("Returns")]
    for name in ("commands", "targets", "shifts", "observe"):
        assert f"\n{name} : " in params, name
