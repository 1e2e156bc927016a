"""Tests of ``sandbox.render.animation``: GIF timing, geometry, colours and markers.

Runs are synthetic (built by :func:`make_run`), so these tests need no simulator.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image, ImageColor

from sandbox.render import animation as render
from sandbox.render import camera as render_camera
from sandbox.render import gif_stream
from sandbox.render import overlay as render_overlay
from sandbox.render import palette as render_palette
from sandbox.run.record import MODE_AVOID, CollisionEvent, Run


def make_run(
    n: int = 2,
    duration: float = 2.0,
    dt: float = 0.01,
    *,
    colors: list[str] | None = None,
    diameter: float = 0.5,
    speed: float = 0.5,
) -> Run:
    """Build a run of ``n`` vehicles heading +x1 at ``speed`` [m/s], 3 m apart in x2.

    Vehicle ``i`` starts at ``(0, 3 i)``; the last one stands still (``speed`` 0).
    """
    t = np.arange(0.0, duration + dt / 2, dt)
    T = len(t)
    v = np.full(n, speed)
    v[-1] = 0.0
    x = t[:, None] * v[None, :]
    y = np.broadcast_to(3.0 * np.arange(n), (T, n))
    pose = np.stack((x, y, np.zeros((T, n))), -1)
    cmd = np.stack((np.broadcast_to(v, (T, n)), np.zeros((T, n))), -1)
    return Run(
        t=t,
        pose=pose,
        cmd=cmd,
        chi=cmd.copy(),
        slot=np.full((T, n, 2), np.nan),
        target=pose[:, :, :2].copy(),
        mode=np.zeros((T, n), dtype=np.int8),
        failed=np.zeros((T, n), dtype=bool),
        reference=np.full((T, 2), np.nan),
        names=[f"v{i}" for i in range(n)],
        colors=colors or ["blue", "#ff8800", "green", "purple"][:n],
        diameter=np.full(n, diameter),
        leader=0,
        info={"recovery": {"strategy": "none", "R": 1.5, "r": None}},
    )


def frame_at(run: Run, t: float, **kw: object) -> np.ndarray:
    """Render the single frame that shows simulated time ``t`` (at 10 fps)."""
    plan = render.frame_plan(run, fps=10.0)
    k = int(np.argmin(np.abs(plan.times - t)))
    for j, frame in enumerate(render.render_frames(run, fps=10.0, **kw)):
        if j == k:
            return frame
    raise AssertionError("frame not reached")


def pixel(frame: np.ndarray, uv: np.ndarray) -> tuple[int, ...]:
    """Colour of the pixel containing pixel coordinates ``uv`` (column, row)."""
    col, row = np.floor(uv).astype(int)
    return tuple(int(c) for c in frame[row, col])


def body_sample(cam: render.Camera, xy: np.ndarray, radius: float) -> np.ndarray:
    """A point inside a +x1-heading body, half a radius above its centre (off the
    heading line, inside the edge)."""
    return cam.world_to_pixel(np.asarray(xy) + [0.0, 0.5 * radius])


# ------------------------------------------------------------------------- timing
def test_gif_frame_count_size_and_durations(tmp_path: Path) -> None:
    run = make_run(duration=2.0)
    out = tmp_path / "run.gif"
    info = render.write_gif(run, out, fps=25.0, size=128)
    # 2 s at 25 fps -> 50 frames of 1000 / 25 = 40 ms, 2.0 s in all
    assert info == {"frames": 50, "duration": 2.0, "path": str(out)}
    assert iio.improps(out, index=None).shape == (50, 128, 128, 3)
    with Image.open(out) as im:
        assert im.size == (128, 128)
        assert im.n_frames == 50
        assert im.info["loop"] == 0
        durations = []
        for k in range(im.n_frames):
            im.seek(k)
            durations.append(im.info["duration"])
    assert durations == [40] * 50
    assert iio.immeta(out, index=0)["duration"] == 40
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left


def test_speed_two_halves_the_frames(tmp_path: Path) -> None:
    info = render.write_gif(make_run(duration=2.0), tmp_path / "a.gif", fps=25, speed=2)
    # 2 s / 2 = 1 s of playback at 25 fps -> 25 frames of 40 ms
    assert (info["frames"], info["duration"]) == (25, 1.0)


def test_delays_spread_when_fps_does_not_divide_100() -> None:
    plan = render.frame_plan(make_run(duration=1.0), fps=30.0)
    # 1 s at 30 fps -> 30 frames; 100 / 30 = 3.33 cs -> delays of 30 or 40 ms
    assert len(plan) == 30
    assert set(plan.durations_ms.tolist()) == {30, 40}
    assert plan.durations_ms.sum() == 1000


def test_frame_plan_picks_nearest_samples_and_ends_on_last() -> None:
    run = make_run(duration=1.0, dt=0.1)  # samples every 0.1 s, 11 of them
    plan = render.frame_plan(run, fps=25.0)
    assert len(plan) == 25
    # frame 3 shows 3 * 0.04 = 0.12 s -> sample 1 (0.1 s); frame 4: 0.16 s -> sample 2
    assert plan.index[:5].tolist() == [0, 0, 1, 1, 2]
    assert plan.index[-1] == 10 and plan.times[-1] == pytest.approx(1.0)


def test_repeated_frames_are_merged_keeping_duration(tmp_path: Path) -> None:
    run = make_run(duration=1.0, dt=0.1)
    info = render.write_gif(run, tmp_path / "a.gif", fps=25.0, size=96)
    # 25 frames show only 11 distinct samples; delays add up to 1 s all the same
    assert info["frames"] == 11
    assert info["duration"] == pytest.approx(1.0)
    with Image.open(tmp_path / "a.gif") as im:
        total = 0
        for k in range(im.n_frames):
            im.seek(k)
            total += im.info["duration"]
    assert (im.n_frames, total) == (11, 1000)


def test_gif_decodes_to_the_rendered_frames_across_chunks(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(render, "GIF_CHUNK", 4)  # several imageio chunks
    run = make_run(n=3, duration=1.0)
    run.mode[40:60, 0] = MODE_AVOID
    run.events.append(CollisionEvent(0.5, "v0", "v1", "vehicle_vehicle"))
    info = render.write_gif(run, tmp_path / "a.gif", fps=20.0, size=96, zones=True)
    frames = np.stack(list(render.render_frames(run, fps=20.0, size=96, zones=True)))
    back = iio.imread(tmp_path / "a.gif", index=None, mode="RGB")
    assert info["frames"] == len(frames) == 20
    np.testing.assert_array_equal(back, frames)


def test_same_run_gives_identical_bytes(tmp_path: Path) -> None:
    run = make_run(n=3, duration=1.0)
    render.write_gif(run, tmp_path / "a.gif", fps=10.0, size=96)
    render.write_gif(run, tmp_path / "b.gif", fps=10.0, size=96)
    assert (tmp_path / "a.gif").read_bytes() == (tmp_path / "b.gif").read_bytes()


def test_failed_write_leaves_target_untouched(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "a.gif"
    out.write_bytes(b"old")

    def boom(*args: object) -> None:
        raise RuntimeError("disk full")

    monkeypatch.setattr(render._GifStream, "add", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        render.write_gif(make_run(duration=0.5), out, fps=10.0, size=96)
    assert out.read_bytes() == b"old"
    assert list(tmp_path.iterdir()) == [out]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fps": 60.0}, "fps"),
        ({"fps": 0.0}, "fps"),
        ({"speed": -1.0}, "speed"),
        ({"size": 10}, "size"),
        ({"follow": "nobody"}, "follow"),
    ],
)
def test_bad_arguments_raise(tmp_path: Path, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        render.write_gif(make_run(duration=0.5), tmp_path / "a.gif", **kwargs)


# ------------------------------------------------------------------------- geometry
def test_camera_flips_y_and_round_trips() -> None:
    cam = render.Camera(center=(1.0, 1.0), scale=20.0, size=100, anchor=(50.0, 50.0))
    # 1 m right of the centre -> 20 px right; 1 m up -> 20 px up (row decreases)
    assert cam.world_to_pixel([2.0, 1.0]).tolist() == [70.0, 50.0]
    assert cam.world_to_pixel([1.0, 2.0]).tolist() == [50.0, 30.0]
    pts = np.array([[0.3, -2.0], [5.0, 7.5]])
    np.testing.assert_allclose(cam.pixel_to_world(cam.world_to_pixel(pts)), pts)


def test_whole_run_camera_contains_every_pose() -> None:
    run = make_run(n=3, duration=4.0)
    cam = render.Camera.for_run(run, size=200)
    px = cam.world_to_pixel(run.pose[:, :, :2])
    assert (px > 0).all() and (px < 200).all()


def test_vehicle_pixel_has_its_colour() -> None:
    run = make_run(n=2, colors=["blue", "#ff8800"], diameter=0.6)
    cam = render.Camera.for_run(run, size=256)
    frame = frame_at(run, 1.0, size=256)
    k = int(np.argmin(np.abs(run.t - 1.0)))
    for i, color in enumerate(run.colors):
        uv = body_sample(cam, run.pose[k, i, :2], 0.3)
        assert pixel(frame, uv) == ImageColor.getrgb(color)
    # and far from every vehicle the background is white
    assert pixel(frame, cam.world_to_pixel([0.5, 1.5])) == (255, 255, 255)


def test_frames_are_rgb_uint8_of_the_requested_size() -> None:
    frames = list(render.render_frames(make_run(duration=0.4), fps=10.0, size=100))
    assert len(frames) == 4
    assert all(f.shape == (100, 100, 3) and f.dtype == np.uint8 for f in frames)


def test_follow_leader_keeps_leader_at_anchor() -> None:
    run = make_run(n=2, duration=2.0, speed=1.0)
    cam = render.Camera.for_run(run, size=200, follow="leader")
    for t in (0.0, 1.9):
        frame = frame_at(run, t, size=200, follow="leader")
        centre = np.array(cam.anchor) + [0.0, -0.5 * 0.25 * cam.scale]  # above centre
        assert pixel(frame, centre) == ImageColor.getrgb("blue")


# ------------------------------------------------------------------------- markers
def test_failure_mark_appears_only_after_failure_time() -> None:
    run = make_run(n=2, diameter=0.8)
    run.failed[run.t >= 1.0, 1] = True  # v1 (standing still) fails at 1 s
    cam = render.Camera.for_run(run, size=256)
    center = cam.world_to_pixel(run.pose[0, 1, :2])
    r = 0.4 * cam.scale  # [px]
    diag = center + np.array([-0.45, -0.45]) * r  # on the X, off the heading line
    before, after = frame_at(run, 0.5, size=256), frame_at(run, 1.5, size=256)
    assert pixel(before, diag) == ImageColor.getrgb("#ff8800")
    assert pixel(after, diag) == (0, 0, 0)
    box = np.s_[
        int(center[1] - r) : int(center[1] + r), int(center[0] - r) : int(center[0] + r)
    ]
    black = [int((f[box] == 0).all(axis=-1).sum()) for f in (before, after)]
    assert black[1] > black[0] + 10


def test_collision_flash_is_red_for_a_moment() -> None:
    run = make_run(n=2)
    run.events.append(CollisionEvent(1.0, "v0", "v1", "vehicle_vehicle"))
    red = np.array(render_palette._BASE_COLORS[render_palette.RED])

    def reds(t: float) -> int:
        return int((frame_at(run, t, size=160) == red).all(axis=-1).sum())

    assert reds(0.9) == 0
    assert reds(1.1) > 20
    assert reds(1.5) == 0  # 0.3 s later it is gone


def test_avoiding_vehicle_gets_an_orange_ring() -> None:
    run = make_run(n=2)
    run.mode[run.t >= 1.0, 0] = MODE_AVOID
    orange = np.array(render_palette._BASE_COLORS[render_palette.ORANGE])

    def oranges(t: float) -> int:
        return int((frame_at(run, t, size=160) == orange).all(axis=-1).sum())

    assert oranges(0.5) == 0
    assert oranges(1.5) > 10


def test_thousand_vehicles_render(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    run = make_run(n=1000, duration=0.2, dt=0.1, colors=["red"] * 1000, diameter=0.3)
    run.pose[:, :, :2] = rng.uniform(-50, 50, (1, 1000, 2))
    frames = list(render.render_frames(run, fps=10.0, size=320))
    red = (frames[-1] == ImageColor.getrgb("red")).all(axis=-1).sum()
    assert len(frames) == 2 and red > 500  # at least one pixel per vehicle, mostly
    assert (
        render.write_gif(run, tmp_path / "big.gif", fps=10.0, size=320)["frames"] == 2
    )


# ------------------------------------------------------------------------- headless
def test_renders_without_display(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    info = render.write_gif(make_run(duration=0.5), tmp_path / "a.gif", fps=10, size=96)
    assert info["frames"] == 5 and (tmp_path / "a.gif").stat().st_size > 500


def test_render_imports_only_numpy_pil_imageio() -> None:
    roots = set()
    for module in (render, render_camera, render_palette, render_overlay, gif_stream):
        tree = ast.parse(Path(module.__file__).read_text())
        roots |= {
            (alias.name if isinstance(node, ast.Import) else node.module).split(".")[0]
            for node in ast.walk(tree)
            if isinstance(node, (ast.Import, ast.ImportFrom))
            for alias in node.names
        }
    third_party = roots - set(sys.stdlib_module_names) - {"sandbox"}
    assert third_party == {"numpy", "PIL", "imageio"}


def test_write_gif_reports_progress_up_to_every_planned_frame(tmp_path: Path) -> None:
    run = make_run()
    calls: list[tuple[int, int]] = []
    render.write_gif(run, tmp_path / "p.gif", progress=lambda *a: calls.append(a))
    total = len(render.frame_plan(run).durations_ms)
    assert calls[-1] == (total, total)
    assert [d for d, _ in calls] == sorted({d for d, _ in calls})  # increasing
    assert 1 <= len(calls) <= 101


def test_the_heads_up_line_names_the_new_leader_after_a_handover() -> None:
    # A leader change (and reassignment) at 1 s and one at 1.9 s: the frames at 0.5 s
    # are the same, at 1.5 s the first reads "lead: v1  reassigned: 1" and the second
    # "reassigned: 0"; below the heads-up line nothing differs.
    def handed(at: float) -> Run:
        run = make_run()
        run.info["leader_changes"] = [
            {"t": at, "from": "v0", "to": "v1", "mode": "elect"}
        ]
        run.info["reassignments"] = [{"t": at, "assignment": {"v0": None, "v1": 0}}]
        return run

    soon, late = handed(1.0), handed(1.9)
    hud = render_overlay.font_px(640) + 6
    k = int(np.searchsorted(soon.t, 0.5))
    assert np.array_equal(render.render_frame(soon, k), render.render_frame(late, k))
    k = int(np.searchsorted(soon.t, 1.5))
    a, b = render.render_frame(soon, k), render.render_frame(late, k)
    assert not np.array_equal(a[:hud], b[:hud])
    assert np.array_equal(a[hud:], b[hud:])
    # a run without reconfiguration draws neither
    plain = render.render_frame(make_run(), k)
    assert not np.array_equal(plain[:hud], b[:hud])  # "reassigned: 0" is drawn
    assert np.array_equal(plain[hud:], b[hud:])
