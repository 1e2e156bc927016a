"""`sandbox gallery`: every scenario of a folder run and rendered, under the size
budget."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import pytest
from helpers import run_scenario, write_yaml

from sandbox.cli import main
from sandbox.render.gallery import MAX_GIF_BYTES, camera_follow

LINE = {
    "name": "line",
    "duration": 2.0,
    "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 2},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "leader", "pose": [0, 0, 0], "leader": True},
        {"name": "red", "pose": [-1, 1, 0], "offset": [-1, 1]},
    ],
}
CIRCLE = {
    "name": "circle",
    "duration": 2.0,
    "reference": {"type": "circle", "center": [0, 0], "radius": 1, "speed": 1},
    "vehicles": [{"name": "solo", "pose": [1, 0, 1.5708]}],
}


def test_camera_follows_the_leader_only_on_runs_spread_along_a_line() -> None:
    # The line run covers about 5 m x 1.5 m (ratio > 2.5): follow the leader.
    run, _ = run_scenario(LINE)
    assert camera_follow(run) == "leader"
    # A circle of radius 1 m is as wide as it is tall, and has no leader anyway.
    run, _ = run_scenario(CIRCLE)
    assert camera_follow(run) is None


@pytest.mark.slow
def test_gallery_writes_one_gif_per_scenario(tmp_path: Path) -> None:
    folder = tmp_path / "scenarios"
    folder.mkdir()
    write_yaml(folder, LINE, "line.yaml")
    write_yaml(folder, CIRCLE, "circle.yaml")
    out = tmp_path / "renders"
    assert main(["gallery", str(folder), "--out", str(out)]) == 0
    gifs = sorted(p.name for p in out.glob("*.gif"))
    assert gifs == ["circle.gif", "line.gif"]
    for gif in out.glob("*.gif"):
        assert 0 < gif.stat().st_size <= MAX_GIF_BYTES
        frames = iio.imread(gif, index=None)
        assert frames.shape[0] > 10 and frames.shape[-1] == 3


def test_gallery_refuses_a_missing_folder(tmp_path: Path, capsys) -> None:
    assert main(["gallery", str(tmp_path / "nope"), "--out", str(tmp_path)]) == 1
    assert "no such folder" in capsys.readouterr().err
