"""Building blocks of the report figures of :mod:`sandbox.render.figures`.

Atomic, deterministic saving as PNG, PDF or SVG; the median and percentile bands that
stand for a large fleet's time series; the size of an equal-aspect axes box that fits
its content; and time labels placed so that no two overlap. Like
:mod:`sandbox.render.figures`, this module never imports ``pyplot``.
"""

from __future__ import annotations

import os
import uuid
import warnings
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Annotation
from matplotlib.transforms import Bbox

__all__ = [
    "BAND_PERCENTILES",
    "TRAJECTORY_HEIGHT",
    "TRAJECTORY_WIDTH",
    "draw_bands",
    "fit_box",
    "place_time_labels",
    "save_figure",
]

#: Percentiles of the bands drawn for large fleets: outer band, inner band, median.
BAND_PERCENTILES = (5.0, 25.0, 50.0, 75.0, 95.0)
#: Width of the axes box of ``trajectories`` [in]; its height follows the content.
TRAJECTORY_WIDTH = 8.0
#: Bounds of the height of that axes box [in].
TRAJECTORY_HEIGHT = (2.4, 8.0)


def save_figure(fig: Figure, path: Path, dpi: int, fmt: str = "png") -> None:
    """Write ``fig`` in format ``fmt``, atomically (temporary file, then rename).

    Every format is written without a date or software version, so that the same
    figure gives the same bytes.
    """
    FigureCanvasAgg(fig)
    metadata: dict[str, None] = {
        "png": {"Software": None},
        "pdf": {"CreationDate": None, "Creator": None, "Producer": None},
        "svg": {"Date": None, "Creator": None},
    }[fmt]
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with (
            open(tmp, "xb") as fh,
            matplotlib.rc_context({"svg.hashsalt": "sandbox", "svg.fonttype": "path"}),
        ):
            fig.savefig(fh, format=fmt, dpi=dpi, metadata=metadata)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def draw_bands(ax: Axes, x: np.ndarray, ys: np.ndarray, color: str, lw: float) -> None:
    """Draw the median of ``ys`` over vehicles, percentile bands and the maximum.

    Parameters
    ----------
    ax : Axes
    x : ndarray, shape (T,)
    ys : ndarray, shape (T, n)
        NaN where a vehicle is not counted at a sample.
    color : str
    lw : float [pt]
        Width of the median line.
    """
    with warnings.catch_warnings():  # samples where no vehicle counts: NaN, silently
        warnings.simplefilter("ignore", RuntimeWarning)
        lo, q1, mid, q3, hi = np.nanpercentile(ys, BAND_PERCENTILES, axis=1)
        top = np.nanmax(ys, axis=1)
    p = BAND_PERCENTILES
    ax.fill_between(
        x, lo, hi, color=color, alpha=0.18, lw=0, label=f"{p[0]:g}-{p[4]:g} %"
    )
    ax.fill_between(
        x, q1, q3, color=color, alpha=0.4, lw=0, label=f"{p[1]:g}-{p[3]:g} %"
    )
    ax.plot(x, mid, color=color, lw=lw, label="median")
    ax.plot(x, top, color=color, lw=0.8, ls=":", label="max")


def fit_box(
    lo: np.ndarray, hi: np.ndarray
) -> tuple[float, float, np.ndarray, np.ndarray]:
    """Size [in] and limits [m] of an equal-aspect axes box showing ``[lo, hi]``.

    The box is :data:`TRAJECTORY_WIDTH` wide, or less for a tall content; its height
    follows the content's aspect ratio within :data:`TRAJECTORY_HEIGHT`. Where a bound
    applies, the limits grow (about the centre) so that one metre is as long on both
    axes.

    Returns
    -------
    width, height : float [in]
    lo, hi : ndarray, shape (2,) [m]
        Limits with the box's aspect ratio.
    """
    ext = np.maximum(hi - lo, 1e-9)
    ratio = float(ext[1] / ext[0])
    low, high = TRAJECTORY_HEIGHT
    width = TRAJECTORY_WIDTH
    height = width * ratio
    if height > high:
        height, width = high, max(high / ratio, 3.0)
    height = max(height, low)
    half = np.maximum(ext, [ext[1] * width / height, ext[0] * height / width]) / 2.0
    mid = (lo + hi) / 2.0
    return width, height, mid - half, mid + half


def place_time_labels(
    fig: Figure, ax: Axes, snaps: list[tuple[float, np.ndarray]]
) -> list[Annotation]:
    """Label each snapshot with its time, never letting two labels overlap.

    Each snapshot is labelled above the highest of its vehicles whose label would not
    overlap one already placed; when there is none (every vehicle of the snapshot sits
    under a label, as on a stopped vehicle), its time joins the label it overlaps
    (``"9, 12 s"``). Overlaps are measured on the drawn figure.

    Parameters
    ----------
    fig : Figure
        Laid out (drawn) before this is called, with its final axes limits.
    ax : Axes
    snaps : list of (t [s], ndarray (m, 2) [m])
        Each snapshot's time and its candidate anchors (top of each vehicle's circle),
        highest first.

    Returns
    -------
    list of Annotation
        The labels, in time order of their first time.
    """
    renderer = fig.canvas.get_renderer()
    style = {
        "xytext": (0, 3),
        "textcoords": "offset points",
        "ha": "center",
        "va": "bottom",
        "fontsize": 7,
        "color": "0.2",
        "zorder": 6,
    }
    placed: list[tuple[list[float], Annotation]] = []

    def extent(label: Annotation) -> Bbox:
        return label.get_window_extent(renderer).expanded(1.08, 1.15)

    def overlapping(box: Bbox) -> int | None:
        for j, (_, other) in enumerate(placed):
            if box.overlaps(extent(other)):
                return j
        return None

    def text(times: list[float]) -> str:
        return ", ".join(f"{v:.3g}" for v in times) + " s"

    for t, anchors in snaps:
        first_clash = None
        for anchor in anchors[:8]:
            label = ax.annotate(text([t]), tuple(anchor), **style)
            clash = overlapping(extent(label))
            if clash is None:
                placed.append(([t], label))
                break
            label.remove()
            first_clash = clash if first_clash is None else first_clash
        else:
            if first_clash is not None:
                times, label = placed[first_clash]
                times.append(t)
                label.set_text(text(times))
    # A merged label grew: merge again until no two labels overlap.
    merged = True
    while merged:
        merged = False
        for j in range(len(placed)):
            for k in range(j + 1, len(placed)):
                if extent(placed[j][1]).overlaps(extent(placed[k][1])):
                    placed[j][0].extend(placed[k][0])
                    placed[j][1].set_text(text(sorted(placed[j][0])))
                    placed[k][1].remove()
                    del placed[k]
                    merged = True
                    break
            if merged:
                break
    return [label for _, label in placed]
