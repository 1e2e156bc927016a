"""Figures of a sweep (matplotlib, Agg): rates against a varied path, heatmaps over two.

- ``rates_<x>.png``: left, the rate of runs with a healthy collision, with its Wilson
  95 % interval; middle, the rate of runs not settled by the end, likewise; right, the
  worst healthy settling time (median, and the quartiles as a band) of the settled
  runs; all against the varied path ``x``, one line per value of the other varied
  paths. The lines are set apart a little along ``x`` and drawn each with its own
  marker and dashes, so that lines that coincide stay visible; categories (an ``x``
  that is not numeric) are points with error bars, not joined by lines; a panel
  without a settled run says so;
- ``heatmap_<x>_<y>.png`` (two or more varied paths): the collision rate and the
  unsettled rate over ``x`` and ``y``, one pair of panels per value of the other paths.

The zipped paths vary together, so they are one axis of the figures, named by their
paths joined with `` & `` (its values likewise), unless ``--by`` names them: a path
named by ``--by`` is an axis of its own.
"""

from __future__ import annotations

import itertools
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from sandbox.study.spec import SweepError
from sandbox.study.store import read_results, replace_atomic, varied_axes
from sandbox.study.summary import group_rows

#: At most this many heatmap pairs (values of the other paths) are drawn.
MAX_PANELS = 6

#: Joins the paths (and the values) of the zipped paths into one axis.
AXIS_JOIN = " & "

#: The lines of a rates figure are set apart along x by this fraction of the
#: smallest step between two x values, in all (the first and the last line).
DODGE = 0.2
#: Markers and dashes of the lines, in turn.
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "*")
DASHES = ("-", "--", "-.", ":")


def save_figure(fig: Any, path: Path) -> None:
    """Write ``fig`` as a PNG at ``path``, whole or not at all.

    Drawn into a hidden temporary file beside ``path`` and renamed into place, so a
    killed ``sweep plot`` never leaves a truncated or empty PNG; an ``OSError`` is
    reported with ``path`` (:func:`~sandbox.study.store.replace_atomic`).
    """
    replace_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))


def _numeric(values: list[str]) -> list[float] | None:
    try:
        return [float(v) for v in values]
    except ValueError:
        return None


def _number(value: Any) -> float:
    """A summary's number, NaN for a missing one (no settled run)."""
    return math.nan if value is None else float(value)


def dodges(xpos: list[float], lines: int) -> np.ndarray:
    """How far each of ``lines`` lines is moved along x, shape (lines,).

    The lines are spread over :data:`DODGE` of the smallest step between two x
    values, centred on the true value (a single line is not moved).

    >>> dodges([0.0, 1.0, 2.0], 3).tolist()
    [-0.1, 0.0, 0.1]
    >>> dodges([0.0, 1.0], 1).tolist()
    [0.0]
    """
    if lines <= 1:
        return np.zeros(max(lines, 0))
    steps = np.diff(np.sort(np.asarray(xpos, dtype=float)))
    steps = steps[steps > 0]
    step = float(steps.min()) if len(steps) else 1.0
    return (np.arange(lines) - (lines - 1) / 2.0) * (DODGE * step / (lines - 1))


def _slug(path: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", path).strip("_")


def _tick(value: str) -> str:
    """A tick label: the values of zipped paths one above the other."""
    return value.replace(AXIS_JOIN, "\n")


def _order(values: list[str]) -> list[str]:
    nums = _numeric(values)
    if nums is None:
        return values
    return [v for _, v in sorted(zip(nums, values, strict=True))]


def plot_sweep(root: Path, out: Path, by: list[str] | None = None) -> list[Path]:
    """Draw the figures of the sweep in ``root`` into ``out``; return their paths.

    Parameters
    ----------
    root : Path
        The sweep's results directory.
    out : Path
        Where the PNG files go (created).
    by : list of str, optional
        The varied paths to draw against: the first is the x axis, the second the
        heatmap's y axis (default: the sweep's varied paths, in order).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    try:
        _, rows = read_results(root)
        axes = varied_axes(root)
    except OSError as exc:
        raise SweepError(f"{root}: not a sweep directory ({exc})") from None
    if not axes:
        raise SweepError(f"{root}: the sweep varies no path: nothing to plot against")
    every = [p for a in axes for p in a]
    for p in by or []:
        if p not in every:
            raise SweepError(f"--by {p}: not a varied path of {root}")
    # The paths named by --by are axes of their own; of the others, the zipped ones
    # vary together and make one axis.
    chosen = list(dict.fromkeys(by or []))
    named = {p: (p,) for p in chosen}
    for a in axes:
        left = tuple(p for p in a if p not in named)
        if left:
            named[AXIS_JOIN.join(left)] = left
    paths = list(named)
    by = chosen or paths[:1]
    rows = [
        {**r, **{n: AXIS_JOIN.join(r[p] for p in a) for n, a in named.items()}}
        for r in rows
    ]
    rest = [p for p in paths if p not in by]
    by = by + rest
    x, others = by[0], by[1:]
    out.mkdir(parents=True, exist_ok=True)
    written = []

    summary = dict(group_rows(rows, [x, *others]))
    xs = _order(list(dict.fromkeys(r[x] for r in rows)))
    xnum = _numeric(xs)
    xpos = xnum if xnum is not None else list(range(len(xs)))
    combos = list(dict.fromkeys(tuple(r[p] for p in others) for r in rows))
    shifts = dodges(xpos, len(combos))

    fig, (ax1, ax3, ax2) = plt.subplots(
        1, 3, figsize=(15, 4.4), constrained_layout=True
    )
    settled_any = False
    for k, combo in enumerate(combos):
        label = ", ".join(f"{p}={v}" for p, v in zip(others, combo, strict=True))
        style = {
            "color": f"C{k % 10}",
            "marker": MARKERS[k % len(MARKERS)],
            "linestyle": DASHES[k % len(DASHES)] if xnum is not None else "none",
            "label": label or None,
        }
        pts = [(xp, summary.get((xv, *combo))) for xp, xv in zip(xpos, xs, strict=True)]
        pts = [(xp, s) for xp, s in pts if s is not None and s["runs"] > 0]
        if not pts:
            continue
        px = np.array([p for p, _ in pts], dtype=float) + shifts[k]
        for ax, key in ((ax1, "collision"), (ax3, "unsettled")):
            rate = np.array([s[f"{key}_rate"] for _, s in pts])
            lo = np.array([s[f"{key}_low"] for _, s in pts])
            hi = np.array([s[f"{key}_high"] for _, s in pts])
            ax.errorbar(
                px,
                100 * rate,
                yerr=100 * np.clip(np.vstack((rate - lo, hi - rate)), 0, None),
                capsize=3,
                **style,
            )
        med, q1, q3 = (
            np.array([_number(s[f"settling_{q}"]) for _, s in pts])
            for q in ("median", "q1", "q3")
        )
        if not np.isfinite(med).any():
            continue
        settled_any = True
        if xnum is None:  # categories: the quartiles as error bars, no band
            spread = np.clip(np.vstack((med - q1, q3 - med)), 0, None)
            ax2.errorbar(px, med, yerr=spread, capsize=3, **style)
        else:
            ax2.plot(px, med, **style)
            ax2.fill_between(px, q1, q3, color=style["color"], alpha=0.2, linewidth=0)
    if not settled_any:
        ax2.text(
            0.5,
            0.5,
            "no run settled",
            ha="center",
            va="center",
            transform=ax2.transAxes,
            fontsize=11,
            color="0.3",
        )
        ax2.set_yticks([])
        ax2.set_xlim(ax1.get_xlim())  # the x axis of the other panels, not 0..1
    n_runs = [s["runs"] for s in summary.values()]
    lo_n, hi_n = min(n_runs), max(n_runs)
    each = f"{lo_n}" if lo_n == hi_n else f"{lo_n}-{hi_n}"
    ax1.set_title(
        f"runs with a healthy collision (Wilson 95 %; {each} runs per point)",
        fontsize=9,
    )
    ax1.set_ylabel("collision rate [%]")
    ax3.set_title(
        f"runs not settled by the end (Wilson 95 %; {each} runs per point)",
        fontsize=9,
    )
    ax3.set_ylabel("unsettled rate [%]")
    for ax in (ax1, ax3):
        ax.set_ylim(-2, 102)
    ax2.set_title(
        "worst healthy settling time of the settled runs (median, quartiles)",
        fontsize=9,
    )
    ax2.set_ylabel("settling time [s]")
    for ax in (ax1, ax3, ax2):
        ax.set_xlabel(x)
        ax.grid(alpha=0.3)
        if xnum is None:
            ax.set_xticks(xpos, [_tick(v) for v in xs], fontsize=7)
        if combos != [()] and ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    path = out / f"rates_{_slug(x)}.png"
    save_figure(fig, path)
    plt.close(fig)
    written.append(path)

    if others:
        y, more = others[0], others[1:]
        ys = _order(list(dict.fromkeys(r[y] for r in rows)))
        panels = list(dict.fromkeys(tuple(r[p] for p in more) for r in rows))[
            :MAX_PANELS
        ]
        fig, axes = plt.subplots(
            len(panels),
            2,
            figsize=(10, 0.6 + 3.4 * len(panels)),
            squeeze=False,
            constrained_layout=True,
        )
        for row_axes, combo in zip(axes, panels, strict=True):
            for ax, key, title in zip(
                row_axes,
                ("collision_rate", "unsettled_rate"),
                ("runs with a healthy collision [%]", "runs not settled [%]"),
                strict=True,
            ):
                grid = np.full((len(ys), len(xs)), math.nan)
                for (i, yv), (j, xv) in itertools.product(enumerate(ys), enumerate(xs)):
                    s = summary.get((xv, yv, *combo))
                    if s is not None and s["runs"] > 0:
                        grid[i, j] = 100 * s[key]
                im = ax.imshow(
                    grid,
                    origin="lower",
                    cmap="viridis",
                    vmin=0,
                    vmax=100,
                    aspect="auto",
                )
                for (i, j), v in np.ndenumerate(grid):
                    if not math.isnan(v):
                        ax.text(
                            j,
                            i,
                            f"{v:.1f}",
                            ha="center",
                            va="center",
                            color="white" if v < 60 else "black",
                            fontsize=8,
                        )
                ax.set_xticks(range(len(xs)), [_tick(v) for v in xs], fontsize=7)
                ax.set_yticks(range(len(ys)), [_tick(v) for v in ys], fontsize=7)
                ax.set_xlabel(x)
                ax.set_ylabel(y)
                extra = ", ".join(f"{p}={v}" for p, v in zip(more, combo, strict=True))
                ax.set_title(title + (f"\n{extra}" if extra else ""), fontsize=9)
                fig.colorbar(im, ax=ax, shrink=0.8)
        path = out / f"heatmap_{_slug(x)}_{_slug(y)}.png"
        save_figure(fig, path)
        plt.close(fig)
        written.append(path)
    return written
