"""``--gif`` and ``--mp4`` never replace a file that is not an earlier output of theirs.

v0.2: ``sandbox run mine.yaml --gif mine.yaml`` turned the scenario into a GIF.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from helpers import PAPER

from sandbox.cli import main


@pytest.fixture
def mine(tmp_path: Path) -> Path:
    path = tmp_path / "mine.yaml"
    shutil.copy(PAPER / "rotating_circle.yaml", path)
    return path


def test_a_gif_target_that_is_a_scenario_is_refused(
    mine: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = mine.read_bytes()
    out = mine.parent / "run"
    argv = ["run", str(mine), "--duration", "0.2", "--out", str(out)]
    assert main([*argv, "--gif", str(mine)]) == 2
    err = capsys.readouterr().err
    assert "exists and is not a GIF file, so it is not replaced" in err
    assert "--force" in err
    assert mine.read_bytes() == before
    assert not out.exists()  # refused before the run


def test_an_earlier_gif_is_replaced_and_force_replaces_anything(
    mine: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    gif = mine.parent / "mine.gif"
    argv = ["run", str(mine), "--duration", "0.2", "--out", str(mine.parent / "run")]
    assert main([*argv, "--gif", str(gif)]) == 0
    first = gif.stat().st_mtime_ns
    assert main([*argv, "--gif", str(gif), "--fps", "10"]) == 0  # an earlier output
    assert gif.read_bytes()[:6] == b"GIF89a" and gif.stat().st_mtime_ns >= first
    other = mine.parent / "notes.txt"
    other.write_text("mine\n")
    assert main([*argv, "--gif", str(other)]) == 2
    assert main([*argv, "--gif", str(other), "--force"]) == 0
    assert other.read_bytes()[:6] == b"GIF89a"


def test_render_refuses_the_same_way(
    mine: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = mine.parent / "run"
    assert main(["run", str(mine), "--duration", "0.2", "--out", str(out)]) == 0
    before = mine.read_bytes()
    assert main(["render", str(out), "--gif", str(mine)]) == 2
    assert mine.read_bytes() == before
