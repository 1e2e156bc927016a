"""Tests of the frames' text bands (``sandbox.render.overlay``), the automatic camera
of ``sandbox run --gif`` and MP4 output (``sandbox.render.video``)."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from helpers import write_yaml
from PIL import ImageColor
from test_render import make_run

from sandbox.cli import main
from sandbox.render import animation as render
from sandbox.render import camera as render_camera
from sandbox.render import overlay as render_overlay
from sandbox.render import palette as render_palette
from sandbox.render import video
from sandbox.run.output import load_run_dir
from sandbox.run.record import MODE_AVOID, CollisionEvent

LINE = {
    "name": "line",
    "duration": 2.0,
    "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 2},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "leader", "pose": [0, 0, 0], "leader": True, "color": "blue"},
        {"name": "red", "pose": [-1, 1, 0], "offset": [-1, 1], "color": "red"},
    ],
}


def labels(run) -> list[str]:
    _, body, _ = render_palette.build_palette(run.colors)
    return [i.label for i in render_camera._legend_items(run, body, False)]


def test_legend_names_each_vehicle_in_its_colour() -> None:
    run = make_run(n=3, colors=["blue", "#ff8800", "green"])
    frame = next(iter(render.render_frames(run, fps=10.0, size=400)))
    bands = render_camera.run_bands(run, 400, True)
    strip = frame[400 - bands.bottom :].reshape(-1, 3)
    for color in run.colors:
        assert (strip == ImageColor.getrgb(color)).all(axis=1).sum() > 10
    assert labels(run)[:3] == ["v0", "v1", "v2"]
    # without the legend the strip holds only the scale bar: no vehicle colour there
    bare = next(iter(render.render_frames(run, fps=10.0, size=400, legend=False)))
    bottom = render_camera.run_bands(run, 400, False).bottom
    assert not (bare[400 - bottom :] == ImageColor.getrgb("#ff8800")).all(-1).any()


def test_legend_explains_only_the_marks_the_run_shows() -> None:
    run = make_run(n=2)
    assert labels(run) == ["v0", "v1", "slot"]
    run.mode[10:20, 0] = MODE_AVOID
    run.failed[50:, 1] = True
    run.events.append(CollisionEvent(1.0, "v0", "v1", "vehicle_vehicle"))
    run.reference[:] = run.pose[:, 0, :2]
    assert labels(run) == [
        "v0",
        "v1",
        "reference",
        "slot",
        "avoiding",
        "failed",
        "collision",
    ]


def test_large_fleet_legend_gives_the_fleet_size() -> None:
    run = make_run(n=render_overlay.LEGEND_NAMES_MAX + 1)
    _, body, _ = render_palette.build_palette(run.colors)
    items = render_camera._legend_items(run, body, True)
    assert items[0].label == f"{run.n_vehicles} vehicles"
    assert "slot" not in [i.label for i in items]  # large fleets draw no slots


def _text_rows(frame: np.ndarray, top: int) -> int:
    """Height [px] of the black text in the heads-up band."""
    rows = np.flatnonzero((frame[:top] == 0).all(axis=-1).any(axis=1))
    return int(rows[-1] - rows[0] + 1)


def test_font_grows_with_the_frame_size() -> None:
    assert [render_overlay.font_px(s) for s in (200, 640, 1280)] == [10, 16, 32]
    run = make_run(n=2, duration=0.2)
    heights = {}
    for size in (640, 1280):
        frame = next(iter(render.render_frames(run, fps=10.0, size=size)))
        heights[size] = _text_rows(frame, render_camera.run_bands(run, size, True).top)
    assert heights[1280] >= 1.7 * heights[640]


def test_a_small_frame_drops_the_legend_not_the_view() -> None:
    run = make_run(n=4)
    bands = render_camera.run_bands(run, 160, True)
    assert bands.rows == ()
    assert bands.top + bands.bottom <= render_overlay.MAX_BANDS * 160
    assert render.Camera.for_run(run, 64).scale > 0  # even a tiny frame has a view
    assert render_camera.run_bands(run, 640, True).rows  # at 640 px it is there


def test_hud_time_digits_keep_their_place() -> None:
    stamps = render_overlay.TextStamps(16)
    from PIL import Image

    ends = []
    for text in ("1.00", "7.40", "8.88"):
        img = Image.new("L", (200, 30), 0)
        ends.append(stamps.paste_number(img, (0, 0), text, 1))
    assert len(set(ends)) == 1  # every number of 4 characters ends at the same x


def test_auto_camera_follows_a_run_spread_along_a_line() -> None:
    run = make_run(n=2, duration=20.0, speed=1.0)  # 20 m along x1, 3 m across
    run.pose[:, 1, 0] = run.pose[:, 0, 0]  # both drive, side by side: a platoon
    assert render.auto_follow(run) == "leader"
    auto = render.Camera.for_run(run, 320, "auto")
    whole = render.Camera.for_run(run, 320, None)
    assert auto.scale > 2 * whole.scale
    run.leader = -1
    assert render.auto_follow(run) is None


def test_cli_gif_uses_the_automatic_camera(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path, LINE)
    out, gif = tmp_path / "run", tmp_path / "line.gif"
    argv = ["run", str(scenario), "--out", str(out), "--gif", str(gif)]
    assert main([*argv, "--size", "128", "--fps", "5"]) == 0
    run = load_run_dir(out)
    expected = tmp_path / "auto.gif"
    render.write_gif(run, expected, fps=5.0, size=128, follow="auto")
    assert gif.read_bytes() == expected.read_bytes()
    render.write_gif(run, expected, fps=5.0, size=128, follow=None)
    assert gif.read_bytes() != expected.read_bytes()
    whole = tmp_path / "whole.gif"
    assert main(["render", str(out), "--gif", str(whole), "--follow", "whole",
                 "--size", "128", "--fps", "5", "--aspect", "square"]) == 0  # fmt: skip
    assert whole.read_bytes() == expected.read_bytes()
    # --follow whole frames the run in a frame of its own aspect (the default)
    render.write_gif(run, expected, fps=5.0, size=128, follow=None, aspect="run")
    assert main(["render", str(out), "--gif", str(whole), "--follow", "whole",
                 "--size", "128", "--fps", "5"]) == 0  # fmt: skip
    assert whole.read_bytes() == expected.read_bytes()
    width, height = iio.improps(whole, index=0).shape[1::-1]
    assert width == 128 and height < 128  # 4 m x 1 m: wider than high


def test_render_needs_an_output(tmp_path: Path, capsys) -> None:
    assert main(["render", str(tmp_path)]) == 2
    assert "give --gif OUT.gif, --mp4 OUT.mp4 or both" in capsys.readouterr().err


def test_mp4_without_its_extra_fails_before_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    monkeypatch.setattr(video, "video_available", lambda: False)
    scenario = write_yaml(tmp_path, LINE)
    out = tmp_path / "run"
    argv = ["run", str(scenario), "--out", str(out), "--mp4", str(tmp_path / "x.mp4")]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "pip install 'platoon-sandbox[video]'" in err
    assert not out.exists()  # refused before simulating


@pytest.mark.skipif(not video.video_available(), reason="needs the extra 'video'")
def test_mp4_holds_the_gif_frames_and_is_deterministic(tmp_path: Path) -> None:
    run = make_run(n=2, duration=1.0, colors=["blue", "red"], diameter=1.0)
    first, second = tmp_path / "a.mp4", tmp_path / "b.mp4"
    info = video.write_mp4(run, first, fps=10.0, size=97)  # odd: padded to 98
    video.write_mp4(run, second, fps=10.0, size=97)
    assert info["frames"] == len(render.frame_plan(run, 10.0)) == 10
    assert info["duration"] == pytest.approx(1.0)
    assert first.read_bytes() == second.read_bytes()
    assert first.read_bytes()[4:8] == b"ftyp"
    import subprocess

    import imageio_ffmpeg

    raw = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-loglevel", "error", "-i", str(first)]
        + ["-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"],
        capture_output=True,
        check=True,
    ).stdout
    decoded = np.frombuffer(raw, np.uint8).reshape(-1, 98, 98, 3)  # 98 x 98 px
    assert len(decoded) == 10
    drawn = list(render.render_frames(run, fps=10.0, size=97))
    for got, want in zip(decoded, drawn, strict=True):
        diff = np.abs(got[:97, :97].astype(int) - want.astype(int))
        assert diff.mean() < 6  # lossy, but the same picture
    assert not list(tmp_path.glob(".*.tmp"))


def test_gif_still_written_when_asked_with_mp4_refused_fps(tmp_path: Path) -> None:
    run = make_run(n=2, duration=0.5)
    with pytest.raises(ValueError, match="fps: expected 0 < fps <= 120 for an MP4"):
        video.write_mp4(run, tmp_path / "x.mp4", fps=500.0)
    assert not list(tmp_path.iterdir())
    frames = iio.imread(render.write_gif(run, tmp_path / "x.gif", fps=10)["path"])
    assert len(frames) >= 1
