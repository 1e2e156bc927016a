"""The palette of an animation and the drawing primitives that use it.

Frames of :mod:`sandbox.render.animation` are canvases of palette indices: the fixed
entries below (white, black, greys, orange, red, blue), then each vehicle's colour and a
few paler shades of it for its trail. This module builds that palette, and holds the
drawing helpers that need nothing else: dashes along a path, vectorized disc stamps for
large fleets, the scale bar's round lengths.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from PIL import ImageColor

__all__ = [
    "BLACK",
    "BLUE",
    "OBSTACLE",
    "OBSTACLE_EDGE",
    "ORANGE",
    "PATH",
    "RED",
    "WHITE",
    "ZONE",
]

_TRAIL_LEVELS = 4  # fading steps of a trail
_TRAIL_FADE = (0.2, 0.45, 0.65, 0.82)  # blend toward white of each step, newest first

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


def color_rgb(color: str, k: int) -> tuple[int, int, int]:
    """RGB of a colour name, or a default colour when Pillow cannot parse it."""
    try:
        rgb = ImageColor.getrgb(str(color))
    except ValueError:
        rgb = ImageColor.getrgb(_FALLBACK_COLORS[k % len(_FALLBACK_COLORS)])
    return (int(rgb[0]), int(rgb[1]), int(rgb[2]))


def build_palette(colors: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    rgbs = [color_rgb(c, k) for k, c in enumerate(colors)]
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


def nice_length(target: float) -> float:
    """Largest 1, 2 or 5 times a power of ten not above ``target`` [m].

    >>> nice_length(3.7), nice_length(0.12), nice_length(10.0)
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


def dash_segments(path: np.ndarray, on: float, off: float) -> np.ndarray:
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


def stamp_discs(
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


def flat_points(points: np.ndarray) -> list[float]:
    """Flatten pixel points (m, 2) for ``ImageDraw`` (whose integer x is a centre)."""
    return (points - 0.5).ravel().tolist()
