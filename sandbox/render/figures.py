"""Report-style figures of a recorded run, as PNG, PDF or SVG files.

Figures are built on :class:`matplotlib.figure.Figure` with an explicit Agg canvas, so
this module never imports ``pyplot`` and works without a display (SVG files are written
inside a :func:`matplotlib.rc_context` that fixes their element ids, so that they are
deterministic). It reads a :class:`sandbox.run.record.Run` only.

:func:`plot_run` writes four figures; each also has its own builder returning the
``Figure`` (for notebooks or tests):

- ``trajectories`` (:func:`trajectories_figure`): paths in the world frame, with
  snapshots of the vehicles (circles of their real diameter, heading line) at regular
  intervals, each snapshot labelled with its time (labels that would overlap are merged,
  ``"9, 12, 15 s"`` on a vehicle that stopped), the reference path dashed, obstacles,
  failures and collisions. The figure's shape follows the content: a run along a line
  gives a wide, low figure rather than a mostly empty square;
- ``leader_frame`` (:func:`leader_frame_figure`): every follower's position in the
  leader's frame over time (report Figs. 5 and 8). A run without a leader is drawn
  relative to the centroid of the fleet, with world-aligned axes, and says so in its
  title;
- ``formation_error`` (:func:`formation_error_figure`): distance of each vehicle to its
  slot against time, failures as vertical dashed lines (dotted where they end),
  collisions as red stars, detections (``detection: residual``) as triangles on the time
  axis, reassignments and leader changes (``reconfigure``, ``on_leader_failure``) as
  marks on its top edge (:mod:`sandbox.render.figure_marks`). A failed vehicle's error
  while it is failed (it grows without bound for a stopped vehicle) is drawn apart, on a
  lower panel with its own scale, so that it does not flatten the healthy curves;
- ``commands`` (:func:`commands_figure`): ``v1`` and ``v2`` against time.

Fleets of more than :data:`LEGEND_MAX` vehicles have no per-vehicle legend; their time
series (formation error, commands) are drawn as the median over the vehicles with 25-75
and 5-95 percentile bands and the maximum, instead of one line per vehicle.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.colors import is_color_like
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from sandbox.render.cars import car_lines, car_wheelbases
from sandbox.render.figure_marks import (
    TITLE_PAD,
    detection_marks,
    reconfiguration_marks,
)
from sandbox.render.figure_parts import (
    draw_bands,
    fit_box,
    place_time_labels,
    save_figure,
)
from sandbox.render.platoons import (
    platoon_error_figure,
    platoon_groups,
    platoon_paths,
    platoon_tracks,
)
from sandbox.run.record import Run

__all__ = [
    "DPI_RANGE",
    "FIGURES",
    "FORMATS",
    "LEGEND_MAX",
    "commands_figure",
    "formation_error_figure",
    "leader_frame_figure",
    "plot_run",
    "trajectories_figure",
]

#: Largest fleet that gets one legend entry per vehicle.
LEGEND_MAX = 12
#: Number of vehicle snapshots in ``trajectories.png`` (first and last sample included).
SNAPSHOTS = 6
#: Lines are drawn through at most about this many samples (evenly spaced, last kept).
MAX_LINE_SAMPLES = 4000
#: File formats :func:`plot_run` writes.
FORMATS = ("png", "pdf", "svg")
#: Resolutions :func:`plot_run` accepts, inclusive [dots per inch].
DPI_RANGE = (10, 1200)

_OBSTACLE_FACE = "0.72"
_OBSTACLE_EDGE = "0.4"
_REFERENCE = "0.45"


# ------------------------------------------------------------------------- helpers
def vehicle_colors(run: Run) -> list[str]:
    """Return each vehicle's colour, or a default where matplotlib cannot read it."""
    return [
        c if isinstance(c, str) and is_color_like(c) else f"C{k % 10}"
        for k, c in enumerate(run.colors)
    ]


def _info(run: Run, key: str) -> object:
    """Return ``run.info[key]``, or ``None``."""
    return run.info.get(key) if isinstance(run.info, dict) else None


def _title(run: Run, what: str) -> str:
    """Return a figure title: what it shows, then the scenario and law when known."""
    parts = [str(x) for x in (_info(run, "scenario_name"), _info(run, "law")) if x]
    return what + (f" ({', '.join(parts)})" if parts else "")


def _thin(run: Run) -> np.ndarray:
    """Indices of the samples lines are drawn through (all of them for short runs)."""
    count = len(run.t)
    step = max(1, -(-count // MAX_LINE_SAMPLES))
    idx = np.arange(0, count, step)
    return idx if idx[-1] == count - 1 else np.append(idx, count - 1)


def _in_frame(xy: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Express points (T, n, 2) [m] in the frames of poses ``origin`` (T, 3)."""
    c = np.cos(origin[:, 2])[:, None]
    s = np.sin(origin[:, 2])[:, None]
    d = xy - origin[:, None, :2]
    return np.stack((c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]), -1)


def draw_obstacles(ax: Axes, run: Run) -> None:
    """Add the obstacles of ``info["obstacles"]`` as grey patches."""
    for ob in _info(run, "obstacles") or []:
        kind = ob.get("type")
        style = {"facecolor": _OBSTACLE_FACE, "edgecolor": _OBSTACLE_EDGE, "zorder": 1}
        if kind == "circle":
            ax.add_patch(Circle(tuple(ob["center"]), float(ob["radius"]), **style))
        elif kind == "polygon":
            pts = np.asarray(ob["points"], dtype=float).reshape(-1, 2)
            ax.add_patch(Polygon(pts, closed=True, **style))


def reference_path(run: Run) -> np.ndarray | None:
    """Return the reference path (m, 2) [m]: ``info["reference_path"]`` or samples."""
    raw = _info(run, "reference_path")
    pts = np.asarray(raw, dtype=float) if raw is not None else None
    if pts is None or pts.ndim != 2 or pts.shape[-1] != 2:
        pts = np.asarray(run.reference, dtype=float).reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(axis=1)]
    return pts if len(pts) >= 2 else None


def _lines(
    ax: Axes, x: np.ndarray, ys: np.ndarray, run: Run, colors: list[str], **kw: object
) -> None:
    """Plot ``ys[:, i]`` against ``x`` for every vehicle ``i`` in its colour.

    Parameters
    ----------
    ax : Axes
    x : ndarray, shape (T,)
    ys : ndarray, shape (T, n)
    run : Run
    colors : list of str
    **kw
        Passed to ``Axes.plot`` or ``LineCollection``.
    """
    if run.n_vehicles <= LEGEND_MAX:
        for i, name in enumerate(run.names):
            ax.plot(x, ys[:, i], color=colors[i], label=name, **kw)
    else:
        segs = np.stack((np.broadcast_to(x[:, None], ys.shape), ys), -1)  # (T, n, 2)
        ax.add_collection(LineCollection(segs.transpose(1, 0, 2), colors=colors, **kw))
        ax.autoscale_view()


def _legend(ax: Axes, run: Run, **kw: object) -> None:
    """Add a legend, or a note when the fleet is too large for one."""
    if run.n_vehicles <= LEGEND_MAX:
        ax.legend(fontsize="small", **kw)
    else:
        ax.text(
            0.01,
            0.99,
            f"{run.n_vehicles} vehicles (legend omitted)",
            transform=ax.transAxes,
            va="top",
            fontsize="small",
        )


def _failure_spans(run: Run) -> list[tuple[int, float, float | None, str]]:
    """List failures as ``(vehicle, start [s], end [s] or None, kind)``.

    Taken from ``info["failures"]`` when given, else from the onsets of ``run.failed``.
    """
    index = {name: k for k, name in enumerate(run.names)}
    spans: list[tuple[int, float, float | None, str]] = []
    listed = _info(run, "failures")
    if isinstance(listed, list) and listed:
        for f in listed:
            i = index.get(f.get("vehicle"))
            if i is None or f.get("at") is None:
                continue
            until = f.get("until")
            spans.append(
                (
                    i,
                    float(f["at"]),
                    None if until is None else float(until),
                    str(f.get("kind", "")),
                )
            )
        return spans
    failed = np.asarray(run.failed, dtype=bool)
    t = np.asarray(run.t, dtype=float)
    for i in range(run.n_vehicles):
        edges = np.diff(failed[:, i].astype(np.int8), prepend=0, append=0)
        for a, b in zip(
            np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True
        ):
            spans.append(
                (i, float(t[a]), float(t[b]) if b < len(t) else None, "failure")
            )
    return spans


def _event_samples(run: Run) -> list[tuple[float, int, list[int]]]:
    """List collisions as ``(t [s], nearest sample, vehicle indices involved)``."""
    index = {name: k for k, name in enumerate(run.names)}
    t = np.asarray(run.t, dtype=float)
    out = []
    for ev in run.events:
        k = int(np.clip(np.searchsorted(t, ev.t), 0, len(t) - 1))
        out.append((float(ev.t), k, [index[x] for x in (ev.a, ev.b) if x in index]))
    return out


def _series(
    ax: Axes,
    x: np.ndarray,
    ys: np.ndarray,
    run: Run,
    colors: list[str],
    who: Sequence[int] | None = None,
    lw: float = 1.2,
) -> None:
    """One line per vehicle of ``who`` (default all), or bands for a large fleet.

    Parameters
    ----------
    ax : Axes
    x : ndarray, shape (T,)
    ys : ndarray, shape (T, n)
        NaN breaks a vehicle's line.
    run : Run
    colors : list of str
    who : sequence of int, optional
        Vehicles drawn; the others are ignored.
    lw : float [pt]
    """
    who = list(range(run.n_vehicles)) if who is None else list(who)
    if len(who) <= LEGEND_MAX and run.n_vehicles <= LEGEND_MAX:
        for i in who:
            ax.plot(x, ys[:, i], color=colors[i], label=run.names[i], lw=lw)
    elif who:
        draw_bands(ax, x, ys[:, who], "C0", lw)


# ------------------------------------------------------------------------- figures
def content_bounds(
    run: Run, pos: np.ndarray, path: np.ndarray | None, reach: float
) -> tuple[np.ndarray, np.ndarray]:
    """World box ``(lo, hi)`` [m] of the paths, reference and obstacles, padded.

    Parameters
    ----------
    run : Run
    pos : ndarray, shape (T, n, 2) [m]
        Positions drawn.
    path : ndarray, shape (m, 2) [m], or None
        Reference path.
    reach : float [m]
        Largest vehicle radius; the box is padded by it and by 4 % of its size.
    """
    pts = [pos.reshape(-1, 2)]
    if path is not None:
        pts.append(path)
    for ob in _info(run, "obstacles") or []:
        if ob.get("type") == "circle":
            c, r = np.asarray(ob["center"], dtype=float), float(ob["radius"])
            pts.append(np.array([c - r, c + r]))
        elif ob.get("type") == "polygon":
            pts.append(np.asarray(ob["points"], dtype=float).reshape(-1, 2))
    allp = np.concatenate(pts)
    allp = allp[np.isfinite(allp).all(axis=1)]
    if len(allp) == 0:
        return np.full(2, -1.0), np.full(2, 1.0)
    lo, hi = allp.min(axis=0) - reach, allp.max(axis=0) + reach
    pad = 0.04 * float(np.max(hi - lo)) + 1e-3
    return lo - pad, hi + pad


def trajectories_figure(run: Run) -> Figure:
    """Draw the paths and snapshots of every vehicle in the world frame.

    The axes box takes the aspect ratio of the content (within the bounds of
    :data:`~sandbox.render.figure_parts.TRAJECTORY_HEIGHT`), so the content fills it;
    the legend stands outside the axes, below a wide figure and right of a tall one.

    Parameters
    ----------
    run : Run

    Returns
    -------
    Figure
        One axes, equal aspect, ``x1 [m]`` against ``x2 [m]``.
    """
    colors = vehicle_colors(run)
    pose = run.pose  # may be memory-mapped: read only the samples drawn
    pos = np.asarray(pose[_thin(run), :, :2], dtype=float)
    radius = np.asarray(run.diameter, dtype=float) / 2.0
    path = reference_path(run)
    lo, hi = content_bounds(run, pos, path, float(np.max(radius, initial=0.0)))
    width, height, lo, hi = fit_box(lo, hi)
    wide = width >= 1.3 * height
    fig = Figure(
        figsize=(width + 1.2, height + 1.5) if wide else (width + 2.6, height + 1.0),
        layout="constrained",
    )
    ax = fig.add_subplot()
    draw_obstacles(ax, run)
    groups = platoon_groups(run)  # with platoons: a legend entry per platoon
    if groups is not None:
        lead = {name: rows[0] for name, rows in groups}
        formed = {t.name: t.color for t in platoon_tracks(run) or []}
        for name, ref in platoon_paths(run) or []:
            # a platoon of the file in its leader's colour; one a split formed, its own
            color = colors[lead[name]] if name in lead else formed[name]
            ax.plot(ref[:, 0], ref[:, 1], "--", color=color, lw=1.0)
        first = {rows[0]: name for name, rows in groups}
    elif path is not None:
        ax.plot(
            path[:, 0], path[:, 1], "--", color=_REFERENCE, lw=1.2, label="reference"
        )
    if run.n_vehicles <= LEGEND_MAX or groups is not None:
        for i, name in enumerate(run.names):
            if groups is not None:
                name = first.get(i, "_nolegend_")
            ax.plot(pos[:, i, 0], pos[:, i, 1], color=colors[i], lw=1.2, label=name)
    else:
        ax.add_collection(
            LineCollection(pos.transpose(1, 0, 2), colors=colors, lw=0.8, zorder=2)
        )
    # Snapshots: circles of the real diameter and a heading line, at regular times.
    snaps = np.unique(np.linspace(0, len(run.t) - 1, SNAPSHOTS).round().astype(int))
    circles, faces, heads = [], [], []
    anchors: list[tuple[float, np.ndarray]] = []
    for k in snaps:
        snap = np.asarray(pose[k], dtype=float)  # (n, 3)
        ok = np.isfinite(snap).all(axis=1)
        for i in np.flatnonzero(ok):
            circles.append(Circle(tuple(snap[i, :2]), radius[i]))
            faces.append(colors[i])
            tip = snap[i, :2] + radius[i] * np.array(
                [np.cos(snap[i, 2]), np.sin(snap[i, 2])]
            )
            heads.append([snap[i, :2], tip])
        tops = snap[ok, :2] + np.column_stack((np.zeros(ok.sum()), radius[ok]))
        anchors.append((float(run.t[k]), tops[np.argsort(-tops[:, 1], kind="stable")]))
    ax.add_collection(
        PatchCollection(
            circles,
            facecolors=faces,
            edgecolors="k",
            linewidths=0.6,
            alpha=0.8,
            zorder=3,
        )
    )
    if heads:
        ax.add_collection(LineCollection(heads, colors="k", linewidths=1.8, zorder=4))
    wheelbase = car_wheelbases(run)
    if wheelbase is not None:  # cars: chassis and wheels, the front one steered
        for k in snaps:
            chassis, wheels = car_lines(
                np.asarray(pose[k], dtype=float),
                np.asarray(run.steer[k], dtype=float),
                wheelbase,
                np.asarray(run.diameter, dtype=float),
            )
            ax.add_collection(LineCollection(chassis, colors="k", lw=0.8, zorder=4))
            ax.add_collection(LineCollection(wheels, colors="k", lw=2.4, zorder=4))
    # Failures (onset position) and collisions (midpoint of the vehicles involved).
    t = np.asarray(run.t, dtype=float)
    fails = [
        pose[int(np.clip(np.searchsorted(t, s), 0, len(t) - 1)), i, :2]
        for i, s, _, _ in _failure_spans(run)
    ]
    if fails:
        f = np.array(fails)
        ax.plot(f[:, 0], f[:, 1], "kx", ms=9, mew=2.2, zorder=5, label="failure")
    hits = [pose[k, who, :2].mean(axis=0) for _, k, who in _event_samples(run) if who]
    if hits:
        h = np.array(hits)
        ax.plot(h[:, 0], h[:, 1], "r*", ms=11, zorder=5, label="collision")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")  # the box was sized for these limits
    ax.set_xlabel("x1 [m]")
    ax.set_ylabel("x2 [m]")
    ax.grid(True, lw=0.4, alpha=0.5)
    what = "Trajectories"
    if run.n_vehicles > LEGEND_MAX:
        what += f" of {run.n_vehicles} vehicles"
    ax.set_title(_title(run, what))
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        if wide:
            fig.legend(
                handles,
                labels,
                loc="outside lower center",
                ncols=min(len(handles), 6),
                fontsize="small",
            )
        else:
            fig.legend(handles, labels, loc="outside right upper", fontsize="small")
    FigureCanvasAgg(fig)
    fig.draw_without_rendering()  # lay out: the labels are placed on the final axes
    place_time_labels(fig, ax, anchors)
    return fig


def leader_frame_figure(run: Run) -> Figure:
    """Draw the vehicles' positions in the leader's frame over time (Figs. 5, 8).

    Without a leader, positions are taken relative to the centroid of the vehicles
    (world-aligned axes), and the title says so.

    Parameters
    ----------
    run : Run

    Returns
    -------
    Figure
        One axes, equal aspect.
    """
    fig = Figure(figsize=(6.5, 6.0), layout="constrained")
    ax = fig.add_subplot()
    colors = vehicle_colors(run)
    radius = np.asarray(run.diameter, dtype=float) / 2.0
    idx = _thin(run)
    pos = np.asarray(run.pose[idx, :, :2], dtype=float)
    slot = np.asarray(run.slot[idx], dtype=float)
    if run.leader >= 0:
        lead = np.asarray(run.pose[idx, run.leader, :], dtype=float)
        rel = _in_frame(pos, lead)  # as Run.leader_frame(), on the samples drawn
        slot_rel = _in_frame(slot, lead)
        who = [i for i in range(run.n_vehicles) if i != run.leader]
        name = run.names[run.leader]
        ax.add_patch(
            Circle(
                (0.0, 0.0),
                radius[run.leader],
                facecolor=colors[run.leader],
                edgecolor="k",
                zorder=4,
                label=name if "leader" in name.lower() else f"{name} (leader)",
            )
        )
        ax.plot([0.0, radius[run.leader]], [0.0, 0.0], "k-", lw=2, zorder=5)
        ax.set_xlabel(f"along {name}'s heading [m]")
        ax.set_ylabel(f"left of {name} [m]")
        title = f"Positions in {name}'s frame"
    else:
        alive = np.isfinite(pos).all(axis=2) & ~np.asarray(run.failed[idx], dtype=bool)
        count = np.maximum(alive.sum(axis=1), 1)[:, None]
        centroid = np.where(alive[..., None], pos, 0.0).sum(axis=1) / count
        rel = pos - centroid[:, None, :]
        slot_rel = slot - centroid[:, None, :]
        who = list(range(run.n_vehicles))
        ax.plot([0.0], [0.0], "k+", ms=12, mew=1.5, label="centroid")
        ax.set_xlabel("x1 - centroid [m]")
        ax.set_ylabel("x2 - centroid [m]")
        title = "No leader: positions relative to the fleet centroid"
    if len(who) <= LEGEND_MAX:
        for i in who:
            ax.plot(
                rel[:, i, 0], rel[:, i, 1], color=colors[i], lw=1.2, label=run.names[i]
            )
            ax.plot(*rel[0, i], "o", mfc="none", mec=colors[i], ms=6)
            ax.add_patch(
                Circle(
                    tuple(rel[-1, i]),
                    radius[i],
                    facecolor=colors[i],
                    edgecolor="k",
                    alpha=0.85,
                    zorder=4,
                )
            )
            if np.isfinite(slot_rel[-1, i]).all():
                ax.plot(*slot_rel[-1, i], "s", mfc="none", mec=colors[i], ms=7, mew=1.2)
    else:
        ax.add_collection(
            LineCollection(
                rel[:, who].transpose(1, 0, 2), colors=[colors[i] for i in who], lw=0.6
            )
        )
    ax.plot([], [], "o", mfc="none", mec="0.3", label="start")
    ax.plot([], [], "s", mfc="none", mec="0.3", label="slot (end)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_title(_title(run, title))
    if run.n_vehicles <= LEGEND_MAX:
        ax.legend(fontsize="small", loc="best")
    else:
        _legend(ax, run)
    return fig


def _failed_mask(run: Run, idx: np.ndarray) -> np.ndarray:
    """Whether each vehicle is failed at each drawn sample, shape (T', n), bool.

    The recorded flag, or the spans of :func:`_failure_spans` (a failure listed in
    ``info["failures"]`` counts from its ``at`` until its ``until``).
    """
    failed = np.asarray(run.failed[idx], dtype=bool).copy()
    t = np.asarray(run.t, dtype=float)[idx]
    for i, start, end, _ in _failure_spans(run):
        failed[:, i] |= (t >= start) & (t < (np.inf if end is None else end))
    return failed


def _side_legend(fig: Figure, ax: Axes, run: Run) -> None:
    """Legend outside the axes on the right (one entry per vehicle, or the bands)."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside right upper", fontsize="small")


def formation_error_figure(run: Run) -> Figure:
    """Draw each vehicle's distance to its slot against time.

    While a vehicle is failed its error is not a formation error (a stopped vehicle's
    grows with the distance the fleet travels): it is drawn apart, on a lower panel
    with its own scale, and the upper panel's scale is set by the vehicles that work.

    Parameters
    ----------
    run : Run

    Returns
    -------
    Figure
        ``t [s]`` against ``formation error [m]`` of the working vehicles; below it,
        when a vehicle fails, a second axes with the error of failed vehicles while
        they are failed. Failures are vertical dashed lines in the vehicle's colour
        (dotted at their end), collisions are red stars, detections triangles on
        the time axis (hollow: withdrawn; with a black cross: a false alarm),
        reassignments grey down-triangles on the top edge (labelled with the slots
        that changed) and leader changes diamonds there in the new leader's colour.
    """
    per_platoon = platoon_error_figure(run)  # with platoons: one panel each
    if per_platoon is not None:
        return per_platoon
    colors = vehicle_colors(run)
    idx = _thin(run)
    t = np.asarray(run.t, dtype=float)
    err = np.linalg.norm(run.pose[idx, :, :2] - run.slot[idx], axis=-1)  # (T', n) [m]
    failed = _failed_mask(run, idx)
    # A failed vehicle whose slot was taken away (reconfiguration) has no distance to
    # draw while failed: it gets no lower panel.
    while_failed = np.isfinite(np.where(failed, err, np.nan)).sum(axis=0)
    who_failed = np.flatnonzero(while_failed > 1).tolist()
    if who_failed:
        fig = Figure(figsize=(9.0, 6.0), layout="constrained")
        ax, low = fig.subplots(2, 1, sharex=True, height_ratios=(2.2, 1.0))
    else:
        fig = Figure(figsize=(9.0, 4.5), layout="constrained")
        ax, low = fig.add_subplot(), None
    _series(ax, t[idx], np.where(failed, np.nan, err), run, colors)
    for n_f, (i, start, end, kind) in enumerate(_failure_spans(run)):
        for target in (ax, low) if low is not None else (ax,):
            label = "failure" if n_f == 0 and target is ax else None
            target.axvline(start, color=colors[i], ls="--", lw=1.2, label=label)
            if end is not None:
                target.axvline(end, color=colors[i], ls=":", lw=1.2)
        ax.annotate(
            f"{run.names[i]} {kind}".strip(),
            (start, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(3, -3),
            textcoords="offset points",
            va="top",
            fontsize=7,
            rotation=90,
        )
    if low is not None:
        after = np.where(failed, err, np.nan)
        if len(who_failed) <= LEGEND_MAX:
            for i in who_failed:
                low.plot(t[idx], after[:, i], color=colors[i], lw=1.2)
        else:
            draw_bands(low, t[idx], after[:, who_failed], "C3", 1.2)
        low.set_ylim(bottom=0.0)
        low.set_ylabel("while failed [m]")
        low.grid(True, lw=0.4, alpha=0.5)
        low.set_title(
            f"{len(who_failed)} failed vehicle{'s' * (len(who_failed) > 1)}: distance"
            " to slot while failed (own scale)",
            fontsize="medium",
        )
    marks: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
    for te, k, who in _event_samples(run):
        for i in who:
            e = float(np.linalg.norm(run.pose[k, i, :2] - run.slot[k, i]))
            if np.isfinite(e):
                j = int(np.clip(np.searchsorted(t[idx], te), 0, len(idx) - 1))
                marks[bool(failed[j, i]) and low is not None].append((te, e))
    for down, pts in marks.items():
        if pts:
            m = np.array(sorted(pts))
            label = None if down else "collision"
            (low if down else ax).plot(
                m[:, 0], m[:, 1], "r*", ls="none", ms=10, zorder=5, label=label
            )
    if marks[True] and not marks[False]:
        ax.plot([], [], "r*", ls="none", ms=10, label="collision")
    detection_marks(ax, run, colors)
    marked = reconfiguration_marks(ax, run, colors)
    bottom = low if low is not None else ax
    bottom.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)
    bottom.set_xlabel("t [s]")
    ax.set_ylim(bottom=0.0)
    ax.set_ylabel("formation error [m]")
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_title(_title(run, "Distance to slot"), pad=TITLE_PAD if marked else None)
    _side_legend(fig, ax, run)
    return fig


def commands_figure(run: Run) -> Figure:
    """Draw the applied commands ``v1`` and ``v2`` against time, on stacked axes.

    Parameters
    ----------
    run : Run

    Returns
    -------
    Figure
        Top: ``v1 [m/s]``; then ``v2 [rad/s]``; for a run with cars, at the bottom
        their steering angles ``delta [rad]``; shared ``t [s]`` axis.
    """
    cars = run.steer is not None  # a third panel: the cars' steering angles
    fig = Figure(figsize=(9.0, 8.0 if cars else 6.0), layout="constrained")
    axes = list(fig.subplots(3 if cars else 2, 1, sharex=True))
    top, bottom = axes[0], axes[-1]
    colors = vehicle_colors(run)
    idx = _thin(run)
    t = np.asarray(run.t, dtype=float)
    cmd = np.asarray(run.cmd[idx], dtype=float)
    _series(top, t[idx], cmd[:, :, 0], run, colors, lw=1.0)
    _series(axes[1], t[idx], cmd[:, :, 1], run, colors, lw=1.0)
    if cars:
        steer = np.asarray(run.steer[idx], dtype=float)
        _series(bottom, t[idx], steer, run, colors, lw=1.0)
        bottom.set_ylabel("steering delta [rad]")
    for i, start, end, _ in _failure_spans(run):
        for ax in axes:
            ax.axvline(start, color=colors[i], ls="--", lw=1.0)
            if end is not None:
                ax.axvline(end, color=colors[i], ls=":", lw=1.0)
    top.set_ylabel("v1 [m/s]")
    axes[1].set_ylabel("v2 [rad/s]")
    bottom.set_xlabel("t [s]")
    bottom.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)
    for ax in axes:
        ax.grid(True, lw=0.4, alpha=0.5)
    top.set_title(_title(run, "Commands"))
    _side_legend(fig, top, run)
    return fig


#: Figures written by :func:`plot_run`: file name stem and builder, in order.
FIGURES: dict[str, Callable[[Run], Figure]] = {
    "trajectories": trajectories_figure,
    "leader_frame": leader_frame_figure,
    "formation_error": formation_error_figure,
    "commands": commands_figure,
}


def plot_run(
    run: Run,
    out_dir: str | os.PathLike[str],
    *,
    dpi: int = 120,
    fmt: str = "png",
    progress: Callable[[int, int], None] | None = None,
) -> list[Path]:
    """Write the four report figures of ``run``.

    Parameters
    ----------
    run : Run
    out_dir : str or os.PathLike
        Directory, created if needed. Each file is written atomically; files of the
        same names are replaced, nothing else in the directory is touched.
    dpi : int [1/in]
        Resolution of PNG files (and of the few raster parts of PDF and SVG files),
        within :data:`DPI_RANGE`.
    fmt : {"png", "pdf", "svg"}
        File format (PDF and SVG are vector formats).
    progress : callable, optional
        Called as ``progress(done, total)`` after each figure is written.

    Returns
    -------
    list of Path
        ``trajectories.FMT``, ``leader_frame.FMT``, ``formation_error.FMT``,
        ``commands.FMT``, in that order.

    Raises
    ------
    ValueError
        On a format not in :data:`FORMATS` or a resolution outside :data:`DPI_RANGE`.
    """
    if fmt not in FORMATS:
        raise ValueError(f"format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    if not (isinstance(dpi, int | np.integer) and DPI_RANGE[0] <= dpi <= DPI_RANGE[1]):
        raise ValueError(
            f"dpi: expected a whole number from {DPI_RANGE[0]} to {DPI_RANGE[1]}, "
            f"got {dpi!r}"
        )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for stem, build in FIGURES.items():
        path = out / f"{stem}.{fmt}"
        save_figure(build(run), path, int(dpi), fmt)
        paths.append(path)
        if progress is not None:
            progress(len(paths), len(FIGURES))
    return paths
