"""What an animation frame shows of the world: the camera and its framing.

:class:`Camera` maps world coordinates to pixels. :meth:`Camera.for_run` frames a whole
run (every pose, the reference path and the obstacles), follows a vehicle, or, for the
automatic camera, follows what happens (:func:`action_track`: the healthy vehicles, a
failed vehicle while others are near it, and the obstacles near them).
:func:`auto_follow` is the automatic choice between the whole run and a moving window
that ``sandbox run --gif``, ``sandbox render`` and ``sandbox gallery`` use. A frame is
square, or as wide as ``aspect`` says (:func:`frame_height`: ``"run"`` gives a frame of
the framed area's own aspect). The viewport leaves room for the text bands of
:mod:`sandbox.render.overlay` (the heads-up line, the scale bar and the legend), whose
layout depends on the run (its vehicles' names and the marks it shows).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from sandbox.render.overlay import (
    LEGEND_NAMES_MAX,
    MAX_BANDS,
    Bands,
    LegendItem,
    frame_bands,
)
from sandbox.render.palette import build_palette
from sandbox.run.constrained import constrained_mask, filter_name
from sandbox.run.record import MODE_AVOID, MODE_EXTERNAL, MODE_FAILED, Run

__all__ = [
    "AUTO_FOLLOW_ASPECT",
    "MAX_FRAME_ASPECT",
    "Camera",
    "action_track",
    "auto_follow",
    "frame_height",
    "resolve_follow",
]

#: Fleets larger than this are drawn without trails, slot marks and zones.
LARGE_FLEET = 100
_MARGIN = 0.04  # fraction of the image size kept free around the content
#: A frame is at most this many times wider than high, or higher than wide.
MAX_FRAME_ASPECT = 4.0
#: The automatic camera's window moves with the centre of what happens averaged over
#: this long [s] (a vehicle entering or leaving the view does not jerk it).
ACTION_SMOOTHING = 1.0
#: The smallest window of a moving camera, in vehicle diameters.
MIN_WINDOW_DIAMETERS = 10.0


def reference_path(run: Run) -> np.ndarray | None:
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


def drawn_obstacles(run: Run) -> list[tuple[str, Any]]:
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
        Width of the image.
    anchor : tuple of float [px]
        Pixel coordinates of ``center``.
    height : int or None [px]
        Height of the image; None: ``size`` (a square image).

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
    height: int | None = None

    @property
    def rows(self) -> int:
        """Height of the image [px]."""
        return self.size if self.height is None else self.height

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
        return Camera(
            (float(c[0]), float(c[1])), self.scale, self.size, self.anchor, self.height
        )

    @classmethod
    def fit(
        cls,
        lo: ArrayLike,
        hi: ArrayLike,
        size: int,
        bands: tuple[int, int] = (16, 18),
        height: int | None = None,
    ) -> Camera:
        """Camera showing the world box ``[lo, hi]`` [m] whole, with a margin.

        The box is centred in the viewport, the part of the image (``size`` px wide,
        ``height`` px high, default ``size``) below the heads-up band and above the
        bottom band (scale bar and legend), ``bands = (top, bottom)`` [px] high.
        """
        lo = np.asarray(lo, dtype=float)
        hi = np.asarray(hi, dtype=float)
        x0, y0, x1, y1 = _viewport(size, bands, height)
        y1 = max(y1, y0 + 1.0)  # [px] bands taller than the frame: a one-pixel view
        extent = np.maximum(hi - lo, 1e-9)
        scale = float(min((x1 - x0) / extent[0], (y1 - y0) / extent[1]))
        mid = (lo + hi) / 2.0
        return cls(
            (float(mid[0]), float(mid[1])),
            scale,
            size,
            ((x0 + x1) / 2, (y0 + y1) / 2),
            height,
        )

    @classmethod
    def for_run(
        cls,
        run: Run,
        size: int = 640,
        follow: str | None = None,
        legend: bool = True,
        aspect: float | str = 1.0,
    ) -> Camera:
        """Build the camera of the first frame of ``run``.

        Parameters
        ----------
        run : Run
        size : int [px]
            Width of the frame.
        follow : {None, "auto", "leader"} or str
            ``None``: the whole run is framed (every pose, the reference path and the
            obstacles) and the camera never moves. ``"leader"`` or a vehicle name: a
            window centred on that vehicle (the fleet centroid when ``"leader"`` is
            asked of a run without leader), 1.3 times as wide as the initial formation
            and at least :data:`MIN_WINDOW_DIAMETERS` diameters and the run's narrow
            side; :func:`render_frames` recentres it on every frame. ``"auto"``: for
            a run that :func:`auto_follow` would follow, a window that moves with
            what happens (:func:`action_track`), else the whole run.
        legend : bool
            Whether the frame has a legend strip (the viewport leaves room for it).
        aspect : float or "run"
            Width over height of the frame (:func:`frame_height`).

        Returns
        -------
        Camera
        """
        height = frame_height(run, size, follow, aspect)
        bands = run_bands(run, size, legend, height)
        edges = (bands.top, bands.bottom)
        framing = camera_track(run, follow)
        if framing is None:  # a square frame keeps the square box it always had
            lo, hi = content_bounds(run, _reach(run), square=height == size)
            return cls.fit(lo, hi, size, edges, height)
        track, window = framing
        c = track[0]
        return cls.fit(c - window / 2, c + window / 2, size, edges, height)


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


def frame_height(
    run: Run, size: int, follow: str | None = None, aspect: float | str = 1.0
) -> int:
    """Height [px] of the frames of ``run``, ``size`` px wide.

    Parameters
    ----------
    run : Run
    size : int [px]
        Width of the frame.
    follow : {None, "auto", "leader"} or str
        The camera (:meth:`Camera.for_run`).
    aspect : float or "run"
        Width over height, from ``1 / MAX_FRAME_ASPECT`` to :data:`MAX_FRAME_ASPECT`;
        ``"run"``: the aspect of the area framed when the whole run is (the text
        bands added, the frame high enough to keep the legend, within the same
        bounds), and a square frame for a camera that moves.

    Returns
    -------
    int
        At least 64 px.
    """
    if aspect == "run":
        if camera_track(run, follow) is not None:
            return int(size)
        lo, hi = content_bounds(run, _reach(run), square=False)
        extent = np.maximum(hi - lo, 1e-9)
        x0, _, x1, _ = _viewport(size)
        bands = run_bands(run, size, True)
        view = (x1 - x0) * extent[1] / extent[0]
        height = view + bands.top + bands.bottom + 2.0 * _MARGIN * size
        height = max(height, (bands.top + bands.bottom) / MAX_BANDS + 1.0)  # a legend
        low, high = size / MAX_FRAME_ASPECT, size * MAX_FRAME_ASPECT
        return max(64, int(round(min(max(height, low), high))))
    if isinstance(aspect, str) or not (
        1.0 / MAX_FRAME_ASPECT <= float(aspect) <= MAX_FRAME_ASPECT
    ):
        raise ValueError(
            f"aspect: expected 'run' or a number from {1 / MAX_FRAME_ASPECT:g} to "
            f"{MAX_FRAME_ASPECT:g} (width over height), got {aspect!r}"
        )
    return max(64, int(round(size / float(aspect))))


def camera_track(run: Run, follow: str | None) -> tuple[np.ndarray, np.ndarray] | None:
    """Where a moving camera is at each sample and the window it shows, or None.

    Parameters
    ----------
    run : Run
    follow : {None, "auto", "leader"} or str
        As for :meth:`Camera.for_run`.

    Returns
    -------
    tuple of ndarray or None
        ``(track, window)``: the window's centre at each sample, shape (T, 2) [m],
        and its size (x, y), shape (2,) [m]; None when the camera frames the whole
        run and never moves.
    """
    if follow is None:
        return None
    reach = _reach(run)
    if follow == "auto":
        if auto_follow(run) is None:
            return None
        return action_track(run)
    track = _follow_track(run, follow)
    pos = run.pose[:, :, :2]
    first = pos[0][np.isfinite(pos[0]).all(axis=1)]
    spread = float(np.max(np.linalg.norm(first - track[0], axis=1), initial=0.0))
    side = max(1.3 * 2.0 * (spread + reach), _least_window(run), 1e-3)  # [m]
    return track, np.full(2, side)


def action_track(run: Run) -> tuple[np.ndarray, np.ndarray] | None:
    """The automatic camera's window: what happens, followed; None: the whole run.

    At each sample the window holds the healthy vehicles, each failed vehicle while it
    is within the formation's width of them (so a vehicle that stops in the
    platoon's path, and the contacts around it, stay in view until the others have
    passed it), and the parts of the obstacles within twice the avoidance radius
    ``R`` of them (at least :data:`MIN_WINDOW_DIAMETERS` vehicle radii). Its centre is
    the centre of these, averaged over :data:`ACTION_SMOOTHING`; its size is fixed
    for the run, the largest the samples need (with the averaging's lag), at least
    that of a window following the leader, :data:`MIN_WINDOW_DIAMETERS` vehicle
    diameters and the run's narrow side. When that window would hold the whole run,
    the whole run is framed instead (None).

    Returns
    -------
    tuple of ndarray or None
        ``(track (T, 2) [m], window (2,) [m])``, as :func:`camera_track`.
    """
    reach = _reach(run)
    pos = np.asarray(run.pose[:, :, :2], dtype=float)
    T = len(pos)
    lead = _follow_track(run, "leader")
    first = pos[0][np.isfinite(pos[0]).all(axis=1)]
    spread = float(np.max(np.linalg.norm(first - lead[0], axis=1), initial=0.0))
    near = max(1.3 * 2.0 * (spread + reach), _least_window(run))  # [m]
    finite = np.isfinite(pos).all(axis=2)
    failed = np.asarray(run.failed, dtype=bool) | (np.asarray(run.mode) == MODE_FAILED)
    healthy = finite & ~failed
    every_failed = ~healthy.any(axis=1)
    healthy[every_failed] = finite[every_failed]
    inf = np.inf
    lo = np.min(np.where(healthy[..., None], pos, inf), axis=1)
    hi = np.max(np.where(healthy[..., None], pos, -inf), axis=1)
    none = ~np.isfinite(lo).all(axis=1)  # no vehicle at all: the leader's point
    lo[none], hi[none] = lead[none], lead[none]
    # Failed vehicles near the healthy ones.
    gap = np.maximum(np.maximum(lo[:, None] - pos, pos - hi[:, None]), 0.0)
    close = finite & failed & (np.hypot(gap[..., 0], gap[..., 1]) <= near)
    lo = np.minimum(lo, np.min(np.where(close[..., None], pos, inf), axis=1))
    hi = np.maximum(hi, np.max(np.where(close[..., None], pos, -inf), axis=1))
    # The parts of the obstacles near them: within twice the avoidance radius R.
    rec = run.info.get("recovery") if isinstance(run.info, dict) else None
    radius = rec.get("R") if isinstance(rec, dict) else None
    margin = max(2.0 * float(radius or 0.0), MIN_WINDOW_DIAMETERS * reach)  # [m]
    for kind, geom in drawn_obstacles(run):
        if kind == "circle":
            (cx, cy), r = geom
            olo, ohi = np.array([cx - r, cy - r]), np.array([cx + r, cy + r])
        else:
            olo, ohi = geom.min(axis=0), geom.max(axis=0)
        clo, chi = np.maximum(olo, lo - margin), np.minimum(ohi, hi + margin)
        seen = (clo <= chi).all(axis=1)
        lo[seen] = np.minimum(lo[seen], clo[seen])
        hi[seen] = np.maximum(hi[seen], chi[seen])
    centre = (lo + hi) / 2.0
    dt = float(np.median(np.diff(run.t))) if T > 1 else 1.0
    track = _moving_average(centre, max(1, int(round(ACTION_SMOOTHING / dt))))
    need = 2.0 * np.maximum(hi - track, track - lo).max(axis=0) + 2.0 * reach
    window = np.maximum(need, max(near, _least_window(run)))
    whole_lo, whole_hi = content_bounds(run, reach, square=False)
    if (window >= whole_hi - whole_lo).all():
        return None
    return track, window


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average of ``x`` (T, 2) over ``width`` samples, edges held."""
    if width <= 1 or len(x) < 2:
        return x.copy()
    half = width // 2
    padded = np.concatenate((np.repeat(x[:1], half, 0), x, np.repeat(x[-1:], half, 0)))
    sums = np.cumsum(np.concatenate((np.zeros((1, 2)), padded)), axis=0)
    span = 2 * half + 1
    return (sums[span:] - sums[:-span]) / span


def _reach(run: Run) -> float:
    """The largest vehicle radius [m]."""
    return float(np.max(run.diameter, initial=0.0)) / 2.0


def _least_window(run: Run) -> float:
    """The smallest side of a moving window [m]: a few diameters, the narrow side.

    The narrow side of the area the run covers (every pose, the reference path and
    the obstacles): a platoon on a straight road is followed in a window as wide as
    the road's scene, and a lone vehicle is not framed at its own size.
    """
    reach = _reach(run)
    lo, hi = content_bounds(run, reach, square=False)
    return max(MIN_WINDOW_DIAMETERS * 2.0 * reach, float(np.min(hi - lo)))


def _viewport(
    size: int, bands: tuple[int, int] = (16, 18), height: int | None = None
) -> tuple[float, float, float, float]:
    """Pixel box ``(x0, y0, x1, y1)`` the world content is fitted into."""
    rows = size if height is None else height
    pad = _MARGIN * min(size, rows)
    return pad, bands[0] + pad, size - pad, rows - bands[1] - pad


def _legend_items(run: Run, body: np.ndarray, large: bool) -> list[LegendItem]:
    """The legend strip of ``run``: its vehicles, then the marks its frames show.

    With ``platoons:``, one entry per platoon, in the colour of its first vehicle.
    """
    from sandbox.render.platoons import platoon_groups

    groups = platoon_groups(run)
    if groups is not None:
        items = [
            LegendItem("vehicle", name, int(body[rows[0]])) for name, rows in groups
        ]
    elif run.n_vehicles <= LEGEND_NAMES_MAX:
        items = [
            LegendItem("vehicle", name, int(body[i]))
            for i, name in enumerate(run.names)
        ]
    else:
        items = [LegendItem("vehicle", f"{run.n_vehicles} vehicles", int(body[0]))]
    mode = np.asarray(run.mode)
    if reference_path(run) is not None:
        items.append(LegendItem("reference", "reference"))
    if not large:
        items.append(LegendItem("slot", "slot"))
    if (mode == MODE_AVOID).any():
        items.append(LegendItem("avoid", "avoiding"))
    if (mode == MODE_EXTERNAL).any():
        items.append(LegendItem("external", "external command"))
    constrained = constrained_mask(run)
    if constrained is not None and constrained.any():
        items.append(LegendItem("filter", f"{filter_name(run)} acting"))
    if np.asarray(run.failed, dtype=bool).any() or (mode == MODE_FAILED).any():
        items.append(LegendItem("failed", "failed"))
    if len(run.events):
        items.append(LegendItem("collision", "collision"))
    return items


def run_bands(run: Run, size: int, legend: bool, height: int | None = None) -> Bands:
    """Layout of the text bands of ``run``'s frames (no legend rows without legend).

    The frames are ``size`` px wide and ``height`` px high (default ``size``).
    """
    if not legend:
        return frame_bands(int(size), [], height)
    _, body, _ = build_palette(run.colors)
    return frame_bands(
        int(size), _legend_items(run, body, run.n_vehicles > LARGE_FLEET), height
    )


def content_bounds(
    run: Run, reach: float, square: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """World bounding box [m] of poses, reference path and obstacles.

    ``square``: the box made square about its centre (its longer side); otherwise
    each side is at least the larger of 8 ``reach`` and 0.5 m.
    """
    boxes = [_finite_box(run.pose[:, :, :2]), _finite_box(run.reference)]
    path = reference_path(run)
    if path is not None:
        boxes.append(_finite_box(path))
    for kind, geom in drawn_obstacles(run):
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
    least = max(8.0 * reach, 0.5)  # [m] never a degenerate box
    side = max(float(np.max(hi - lo)), least) if square else least
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
