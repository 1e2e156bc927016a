"""Headless animation of a recorded run: frames in memory and animated GIFs.

This module and its helpers are the only ones that draw frames: the camera and framing
(:mod:`sandbox.render_camera`), the palette and drawing primitives
(:mod:`sandbox.render_palette`), the text bands (:mod:`sandbox.render_overlay`: the
heads-up line, the scale bar and the legend strip) and the GIF encoder
(:mod:`sandbox.gif_stream`); :mod:`sandbox.video` writes the same frames as MP4. They
read a :class:`sandbox.run.Run` and never touch the simulation. Frames are drawn with
Pillow's ``ImageDraw`` (and, for large fleets, vectorized numpy stamps of the bodies) on
a canvas of palette indices: every colour a frame can contain is known before drawing
starts (white, black, greys, orange, red, blue, each vehicle's colour and a few paler
shades of it for trails), so no per-frame quantization is needed and the GIF palette is
exact. Drawing is not antialiased (that would need blended colours outside the
palette).

Timing
------
Frame ``k`` shows simulated time ``t0 + k * speed / fps`` [s] (the recorded sample
nearest to it), except the last frame, which always shows the final sample. A run
lasting ``D`` seconds gives ``round(D * fps / speed)`` frames, each displayed
``1 / fps`` seconds: a 20 s run at 25 fps gives 500 frames of 40 ms (20 s in all);
``speed=2`` gives 250 frames of 40 ms (10 s), i.e. the frame interval stays ``1 / fps``
and there are fewer frames.

GIF delays are whole centiseconds. Frame ``k`` is given the delay
``round((k + 1) * 100 / fps) - round(k * 100 / fps)`` [cs], so delays are exact when
``100 / fps`` is an integer (25 fps: 4 cs = 40 ms; 20 fps: 50 ms; 50 fps: 20 ms) and
otherwise alternate (30 fps: 30, 40, 30, ... ms) so that the total stays within 5 ms of
``frames / fps``. :func:`write_gif` accepts ``0 < fps <= 50`` because browsers slow
down delays under 20 ms. A frame identical to the previous one (a run recorded more
coarsely than the frame rate) is merged into it and their delays are added, so the GIF
may hold fewer frames than :func:`render_frames` yields; the total duration is
unchanged.

Large fleets
------------
Above :data:`LARGE_FLEET` vehicles, trails, slot marks and avoidance zones are not
drawn; bodies (with heading lines and avoidance rings) are stamped with numpy for all
vehicles at once; failure marks and collision flashes are still drawn.
"""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from sandbox.gif_stream import GifStream as _GifStream
from sandbox.render_camera import (
    AUTO_FOLLOW_ASPECT,
    LARGE_FLEET,
    Camera,
    _follow_track,
    _obstacles,
    _reference_path,
    _run_bands,
    auto_follow,
    resolve_follow,
)
from sandbox.render_overlay import (
    TextStamps,
    draw_bottom_band,
)
from sandbox.render_palette import (
    BLACK,
    BLUE,
    OBSTACLE,
    OBSTACLE_EDGE,
    ORANGE,
    PATH,
    RED,
    WHITE,
    ZONE,
    _build_palette,
    _dashes,
    _flat,
    _nice_length,
    _stamp_discs,
)
from sandbox.run import MODE_AVOID, MODE_EXTERNAL, MODE_FAILED, Run

__all__ = [
    "AUTO_FOLLOW_ASPECT",
    "Camera",
    "auto_follow",
    "FramePlan",
    "LARGE_FLEET",
    "frame_plan",
    "render_frames",
    "write_gif",
]

#: How long a collision flash stays visible [s] (simulated; at least 1.5 frames).
COLLISION_FLASH = 0.3
#: Highest frame rate :func:`write_gif` accepts [1/s] (browsers slow delays < 20 ms).
MAX_GIF_FPS = 50.0
#: Frames encoded per imageio call in :func:`write_gif` (bounds memory on long runs).
GIF_CHUNK = 128

_TRAIL_POINTS = 40  # at most about this many points per trail
_DASH_PX = (8.0, 6.0)  # reference path: dash and gap lengths [px]
_MIN_DETAIL_PX = 3.0  # bodies smaller than this radius [px] get no edge nor heading


# ---------------------------------------------------------------------------- timing
@dataclass(frozen=True)
class FramePlan:
    """Which sample each frame shows, and for how long.

    Attributes
    ----------
    times : ndarray, shape (K,) [s]
        Simulated time of each frame.
    index : ndarray, shape (K,), int
        Recorded sample shown by each frame (nearest to ``times``).
    durations_ms : ndarray, shape (K,), int [ms]
        Display time of each frame, whole centiseconds (GIF delays).
    """

    times: np.ndarray
    index: np.ndarray
    durations_ms: np.ndarray

    def __len__(self) -> int:
        """Return the number of frames ``K``."""
        return len(self.times)


def frame_plan(run: Run, fps: float = 25.0, speed: float = 1.0) -> FramePlan:
    """Frame times, samples and GIF delays of an animation of ``run``.

    Parameters
    ----------
    run : Run
    fps : float [1/s]
        Frames per second of playback.
    speed : float
        Simulated seconds per second of playback.

    Returns
    -------
    FramePlan
        ``round(D * fps / speed)`` frames (at least one) for a run lasting ``D``
        seconds; see the module docstring.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 20.0, 2001)
    >>> plan = frame_plan(type("R", (), {"t": t})(), fps=25.0)
    >>> len(plan), int(plan.durations_ms.sum()), int(plan.durations_ms[0])
    (500, 20000, 40)
    """
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps: expected a positive number, got {fps!r}")
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed: expected a positive number, got {speed!r}")
    t = np.asarray(run.t, dtype=float)
    if t.size == 0:
        raise ValueError("the run has no samples")
    step = speed / fps  # [s] simulated time per frame
    count = max(1, int(round((t[-1] - t[0]) / step)))
    times = t[0] + step * np.arange(count)
    times[-1] = t[-1]  # the end state is always shown
    right = np.clip(np.searchsorted(t, times), 1, max(len(t) - 1, 1))
    left = right - 1
    nearer_left = np.abs(times - t[left]) <= np.abs(
        t[np.minimum(right, len(t) - 1)] - times
    )
    index = np.where(nearer_left, left, right).clip(0, len(t) - 1)
    centis = np.round(np.arange(count + 1) * 100.0 / fps).astype(np.int64)
    return FramePlan(times, index, np.diff(centis) * 10)


# ---------------------------------------------------------------------------- scene
class _Scene:
    """What stays the same from frame to frame, and the drawing of one frame."""

    def __init__(
        self,
        run: Run,
        *,
        size: int,
        zones: bool,
        follow: str | None,
        trail_seconds: float,
        step: float,
        legend: bool = True,
    ) -> None:
        if int(size) < 64:
            raise ValueError(f"size: expected at least 64 px, got {size!r}")
        follow = resolve_follow(run, follow)
        self.run = run
        self.size = int(size)
        self.t = np.asarray(run.t, dtype=float)
        self.pos = np.asarray(run.pose[:, :, :2], dtype=float)
        self.theta = np.asarray(run.pose[:, :, 2], dtype=float)
        self.n = run.n_vehicles
        self.large = self.n > LARGE_FLEET
        self.rgb, self.body, self.trail_idx = _build_palette(run.colors)
        self.camera = Camera.for_run(run, self.size, follow, legend)
        self.bands = _run_bands(run, self.size, legend)
        self.stamps = TextStamps(self.bands.px)
        self.track = None if follow is None else _follow_track(run, follow)
        self.radius_px = np.asarray(run.diameter, dtype=float) / 2.0 * self.camera.scale
        self.mode = np.asarray(run.mode)
        self.failed_raw = np.asarray(run.failed, dtype=bool)
        self.slot = np.asarray(run.slot, dtype=float)
        self.reference = np.asarray(run.reference, dtype=float).reshape(-1, 2)
        # Trails: a fixed sample grid, so the polylines do not shimmer between frames.
        self.trail_seconds = float(trail_seconds)
        self.trails = (
            not self.large and self.trail_seconds > 0 and self.trail_idx.shape[1] > 0
        )
        dt = float(np.median(np.diff(self.t))) if len(self.t) > 1 else 1.0
        window = self.trail_seconds / dt if dt > 0 else 1.0
        self.trail_stride = max(1, int(math.ceil(window / _TRAIL_POINTS)))
        self.trail_start = np.searchsorted(self.t, self.t - self.trail_seconds)
        self.trail_width = 2 if self.n <= 20 else 1
        # Recovery zones.
        rec = run.info.get("recovery") if isinstance(run.info, dict) else None
        rec = rec if isinstance(rec, dict) else {}
        self.strategy = str(rec.get("strategy", "-"))
        self.zone_radii = [
            float(v) for v in (rec.get("R"), rec.get("r")) if v is not None and v > 0
        ]
        self.zones = bool(zones) and not self.large and bool(self.zone_radii)
        # Static geometry.
        self.obstacles = _obstacles(run)
        path = _reference_path(run)
        on, off = (v / self.camera.scale for v in _DASH_PX)
        self.dashes = np.zeros((0, 2, 2)) if path is None else _dashes(path, on, off)
        self.bar = _nice_length(0.22 * self.size / self.camera.scale)
        self.bottom_band = draw_bottom_band(
            self.bands,
            bar_m=self.bar,
            bar_px=self.bar * self.camera.scale,
            white=WHITE,
            black=BLACK,
            marks={"path": PATH, "orange": ORANGE, "blue": BLUE, "red": RED},
        )
        # Collisions: where and when to flash.
        self._prepare_events(step)
        label = run.info.get("scenario_name") if isinstance(run.info, dict) else None
        self.hud_prefix = str(label) if label else ""
        # Reconfiguration on the heads-up line: who leads (after a handover) and how
        # many reassignments so far (runs without them draw neither).
        info = run.info if isinstance(run.info, dict) else {}
        leads = info.get("leader_changes") or []
        self.lead_t = np.array([c["t"] for c in leads], dtype=float)
        self.lead_to = [c["to"] or "reference" for c in leads]
        moves = info.get("reassignments") or []
        self.reassign_t = np.array([e["t"] for e in moves], dtype=float)
        self.background = (
            None if self.track is not None else self._background(self.camera)
        )

    # ------------------------------------------------------------ preparation
    def _prepare_events(self, step: float) -> None:
        index = {name: k for k, name in enumerate(self.run.names)}
        times, where, reach = [], [], []
        for ev in self.run.events:
            k = int(np.clip(np.searchsorted(self.t, ev.t), 0, len(self.t) - 1))
            bodies = [index[x] for x in (ev.a, ev.b) if x in index]
            if not bodies:
                continue
            p = self.pos[k, bodies].mean(axis=0)
            if not np.isfinite(p).all():
                continue
            times.append(float(ev.t))
            where.append(p)
            reach.append(float(self.radius_px[bodies].max()))
        order = np.argsort(times, kind="stable")
        self.flash_t = np.asarray(times, dtype=float)[order]
        self.flash_at = np.asarray(where, dtype=float).reshape(-1, 2)[order]
        self.flash_r = np.asarray(reach, dtype=float)[order]
        self.event_t = np.sort(np.array([float(e.t) for e in self.run.events]))
        self.flash_for = max(COLLISION_FLASH, 1.5 * step)

    def _background(self, cam: Camera) -> Image.Image:
        """White canvas with obstacles and reference path."""
        img = Image.new("L", (self.size, self.size), WHITE)
        draw = ImageDraw.Draw(img)
        for kind, geom in self.obstacles:
            if kind == "circle":
                (cx, cy), r = geom
                u, v = cam.world_to_pixel([cx, cy]) - 0.5
                rp = r * cam.scale
                draw.ellipse(
                    [u - rp, v - rp, u + rp, v + rp],
                    fill=OBSTACLE,
                    outline=OBSTACLE_EDGE,
                )
            else:
                pts = _flat(cam.world_to_pixel(geom))
                draw.polygon(pts, fill=OBSTACLE, outline=OBSTACLE_EDGE)
        if len(self.dashes):
            seg = cam.world_to_pixel(self.dashes)  # (k, 2, 2)
            lo, hi = seg.min(axis=1), seg.max(axis=1)
            seen = (hi > -2).all(axis=1) & (lo < self.size + 2).all(axis=1)
            for a in seg[seen]:
                draw.line(_flat(a), fill=PATH, width=1)
        return img

    # ------------------------------------------------------------ one frame
    def draw(self, k: int) -> np.ndarray:
        """Palette-index canvas (size, size) uint8 of recorded sample ``k``."""
        cam = self.camera
        if self.track is not None:
            cam = cam.centered_on(self.track[k])
            img = self._background(cam)
        else:
            assert self.background is not None
            img = self.background.copy()
        failed = self.failed_raw[k] | (self.mode[k] == MODE_FAILED)
        avoid = (self.mode[k] == MODE_AVOID) & ~failed
        external = (self.mode[k] == MODE_EXTERNAL) & ~failed
        ring = np.where(external, BLUE, ORANGE)
        draw = ImageDraw.Draw(img)
        draw.fontmode = "1"
        if self.trails:
            self._draw_trails(draw, cam, k)
        ref = self.reference[k] if k < len(self.reference) else np.full(2, np.nan)
        if np.isfinite(ref).all():
            u, v = cam.world_to_pixel(ref) - 0.5
            draw.line([u - 4, v, u + 4, v], fill=PATH, width=1)
            draw.line([u, v - 4, u, v + 4], fill=PATH, width=1)
        if self.zones:
            self._draw_zones(draw, cam, k, avoid, failed)
        centers = cam.world_to_pixel(self.pos[k])
        radius = np.maximum(self.radius_px, 0.75)  # [px] every body shows
        halo = max(2.0, min(4.0, 0.25 * float(np.median(radius))))  # [px]
        if self.large:  # vectorized stamps; no slot marks
            canvas = np.array(img)
            _stamp_discs(
                canvas,
                centers,
                radius,
                fill=self.body,
                edge=np.full(self.n, BLACK),
                heading=self.theta[k],
                heading_width=np.maximum(2.0, 0.2 * radius),
                detail=radius >= _MIN_DETAIL_PX,
                halo=avoid | external,
                halo_width=halo,
                halo_color=ring,
            )
            img = Image.fromarray(canvas)
            draw = ImageDraw.Draw(img)
            draw.fontmode = "1"
        else:
            self._draw_slots(draw, cam.world_to_pixel(self.slot[k]))
            self._draw_bodies(
                draw, centers, radius, self.theta[k], avoid | external, halo, ring
            )
        self._draw_failures(draw, centers[failed], radius[failed])
        self._draw_flashes(draw, cam, self.t[k])
        self._draw_hud(draw, img, self.t[k])
        img.paste(self.bottom_band, (0, self.size - self.bands.bottom))
        return np.asarray(img)

    def _draw_slots(self, draw: ImageDraw.ImageDraw, slots: np.ndarray) -> None:
        ring = np.clip(0.35 * self.radius_px, 3.0, 8.0)  # [px]
        for i in np.flatnonzero(np.isfinite(slots).all(axis=1)):
            u, v = slots[i] - 0.5
            r = ring[i]
            width = 2 if r >= 5 else 1
            draw.ellipse(
                [u - r, v - r, u + r, v + r], outline=int(self.body[i]), width=width
            )

    def _draw_bodies(
        self,
        draw: ImageDraw.ImageDraw,
        centers: np.ndarray,
        radius: np.ndarray,
        theta: np.ndarray,
        avoid: np.ndarray,
        halo: float,
        ring: np.ndarray | None = None,
    ) -> None:
        """Bodies (fill, black edge, heading line) and rings of avoiders.

        The ring is orange, or the palette index ``ring[i]`` (blue for vehicles in
        external mode).
        """
        ok = np.isfinite(centers).all(axis=1) & np.isfinite(theta)
        for i in np.flatnonzero(ok):
            u, v = centers[i] - 0.5
            r = float(radius[i])
            if avoid[i]:
                h = r + halo
                color = ORANGE if ring is None else int(ring[i])
                draw.ellipse([u - h, v - h, u + h, v + h], fill=color)
            box = [u - r, v - r, u + r, v + r]
            if r < _MIN_DETAIL_PX:
                draw.ellipse(box, fill=int(self.body[i]))
                continue
            draw.ellipse(box, fill=int(self.body[i]), outline=BLACK, width=1)
            tip = (u + r * math.cos(theta[i]), v - r * math.sin(theta[i]))
            width = max(2, int(round(0.2 * r)))
            draw.line([u, v, *tip], fill=BLACK, width=width)

    def _draw_trails(self, draw: ImageDraw.ImageDraw, cam: Camera, k: int) -> None:
        k0 = int(self.trail_start[k])
        stride = self.trail_stride
        grid = np.arange(-(-k0 // stride) * stride, k, stride)
        idx = np.concatenate((grid, [k]))
        if len(idx) < 2:
            return
        pts = cam.world_to_pixel(self.pos[idx]) - 0.5  # (m, n, 2), ImageDraw's pixels
        age = self.t[k] - self.t[idx[1:]]  # each segment takes its newer end's age
        levels = self.trail_idx.shape[1]
        band = np.minimum((age / self.trail_seconds * levels).astype(int), levels - 1)
        cuts = np.flatnonzero(np.diff(band)) + 1
        for seg in np.split(np.arange(len(band)), cuts):
            b = band[seg[0]]
            chunk = pts[seg[0] : seg[-1] + 2]  # points of the segments, ends shared
            good = np.isfinite(chunk).all(axis=(0, 2))
            for i in np.flatnonzero(good):
                draw.line(
                    chunk[:, i].ravel().tolist(),
                    fill=int(self.trail_idx[i, b]),
                    width=self.trail_width,
                )

    def _draw_zones(
        self,
        draw: ImageDraw.ImageDraw,
        cam: Camera,
        k: int,
        avoid: np.ndarray,
        failed: np.ndarray,
    ) -> None:
        centers = cam.world_to_pixel(self.pos[k]) - 0.5
        for i in range(self.n):
            if failed[i] or not np.isfinite(centers[i]).all():
                continue
            color = ORANGE if avoid[i] else ZONE
            u, v = centers[i]
            for rz in self.zone_radii:
                rp = rz * cam.scale
                draw.ellipse([u - rp, v - rp, u + rp, v + rp], outline=color, width=1)

    def _draw_failures(
        self, draw: ImageDraw.ImageDraw, centers: np.ndarray, radius: np.ndarray
    ) -> None:
        for c, r in zip(centers, radius, strict=True):
            if not np.isfinite(c).all():
                continue
            u, v = c - 0.5
            h = max(float(r), 5.0)
            width = max(2, int(round(0.22 * h)))
            draw.line([u - h, v - h, u + h, v + h], fill=BLACK, width=width)
            draw.line([u - h, v + h, u + h, v - h], fill=BLACK, width=width)

    def _draw_flashes(self, draw: ImageDraw.ImageDraw, cam: Camera, now: float) -> None:
        if len(self.flash_t) == 0:
            return
        lo = np.searchsorted(self.flash_t, now - self.flash_for, side="right")
        hi = np.searchsorted(self.flash_t, now, side="right")
        for j in range(lo, hi):
            u, v = cam.world_to_pixel(self.flash_at[j]) - 0.5
            rho = max(8.0, 1.4 * float(self.flash_r[j]))
            draw.ellipse([u - rho, v - rho, u + rho, v + rho], outline=RED, width=2)
            for a in np.arange(8) * (np.pi / 4):
                c, s = math.cos(a), math.sin(a)
                draw.line(
                    [
                        u + 1.2 * rho * c,
                        v + 1.2 * rho * s,
                        u + 1.7 * rho * c,
                        v + 1.7 * rho * s,
                    ],
                    fill=RED,
                    width=2,
                )

    def _draw_hud(
        self, draw: ImageDraw.ImageDraw, img: Image.Image, now: float
    ) -> None:
        """The heads-up line: scenario, time, collisions, lead, recovery strategy.

        The lead and the number of reassignments so far only with such events.
        """
        hits = int(np.searchsorted(self.event_t, now, side="right"))
        draw.rectangle([0, 0, self.size - 1, self.bands.top - 1], fill=WHITE)
        x, y = max(4, int(0.02 * self.size)), 3
        if self.hud_prefix:
            x = self.stamps.paste(img, (x, y), self.hud_prefix, BLACK)
        x = self.stamps.paste(img, (x, y), "t =", BLACK) - self.bands.px // 2
        x = self.stamps.paste_number(img, (x, y), f"{now:.2f}", BLACK)
        x = self.stamps.paste(img, (x, y), " s", BLACK)
        x = self.stamps.paste(img, (x, y), f"collisions: {hits}", BLACK)
        led = int(np.searchsorted(self.lead_t, now, side="right"))
        if led:
            x = self.stamps.paste(img, (x, y), f"lead: {self.lead_to[led - 1]}", BLACK)
        if len(self.reassign_t):
            moved = int(np.searchsorted(self.reassign_t, now, side="right"))
            x = self.stamps.paste(img, (x, y), f"reassigned: {moved}", BLACK)
        last = f"recovery: {self.strategy}"
        if x + self.stamps.mask(last).width <= self.size:  # whole, or not at all
            self.stamps.paste(img, (x, y), last, BLACK)

    def to_rgb(self, canvas: np.ndarray) -> np.ndarray:
        """RGB image (H, W, 3) uint8 of a palette-index canvas."""
        img = Image.fromarray(canvas)
        img.putpalette(self.rgb.tobytes())
        return np.asarray(img.convert("RGB"))


def _check_follow(follow: str | None) -> None:
    if follow is not None and not isinstance(follow, str):
        raise ValueError(
            f"follow: expected None, 'auto', 'leader' or a vehicle name, got {follow!r}"
        )


def _indexed_frames(
    run: Run,
    plan: FramePlan,
    *,
    size: int,
    zones: bool,
    follow: str | None,
    trail_seconds: float,
    speed: float,
    fps: float,
    legend: bool = True,
) -> tuple[_Scene, Iterator[np.ndarray]]:
    _check_follow(follow)
    scene = _Scene(
        run,
        size=size,
        zones=zones,
        follow=follow,
        trail_seconds=trail_seconds,
        step=speed / fps,
        legend=legend,
    )
    return scene, (scene.draw(int(k)) for k in plan.index)


# ------------------------------------------------------------------------- public API
def render_frames(
    run: Run,
    *,
    fps: float = 25.0,
    size: int = 640,
    speed: float = 1.0,
    zones: bool = False,
    follow: str | None = None,
    trail_seconds: float = 3.0,
    legend: bool = True,
) -> Iterator[np.ndarray]:
    """Frames of an animation of ``run``, drawn lazily.

    Parameters
    ----------
    run : Run
    fps : float [1/s]
        Frames per second of playback.
    size : int [px]
        Width and height of every frame.
    speed : float
        Playback speed: simulated seconds per second of playback (2 plays twice as fast,
        with half the frames).
    zones : bool
        Draw each vehicle's avoidance radii ``R`` (and ``r``) from ``info["recovery"]``
        as thin circles: orange while the vehicle is avoiding, light grey otherwise.
    follow : {None, "auto", "leader"} or str
        Camera, see :meth:`Camera.for_run`.
    trail_seconds : float [s]
        Length of the fading trails (0 disables them).
    legend : bool
        Draw the legend strip at the bottom: each vehicle's name by its colour (or the
        fleet's size above :data:`~sandbox.render_overlay.LEGEND_NAMES_MAX` vehicles)
        and what the marks the run shows mean.

    Yields
    ------
    ndarray, shape (size, size, 3), uint8
        One RGB frame per entry of :func:`frame_plan`.
    """
    plan = frame_plan(run, fps, speed)
    scene, frames = _indexed_frames(
        run,
        plan,
        size=size,
        zones=zones,
        follow=follow,
        trail_seconds=trail_seconds,
        speed=speed,
        fps=fps,
        legend=legend,
    )
    for canvas in frames:
        yield scene.to_rgb(canvas)


def render_frame(
    run: Run,
    k: int = -1,
    *,
    size: int = 640,
    zones: bool = False,
    follow: str | None = None,
    trail_seconds: float = 3.0,
    legend: bool = True,
) -> np.ndarray:
    """One RGB frame of recorded sample ``k`` (default the last), as drawn in a GIF.

    Parameters are those of :func:`render_frames`; the camera frames the samples of
    ``run`` (or follows ``follow``). Used for the ``rgb_array`` render mode of the
    environments in :mod:`sandbox.envs`, which pass the episode so far.

    Returns
    -------
    ndarray, shape (size, size, 3), uint8
    """
    _check_follow(follow)
    scene = _Scene(
        run,
        size=size,
        zones=zones,
        follow=follow,
        trail_seconds=trail_seconds,
        step=1.0 / 25.0,
        legend=legend,
    )
    return scene.to_rgb(scene.draw(int(k) % len(run.t)))


def write_gif(
    run: Run,
    path: str | os.PathLike[str],
    *,
    fps: float = 25.0,
    size: int = 640,
    speed: float = 1.0,
    zones: bool = False,
    follow: str | None = None,
    trail_seconds: float = 3.0,
    legend: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Write an animated GIF of ``run``, atomically.

    The GIF loops forever and uses one global palette: the run's fixed colours. imageio
    (its Pillow plugin) encodes the frames, :data:`GIF_CHUNK` at a time so memory stays
    bounded on long runs; the chunks are joined into one GIF stream written to a
    temporary file next to ``path``, which then replaces ``path``.

    Parameters
    ----------
    run : Run
    path : str or os.PathLike
        Output file; its directory is created if needed.
    fps : float [1/s]
        ``0 < fps <= 50``; see the module docstring for delays.
    size, speed, zones, follow, trail_seconds, legend
        As in :func:`render_frames`.
    progress : callable, optional
        Called as ``progress(done, total)`` about a hundred times, in planned frames.

    Returns
    -------
    dict
        ``{"frames": k, "duration": seconds, "path": str}``: frames written (consecutive
        identical frames are merged), total display time [s] and the output path.
    """
    if not (0 < fps <= MAX_GIF_FPS):
        raise ValueError(
            f"fps: expected 0 < fps <= {MAX_GIF_FPS:g} for a GIF, got {fps!r}"
        )
    path = Path(path)
    plan = frame_plan(run, fps, speed)
    scene, frames = _indexed_frames(
        run,
        plan,
        size=size,
        zones=zones,
        follow=follow,
        trail_seconds=trail_seconds,
        speed=speed,
        fps=fps,
        legend=legend,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "xb") as fh:
            stream = _GifStream(fh, scene.size, scene.size, scene.rgb, loop=0)
            held: list[np.ndarray] = []
            delays: list[int] = []
            total = len(plan.durations_ms)
            every = max(1, total // 100)
            pairs = zip(frames, plan.durations_ms.tolist(), strict=True)
            for k, (canvas, ms) in enumerate(pairs, 1):
                if progress is not None and (k % every == 0 or k == total):
                    progress(k, total)
                if held and np.array_equal(canvas, held[-1]):
                    delays[-1] += ms
                    continue
                if len(held) == GIF_CHUNK:  # keep the last one: its delay may grow
                    stream.add(held[:-1], delays[:-1])
                    held, delays = held[-1:], delays[-1:]
                held.append(canvas)
                delays.append(ms)
            stream.add(held, delays)
            stream.close()
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return {
        "frames": stream.frames,
        "duration": stream.duration_ms / 1000.0,
        "path": str(path),
    }


from sandbox.replay import write_html  # noqa: E402,F401
