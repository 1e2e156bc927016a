"""The range sensor seen: beams in GIF frames and the replay, the scan figure, and
the example controller that drives from ranges alone."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO

from sandbox import Simulation, load_scenario
from sandbox.cli import main
from sandbox.render.animation import render_frame

EXAMPLE = REPO / "examples" / "ranges_controller.yaml"


@pytest.fixture(scope="module")
def scanned():
    """The example's rover at rest before the first crate, 0.3 s recorded."""
    return Simulation(load_scenario(EXAMPLE, overrides=["duration=0.3"])).run()


def test_beams_are_drawn_only_when_asked(scanned) -> None:
    plain = render_frame(scanned, size=240)
    beams = render_frame(scanned, size=240, show_beams=True)
    assert plain.shape == beams.shape == (240, 240, 3)
    assert (plain != beams).any(axis=2).sum() > 200  # the beams' pixels
    red = (beams[..., 0] > 180) & (beams[..., 1] < 80) & (beams[..., 2] < 80)
    assert (
        red.sum()
        > ((plain[..., 0] > 180) & (plain[..., 1] < 80) & (plain[..., 2] < 80)).sum()
    )  # the hits' dots


def test_without_scans_the_option_changes_nothing() -> None:
    doc = {
        "duration": 0.2,
        "reference": {"type": "point", "position": [1, 0]},
        "vehicles": [{"name": "red", "pose": [0, 0, 0]}],
    }
    run = Simulation(load_scenario(doc)).run()
    assert run.ranges is None
    np.testing.assert_array_equal(
        render_frame(run, size=128), render_frame(run, size=128, show_beams=True)
    )


def test_render_and_replay_with_beams(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = ["run", str(EXAMPLE), "--out", str(out), "--duration", "0.4"]
    assert main([*argv, "--html", "--show-beams"]) == 0
    page = (out / "replay.html").read_text()
    assert '"beams":' in page and '"reach":[4.0]' in page
    gif = tmp_path / "b.gif"
    assert main(["render", str(out), "--gif", str(gif), "--show-beams"]) == 0
    assert gif.stat().st_size > 1000
    plain = tmp_path / "plain"
    assert main(["run", str(EXAMPLE), "--out", str(plain), "--duration", "0.4"]) == 0
    assert main(["view", str(plain)]) == 0
    assert '"beams":' not in (plain / "replay.html").read_text()


@pytest.mark.slow
def test_the_scan_figure(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    assert main(["run", str(EXAMPLE), "--out", str(out), "--duration", "0.4"]) == 0
    capsys.readouterr()
    assert main(["plot", str(out), "--scan", "0.2", "--out", str(tmp_path)]) == 0
    path = Path(capsys.readouterr().out.strip())
    assert path == tmp_path / "scan_0.2.png" and path.stat().st_size > 10_000
    plain = tmp_path / "plain"
    doc = tmp_path / "plain.yaml"
    text = EXAMPLE.read_text()
    doc.write_text(re.sub(r"sensors:\n  range: .*\n", "", text))
    assert main(["run", str(doc), "--out", str(plain), "--duration", "0.2"]) == 0
    capsys.readouterr()
    assert main(["plot", str(plain), "--scan", "0.1"]) == 2
    assert "no range-sensor scans" in capsys.readouterr().err


@pytest.mark.slow
def test_the_example_reaches_its_goal_from_ranges_alone() -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "ranges_controller", REPO / "examples" / "ranges_controller.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    figures = module.main(["--duration", "40"])
    assert figures["collisions"] == 0
    assert figures["progress"] > 17.0 and figures["goal_distance"] < 0.5
    assert figures["closest"] > 0.25  # never nearer than its own radius plus 0


def test_the_example_controller_never_reads_the_obstacles() -> None:
    source = (REPO / "examples" / "ranges_controller.py").read_text()
    for looked_up in (".obstacles", "ObstacleField", "obstacle_field", "import yaml"):
        assert looked_up not in source, looked_up
    assert "obs.ranges" in source


def test_a_replay_without_scans_keeps_its_script() -> None:
    from sandbox.render.replay import with_beams
    from sandbox.render.replay.page import asset

    script = asset("replay.js")
    assert "drawBeams" not in script  # the page of every other run is unchanged
    patched = with_beams(script)
    assert patched.count("function drawBeams") == 1
    assert patched.count("if (M.beams && !large) drawBeams(s, xy, th);") == 1
