"""Headless animation of a recorded run: frames in memory and animated GIFs.

This is the only module that draws frames. It reads a :class:`sandbox.run.Run` and
never touches the simulation. Frames are drawn with Pillow's ``ImageDraw`` (and, for
large fleets, vectorized numpy stamps of the bodies) on a canvas of palette indices:
every colour a frame can contain is known before drawing starts (white, black, greys,
orange, red, each vehicle's colour and a few paler shades of it for trails), so no
per-frame quantization is needed and the GIF palette is exact. Drawing is not
antialiased (that would need blended colours outside the palette).

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
import struct
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import imageio.v3 as iio
import numpy as np
from numpy.typing import ArrayLike
from PIL import Image, ImageColor, ImageDraw

from sandbox.render_overlay import (
    LEGEND_NAMES_MAX,
    Bands,
    LegendItem,
    TextStamps,
    draw_bottom_band,
    frame_bands,
)
from sandbox.run import MODE_AVOID, MODE_EXTERNAL, MODE_FAILED, Run

__all__ = [
    "Camera",
    "FramePlan",
    "LARGE_FLEET",
    "frame_plan",
    "render_frames",
    "write_gif",
]

#: Fleets larger than this are drawn without trails, slot marks and zones.
LARGE_FLEET = 100
#: How long a collision flash stays visible [s] (simulated; at least 1.5 frames).
COLLISION_FLASH = 0.3
#: Highest frame rate :func:`write_gif` accepts [1/s] (browsers slow delays < 20 ms).
MAX_GIF_FPS = 50.0
#: Frames encoded per imageio call in :func:`write_gif` (bounds memory on long runs).
GIF_CHUNK = 128

_MARGIN = 0.04  # fraction of the image size kept free around the content
_TRAIL_LEVELS = 4  # fading steps of a trail
_TRAIL_FADE = (0.2, 0.45, 0.65, 0.82)  # blend toward white of each step, newest first
_TRAIL_POINTS = 40  # at most about this many points per trail
_DASH_PX = (8.0, 6.0)  # reference path: dash and gap lengths [px]
_MIN_DETAIL_PX = 3.0  # bodies smaller than this radius [px] get no edge nor heading

# Fixed palette entries (indices); vehicle colours follow.
WHITE, BLACK, OBSTACLE, OBSTACLE_EDGE, PATH, ORANGE, RED, ZONE, BLUE = range(9)
_BASE_COLORS = (
    (255, 255, 255),  # WHITE: background
    (0, 0, 0),  # BLACK: heading lines, edges, failure marks, text
    (175, 175, 175),  # OBSTACLE: fill
    (110, 110, 110),  # OBSTACLE_EDGE
    (128, 128, 128),  # PATH: reference path and reference point
    (255, 140, 0),  # ORANGE: avoidance mode
    (225, 0, 0),  # RED: collision flashes
    (200, 200, 200),  # ZONE: avoidance radii of vehicles not avoiding
    (0, 120, 255),  # BLUE: external mode (driven through Simulation.step)
)
_FALLBACK_COLORS = (
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd",
    "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf",
)  # fmt: skip


# ---------------------------------------------------------------------------- camera
@dataclass(frozen=True)
class Camera:
    """Map from world coordinates [m] (y up) to pixel coordinates (y down).

    Pixel coordinates are continuous: pixel ``(col, row)`` covers ``[col, col + 1) x
    [row, row + 1)``, so the pixel containing a world point is ``floor`` of its pixel
    coordinates. One metre is ``scale`` pixels along both axes (1:1 aspect).

    Attributes
    ----------
    center : tuple of float [m]
        World point drawn at ``anchor``.
    scale : float [px/m]
    size : int [px]
        Width and height of the (square) image.
    anchor : tuple of float [px]
        Pixel coordinates of ``center``.

    Examples
    --------
    >>> cam = Camera(center=(0.0, 0.0), scale=10.0, size=100, anchor=(50.0, 50.0))
    >>> cam.world_to_pixel([1.0, 2.0]).tolist()
    [60.0, 30.0]
    >>> cam.pixel_to_world([60.0, 30.0]).tolist()
    [1.0, 2.0]
    """

    center: tuple[float, float]
    scale: float
    size: int
    anchor: tuple[float, float]

    def world_to_pixel(self, xy: ArrayLike) -> np.ndarray:
        """Pixel coordinates of world points.

        Parameters
        ----------
        xy : array_like, shape (..., 2) [m]

        Returns
        -------
        ndarray, shape (..., 2) [px]
            Column then row, as floats.
        """
        xy = np.asarray(xy, dtype=float)
        col = self.anchor[0] + (xy[..., 0] - self.center[0]) * self.scale
        row = self.anchor[1] - (xy[..., 1] - self.center[1]) * self.scale
        return np.stack((col, row), axis=-1)

    def pixel_to_world(self, px: ArrayLike) -> np.ndarray:
        """World coordinates of pixel points, the inverse of :meth:`world_to_pixel`.

        Parameters
        ----------
        px : array_like, shape (..., 2) [px]

        Returns
        -------
        ndarray, shape (..., 2) [m]
        """
        px = np.asarray(px, dtype=float)
        x = self.center[0] + (px[..., 0] - self.anchor[0]) / self.scale
        y = self.center[1] - (px[..., 1] - self.anchor[1]) / self.scale
        return np.stack((x, y), axis=-1)

    def centered_on(self, center: ArrayLike) -> Camera:
        """Return this camera moved so that ``center`` [m] is drawn at the anchor."""
        c = np.asarray(center, dtype=float)
        return Camera((float(c[0]), float(c[1])), self.scale, self.size, self.anchor)

    @classmethod
    def fit(
        cls,
        lo: ArrayLike,
        hi: ArrayLike,
        size: int,
        bands: tuple[int, int] = (16, 18),
    ) -> Camera:
        """Camera showing the world box ``[lo, hi]`` [m] whole, with a margin.

        The box is centred in the viewport, the part of the image below the heads-up
        band and above the bottom band (scale bar and legend), ``bands = (top,
        bottom)`` [px] high.
        """
        lo = np.asarray(lo, dtype=float)
        hi = np.asarray(hi, dtype=float)
        x0, y0, x1, y1 = _viewport(size, bands)
        y1 = max(y1, y0 + 1.0)  # [px] bands taller than the frame: a one-pixel view
        extent = np.maximum(hi - lo, 1e-9)
        scale = float(min((x1 - x0) / extent[0], (y1 - y0) / extent[1]))
        mid = (lo + hi) / 2.0
        return cls(
            (float(mid[0]), float(mid[1])), scale, size, ((x0 + x1) / 2, (y0 + y1) / 2)
        )

    @classmethod
    def for_run(
        cls,
        run: Run,
        size: int = 640,
        follow: str | None = None,
        legend: bool = True,
    ) -> Camera:
        """Build the camera of the first frame of ``run``.

        Parameters
        ----------
        run : Run
        size : int [px]
        follow : {None, "auto", "leader"} or str
            ``None``: the whole run is framed (every pose, the reference path and the
            obstacles) and the camera never moves. ``"leader"`` or a vehicle name: a
            window centred on that vehicle (the fleet centroid when ``"leader"`` is
            asked of a run without leader), 1.3 times as wide as the initial formation;
            :func:`render_frames` recentres it on every frame. ``"auto"``: the choice
            of :func:`auto_follow` (``"leader"`` for a run spread along a line).
        legend : bool
            Whether the frame has a legend strip (the viewport leaves room for it).

        Returns
        -------
        Camera
        """
        follow = resolve_follow(run, follow)
        pos = run.pose[:, :, :2]
        reach = float(np.max(run.diameter, initial=0.0)) / 2.0
        bands = _run_bands(run, size, legend)
        edges = (bands.top, bands.bottom)
        if follow is None:
            lo, hi = _content_bounds(run, reach)
            return cls.fit(lo, hi, size, edges)
        track = _follow_track(run, follow)
        first = pos[0][np.isfinite(pos[0]).all(axis=1)]
        spread = float(np.max(np.linalg.norm(first - track[0], axis=1), initial=0.0))
        width = max(1.3 * 2.0 * (spread + reach), 10.0 * reach, 1e-3)  # [m]
        c = track[0]
        return cls.fit(c - width / 2, c + width / 2, size, edges)


#: Above this ratio of the sides of the area a run covers, ``follow="auto"`` follows
#: the leader.
AUTO_FOLLOW_ASPECT = 2.5


def auto_follow(run: Run) -> str | None:
    """The automatic camera: ``"leader"`` for a run spread along a line, else None.

    A run whose covered area (every pose, plus a vehicle diameter) is more than
    :data:`AUTO_FOLLOW_ASPECT` times longer than wide, and that has a leader, would be
    drawn tiny in a square frame holding all of it (a platoon on a straight
    reference): the camera follows the leader instead. Otherwise the whole run is
    framed.
    """
    if run.leader < 0:
        return None
    box = _finite_box(run.pose[:, :, :2])
    if box is None:
        return None
    extent = box[1] - box[0] + float(np.max(run.diameter, initial=0.0))
    return "leader" if extent.max() > AUTO_FOLLOW_ASPECT * extent.min() else None


def resolve_follow(run: Run, follow: str | None) -> str | None:
    """``follow`` with ``"auto"`` replaced by the choice of :func:`auto_follow`."""
    return auto_follow(run) if follow == "auto" else follow


def _viewport(
    size: int, bands: tuple[int, int] = (16, 18)
) -> tuple[float, float, float, float]:
    """Pixel box ``(x0, y0, x1, y1)`` the world content is fitted into."""
    pad = _MARGIN * size
    return pad, bands[0] + pad, size - pad, size - bands[1] - pad


def _legend_items(run: Run, body: np.ndarray, large: bool) -> list[LegendItem]:
    """The legend strip of ``run``: its vehicles, then the marks its frames show."""
    if run.n_vehicles <= LEGEND_NAMES_MAX:
        items = [
            LegendItem("vehicle", name, int(body[i]))
            for i, name in enumerate(run.names)
        ]
    else:
        items = [LegendItem("vehicle", f"{run.n_vehicles} vehicles", int(body[0]))]
    mode = np.asarray(run.mode)
    if _reference_path(run) is not None:
        items.append(LegendItem("reference", "reference"))
    if not large:
        items.append(LegendItem("slot", "slot"))
    if (mode == MODE_AVOID).any():
        items.append(LegendItem("avoid", "avoiding"))
    if (mode == MODE_EXTERNAL).any():
        items.append(LegendItem("external", "external command"))
    if np.asarray(run.failed, dtype=bool).any() or (mode == MODE_FAILED).any():
        items.append(LegendItem("failed", "failed"))
    if len(run.events):
        items.append(LegendItem("collision", "collision"))
    return items


def _run_bands(run: Run, size: int, legend: bool) -> Bands:
    """Layout of the text bands of ``run``'s frames (no legend rows without legend)."""
    if not legend:
        return frame_bands(int(size), [])
    _, body, _ = _build_palette(run.colors)
    return frame_bands(
        int(size), _legend_items(run, body, run.n_vehicles > LARGE_FLEET)
    )


def _content_bounds(run: Run, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """World bounding box [m] of poses, reference path and obstacles."""
    boxes = [_finite_box(run.pose[:, :, :2]), _finite_box(run.reference)]
    path = _reference_path(run)
    if path is not None:
        boxes.append(_finite_box(path))
    for kind, geom in _obstacles(run):
        if kind == "circle":
            (cx, cy), r = geom
            boxes.append((np.array([cx - r, cy - r]), np.array([cx + r, cy + r])))
        else:
            boxes.append(_finite_box(geom))
    found = [b for b in boxes if b is not None]
    if found:
        lo = np.min([b[0] for b in found], axis=0) - reach
        hi = np.max([b[1] for b in found], axis=0) + reach
    else:
        lo, hi = np.full(2, -reach), np.full(2, reach)
    side = max(float(np.max(hi - lo)), 8.0 * reach, 0.5)  # [m] never a degenerate box
    half = np.maximum((hi - lo) / 2.0, side / 2.0)
    mid = (lo + hi) / 2.0
    return mid - half, mid + half


def _finite_box(points: ArrayLike) -> tuple[np.ndarray, np.ndarray] | None:
    """Bounding box ``(lo, hi)`` of the finite points of an array (..., 2), or None.

    Reads a large (possibly memory-mapped) array a block of samples at a time.
    """
    arr = np.asarray(points, dtype=float)
    arr = arr.reshape(len(arr), -1, 2) if arr.ndim >= 2 else arr.reshape(1, -1, 2)
    step = max(1, 1_000_000 // max(arr.shape[1], 1))
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    for start in range(0, len(arr), step):
        block = arr[start : start + step].reshape(-1, 2)
        block = block[np.isfinite(block).all(axis=1)]
        if len(block):
            lo = np.minimum(lo, block.min(axis=0))
            hi = np.maximum(hi, block.max(axis=0))
    return (lo, hi) if np.isfinite(lo).all() else None


def _follow_track(run: Run, follow: str) -> np.ndarray:
    """Point the camera follows at each sample, shape (T, 2) [m]."""
    pos = run.pose[:, :, :2]
    if follow == "leader" and run.leader >= 0:
        track = pos[:, run.leader].copy()
    elif follow == "leader":
        alive = np.isfinite(pos).all(axis=2) & ~np.asarray(run.failed, dtype=bool)
        count = alive.sum(axis=1)
        total = np.where(alive[..., None], pos, 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            track = total / count[:, None]
    elif follow in run.names:
        track = pos[:, run.names.index(follow)].copy()
    else:
        raise ValueError(
            f"follow: expected None, 'auto', 'leader' or a vehicle name in "
            f"{run.names}, got {follow!r}"
        )
    # Hold the last finite point where the followed point is undefined.
    good = np.isfinite(track).all(axis=1)
    if not good.any():
        return np.zeros_like(track)
    last = np.maximum.accumulate(np.where(good, np.arange(len(track)), -1))
    last[last < 0] = int(np.argmax(good))
    return track[last]


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
def _reference_path(run: Run) -> np.ndarray | None:
    """Return the reference path (m, 2) [m]: ``info["reference_path"]`` or samples."""
    raw = run.info.get("reference_path") if isinstance(run.info, dict) else None
    pts = None
    if raw is not None:
        arr = np.asarray(raw, dtype=float)
        if arr.ndim == 2 and arr.shape[1] == 2:
            pts = arr
    if pts is None:
        pts = np.asarray(run.reference, dtype=float).reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(axis=1)]
    return pts if len(pts) >= 2 else None


def _obstacles(run: Run) -> list[tuple[str, Any]]:
    """List obstacles as ``("circle", ((x, y), r))`` or ``("polygon", (m, 2))`` [m]."""
    out: list[tuple[str, Any]] = []
    raw = run.info.get("obstacles", []) if isinstance(run.info, dict) else []
    for ob in raw or []:
        kind = ob.get("type")
        if kind == "circle":
            c = np.asarray(ob["center"], dtype=float)
            out.append(("circle", ((float(c[0]), float(c[1])), float(ob["radius"]))))
        elif kind == "polygon":
            pts = np.asarray(ob["points"], dtype=float).reshape(-1, 2)
            if len(pts) >= 2:
                out.append(("polygon", pts))
    return out


def _rgb(color: str, k: int) -> tuple[int, int, int]:
    """RGB of a colour name, or a default colour when Pillow cannot parse it."""
    try:
        rgb = ImageColor.getrgb(str(color))
    except ValueError:
        rgb = ImageColor.getrgb(_FALLBACK_COLORS[k % len(_FALLBACK_COLORS)])
    return (int(rgb[0]), int(rgb[1]), int(rgb[2]))


def _build_palette(colors: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Palette of a run.

    Returns
    -------
    rgb : ndarray, shape (m, 3), uint8
        Palette entries, ``m <= 255`` (one index stays free).
    body : ndarray, shape (n,), int
        Index of each vehicle's colour.
    trail : ndarray, shape (n, L), int
        Index of each vehicle's fading trail shades, newest first (``L`` may be 0).
    """
    rgbs = [_rgb(c, k) for k, c in enumerate(colors)]
    unique = list(dict.fromkeys(rgbs))
    room = 255 - len(_BASE_COLORS)
    if len(unique) > room:  # snap to a 6x6x6 colour cube
        rgbs = [tuple(int(round(v / 51.0)) * 51 for v in c) for c in rgbs]
        unique = list(dict.fromkeys(rgbs))
    levels = min(_TRAIL_LEVELS, room // len(unique) - 1) if unique else 0
    entries = list(_BASE_COLORS)
    where: dict[tuple[int, int, int], int] = {}
    shades: dict[tuple[int, int, int], list[int]] = {}
    for c in unique:
        where[c] = len(entries)
        entries.append(c)
        shades[c] = []
        for a in _TRAIL_FADE[:levels]:
            shades[c].append(len(entries))
            entries.append(tuple(int(round(v + (255 - v) * a)) for v in c))
    body = np.array([where[c] for c in rgbs], dtype=np.int64)
    trail = np.array([shades[c] for c in rgbs], dtype=np.int64).reshape(len(rgbs), -1)
    return np.array(entries, dtype=np.uint8).reshape(-1, 3), body, trail


def _nice_length(target: float) -> float:
    """Largest 1, 2 or 5 times a power of ten not above ``target`` [m].

    >>> _nice_length(3.7), _nice_length(0.12), _nice_length(10.0)
    (2.0, 0.1, 10.0)
    """
    if not (target > 0 and math.isfinite(target)):
        return 1.0
    exp = math.floor(math.log10(target))
    best = 10.0**exp
    for m in (2.0, 5.0, 10.0):
        if m * 10.0**exp <= target * (1 + 1e-9):
            best = m * 10.0**exp
    return float(f"{best:.12g}")


def _dashes(path: np.ndarray, on: float, off: float) -> np.ndarray:
    """Dash segments along a polyline, shape (k, 2, 2), in the polyline's units."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate(([0.0], np.cumsum(seg)))
    if s[-1] <= 0:
        return np.zeros((0, 2, 2))
    starts = np.arange(0.0, s[-1], on + off)
    ends = np.minimum(starts + on, s[-1])
    a = np.stack(
        (np.interp(starts, s, path[:, 0]), np.interp(starts, s, path[:, 1])), -1
    )
    b = np.stack((np.interp(ends, s, path[:, 0]), np.interp(ends, s, path[:, 1])), -1)
    return np.stack((a, b), axis=1)


def _stamp_discs(
    canvas: np.ndarray,
    centers: np.ndarray,
    radius: np.ndarray,
    *,
    fill: np.ndarray | None,
    edge: np.ndarray | None = None,
    edge_width: float = 1.0,
    heading: np.ndarray | None = None,
    heading_width: np.ndarray | None = None,
    detail: np.ndarray | None = None,
    halo: np.ndarray | None = None,
    halo_width: float = 0.0,
    halo_color: np.ndarray | None = None,
) -> None:
    """Paint discs onto a canvas of palette indices, vectorized over discs.

    A pixel belongs to a disc when its centre lies within ``radius`` of the disc centre.
    Later discs are painted over earlier ones.

    Parameters
    ----------
    canvas : ndarray, shape (H, W), uint8
        Modified in place.
    centers : ndarray, shape (m, 2) [px]
    radius : ndarray, shape (m,) [px]
    fill : ndarray, shape (m,), int, or None
        Fill index of each disc; ``None`` paints only the edge (a ring).
    edge : ndarray, shape (m,), int, optional
        Index of a ring of ``edge_width`` [px] just inside the radius.
    heading : ndarray, shape (m,) [rad], optional
        World heading of a black line from the centre to the rim.
    heading_width : ndarray, shape (m,) [px], optional
        Full width of the heading line.
    detail : ndarray, shape (m,), bool, optional
        Which discs get their edge and heading line (default: all).
    halo : ndarray, shape (m,), bool, optional
        Discs that get an orange ring of ``halo_width`` [px] outside the radius.
    halo_color : ndarray, shape (m,), int, optional
        Palette index of each disc's ring instead of orange.
    """
    h, w = canvas.shape
    ok = np.isfinite(centers).all(axis=1) & np.isfinite(radius)
    if heading is not None:
        ok &= np.isfinite(heading)
    sel = np.flatnonzero(ok)
    if sel.size == 0:
        return
    reach = radius[sel] + (halo_width if halo is not None else 0.0)
    half = int(math.ceil(float(reach.max()))) + 1
    offs = np.arange(-half, half + 1)
    side = offs.size
    per_chunk = max(1, 1_500_000 // (side * side))
    for start in range(0, sel.size, per_chunk):
        i = sel[start : start + per_chunk]
        c = centers[i]
        r = radius[i][:, None, None]
        cols = np.floor(c[:, 0]).astype(np.int64)[:, None] + offs  # (m, side)
        rows = np.floor(c[:, 1]).astype(np.int64)[:, None] + offs
        dx = (cols + 0.5 - c[:, :1])[:, None, :]  # (m, 1, side)
        dy = (rows + 0.5 - c[:, 1:])[:, :, None]  # (m, side, 1)
        d2 = dx * dx + dy * dy
        inside = d2 <= r * r
        val = np.full(d2.shape, -1, dtype=np.int16)
        if halo is not None:
            ring = halo[i][:, None, None] & ~inside & (d2 <= (r + halo_width) ** 2)
            if halo_color is None:
                val[ring] = ORANGE
            else:
                color = np.broadcast_to(halo_color[i][:, None, None], ring.shape)
                val[ring] = color[ring]
        if fill is not None:
            val = np.where(inside, fill[i][:, None, None], val)
        fine = (
            np.ones((len(i), 1, 1), bool)
            if detail is None
            else detail[i][:, None, None]
        )
        if edge is not None:
            rim = inside & fine & (d2 > np.maximum(r - edge_width, 0.0) ** 2)
            val = np.where(rim, edge[i][:, None, None], val)
        if heading is not None and heading_width is not None:
            ux = np.cos(heading[i])[:, None, None]
            uy = -np.sin(heading[i])[:, None, None]  # rows point down
            along = dx * ux + dy * uy
            across = np.abs(dx * uy - dy * ux)
            half_w = heading_width[i][:, None, None] / 2.0
            line = inside & fine & (along >= 0) & (across <= half_w)
            val[line] = BLACK
        rr = np.broadcast_to(rows[:, :, None], d2.shape)
        cc = np.broadcast_to(cols[:, None, :], d2.shape)
        paint = (val >= 0) & (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
        canvas[rr[paint], cc[paint]] = val[paint].astype(np.uint8)


def _flat(points: np.ndarray) -> list[float]:
    """Flatten pixel points (m, 2) for ``ImageDraw`` (whose integer x is a centre)."""
    return (points - 0.5).ravel().tolist()


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
        """The heads-up line: scenario, time, collisions so far, recovery strategy."""
        hits = int(np.searchsorted(self.event_t, now, side="right"))
        draw.rectangle([0, 0, self.size - 1, self.bands.top - 1], fill=WHITE)
        x, y = max(4, int(0.02 * self.size)), 3
        if self.hud_prefix:
            x = self.stamps.paste(img, (x, y), self.hud_prefix, BLACK)
        x = self.stamps.paste(img, (x, y), "t =", BLACK) - self.bands.px // 2
        x = self.stamps.paste_number(img, (x, y), f"{now:.2f}", BLACK)
        x = self.stamps.paste(img, (x, y), " s", BLACK)
        x = self.stamps.paste(img, (x, y), f"collisions: {hits}", BLACK)
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
            for canvas, ms in zip(frames, plan.durations_ms.tolist(), strict=True):
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


# ------------------------------------------------------------------------- GIF stream
class _GifStream:
    """One GIF89a stream assembled from GIFs that imageio encodes a chunk at a time.

    The header (logical screen, global colour table = the run's palette, NETSCAPE loop
    block) is written once; from each chunk only the frames are kept (graphic control
    extensions, image descriptors and LZW data), with any local colour table dropped.
    imageio receives the frames as ``L`` images of palette indices with
    ``optimize=False``, so Pillow writes the indices unchanged (it neither quantizes nor
    remaps them) and only its placeholder colour tables need replacing.

    Every frame after the first codes the pixels that did not change as the transparent
    index ``len(palette)`` (no disposal: the previous frame shows through), which about
    halves the file size; Pillow crops each frame to the box that changed.
    """

    def __init__(
        self, fh: IO[bytes], width: int, height: int, palette: np.ndarray, loop: int = 0
    ) -> None:
        if len(palette) > 255:
            raise ValueError("the palette must leave one index free for transparency")
        self.fh = fh
        self.frames = 0
        self.duration_ms = 0
        self.clear = len(palette)  # transparent index: "unchanged since last frame"
        self.previous: np.ndarray | None = None
        bits = max(1, int(math.ceil(math.log2(len(palette) + 1))))
        table = np.full((1 << bits, 3), 255, dtype=np.uint8)
        table[: len(palette)] = palette
        fh.write(b"GIF89a")
        fh.write(
            struct.pack("<HHBBB", width, height, 0x80 | 0x70 | (bits - 1), WHITE, 0)
        )
        fh.write(table.tobytes())
        fh.write(b"!\xff\x0bNETSCAPE2.0\x03\x01" + struct.pack("<H", loop) + b"\x00")

    def add(self, frames: list[np.ndarray], delays_ms: list[int]) -> None:
        """Encode frames (palette indices, (H, W) uint8) with their delays [ms]."""
        if not frames:
            return
        batch = np.empty((len(frames), *frames[0].shape), dtype=np.uint8)
        for j, frame in enumerate(frames):
            if self.previous is None:
                batch[j] = frame
            else:
                _changes(frame, self.previous, self.clear, out=batch[j])
            self.previous = frame
        duration: int | list[int] = delays_ms if len(frames) > 1 else delays_ms[0]
        data = iio.imwrite(
            "<bytes>",
            batch,
            extension=".gif",
            plugin="pillow",
            is_batch=True,
            duration=duration,
            loop=0,
            optimize=False,
            transparency=self.clear,
        )
        self.fh.write(_frame_blocks(data))
        self.frames += len(frames)
        self.duration_ms += int(sum(delays_ms))

    def close(self) -> None:
        """Write the trailer."""
        self.fh.write(b";")


def _changes(
    frame: np.ndarray, previous: np.ndarray, clear: int, out: np.ndarray
) -> None:
    """Copy into ``out`` the changed pixels of ``frame``, and ``clear`` elsewhere.

    All arrays are (H, W) uint8. The changed box is found comparing up to 8 pixels at a
    time, then refined pixel by pixel.
    """
    width = frame.shape[1]
    word = next(b for b in (8, 4, 2, 1) if width % b == 0)
    as_words = np.dtype(f"u{word}")
    moved = frame.view(as_words) != previous.view(as_words)
    out.fill(clear)
    rows = np.flatnonzero(moved.any(axis=1))
    if rows.size == 0:
        return
    r0, r1 = int(rows[0]), int(rows[-1]) + 1
    cols = np.flatnonzero(moved[r0:r1].any(axis=0))
    c0, c1 = int(cols[0]) * word, (int(cols[-1]) + 1) * word
    box = frame[r0:r1, c0:c1]
    np.copyto(out[r0:r1, c0:c1], box, where=box != previous[r0:r1, c0:c1])


def _skip_subblocks(data: bytes, pos: int) -> int:
    """Position just after the data sub-blocks starting at ``pos``."""
    while True:
        length = data[pos]
        pos += 1 + length
        if length == 0:
            return pos


def _frame_blocks(data: bytes) -> bytes:
    """Extract the frames of a GIF stream, without header, trailer nor colour tables."""
    if data[:6] not in (b"GIF87a", b"GIF89a"):
        raise ValueError("not a GIF stream")
    flags = data[10]
    pos = 13 + (3 << ((flags & 7) + 1) if flags & 0x80 else 0)
    out = bytearray()
    started = False
    while True:
        block = data[pos]
        if block == 0x3B:  # trailer
            return bytes(out)
        if block == 0x21:  # extension: keep graphic control and later ones
            end = _skip_subblocks(data, pos + 2)
            started = started or data[pos + 1] == 0xF9
            if started:
                out += data[pos:end]
            pos = end
        elif block == 0x2C:  # image descriptor
            started = True
            desc = bytearray(data[pos : pos + 10])
            pos += 10
            if desc[9] & 0x80:
                pos += 3 << ((desc[9] & 7) + 1)
                desc[9] &= 0x40  # keep only the interlace flag
            end = _skip_subblocks(data, pos + 1)  # after the LZW minimum code size
            out += desc + data[pos:end]
            pos = end
        else:
            raise ValueError(f"unexpected GIF block 0x{block:02x} at byte {pos}")
