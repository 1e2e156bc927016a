"""Report-style figures of a recorded run, as PNG files.

Figures are built on :class:`matplotlib.figure.Figure` with an explicit Agg canvas, so
this module never imports ``pyplot``, never touches matplotlib's global state and works
without a display. It reads a :class:`sandbox.run.Run` only.

:func:`plot_run` writes four figures; each also has its own builder returning the
``Figure`` (for notebooks or tests):

- ``trajectories.png`` (:func:`trajectories_figure`): paths in the world frame, with
  snapshots of the vehicles (circles of their real diameter, heading line) at regular
  intervals, the reference path dashed, obstacles, failures and collisions;
- ``leader_frame.png`` (:func:`leader_frame_figure`): every follower's position in the
  leader's frame over time (report Figs. 5 and 8). A run without a leader is drawn
  relative to the centroid of the fleet, with world-aligned axes, and says so in its
  title;
- ``formation_error.png`` (:func:`formation_error_figure`): distance of each vehicle to
  its slot against time, failures as vertical dashed lines (dotted where they end),
  collisions as red stars;
- ``commands.png`` (:func:`commands_figure`): ``v1`` and ``v2`` against time.

Fleets of more than :data:`LEGEND_MAX` vehicles are drawn with line collections and
without a per-vehicle legend.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.colors import is_color_like
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from sandbox.run import Run

__all__ = [
    "FIGURES",
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

_OBSTACLE_FACE = "0.72"
_OBSTACLE_EDGE = "0.4"
_REFERENCE = "0.45"


# ------------------------------------------------------------------------- helpers
def _colors(run: Run) -> list[str]:
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


def _draw_obstacles(ax: Axes, run: Run) -> None:
    """Add the obstacles of ``info["obstacles"]`` as grey patches."""
    for ob in _info(run, "obstacles") or []:
        kind = ob.get("type")
        style = {"facecolor": _OBSTACLE_FACE, "edgecolor": _OBSTACLE_EDGE, "zorder": 1}
        if kind == "circle":
            ax.add_patch(Circle(tuple(ob["center"]), float(ob["radius"]), **style))
        elif kind == "polygon":
            pts = np.asarray(ob["points"], dtype=float).reshape(-1, 2)
            ax.add_patch(Polygon(pts, closed=True, **style))


def _reference_path(run: Run) -> np.ndarray | None:
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


def _save(fig: Figure, path: Path, dpi: int) -> None:
    """Write ``fig`` as a PNG, atomically (temporary file, then ``os.replace``)."""
    FigureCanvasAgg(fig)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "xb") as fh:
            fig.savefig(fh, format="png", dpi=dpi, metadata={"Software": None})
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


# ------------------------------------------------------------------------- figures
def trajectories_figure(run: Run) -> Figure:
    """Draw the paths and snapshots of every vehicle in the world frame.

    Parameters
    ----------
    run : Run

    Returns
    -------
    Figure
        One axes, equal aspect, ``x1 [m]`` against ``x2 [m]``.
    """
    fig = Figure(figsize=(7.0, 7.0), layout="constrained")
    ax = fig.add_subplot()
    colors = _colors(run)
    pose = run.pose  # may be memory-mapped: read only the samples drawn
    pos = np.asarray(pose[_thin(run), :, :2], dtype=float)
    radius = np.asarray(run.diameter, dtype=float) / 2.0
    _draw_obstacles(ax, run)
    path = _reference_path(run)
    if path is not None:
        ax.plot(
            path[:, 0], path[:, 1], "--", color=_REFERENCE, lw=1.2, label="reference"
        )
    if run.n_vehicles <= LEGEND_MAX:
        for i, name in enumerate(run.names):
            ax.plot(pos[:, i, 0], pos[:, i, 1], color=colors[i], lw=1.2, label=name)
    else:
        ax.add_collection(
            LineCollection(pos.transpose(1, 0, 2), colors=colors, lw=0.8, zorder=2)
        )
    # Snapshots: circles of the real diameter and a heading line, at regular times.
    snaps = np.unique(np.linspace(0, len(run.t) - 1, SNAPSHOTS).round().astype(int))
    circles, faces, heads = [], [], []
    for k in snaps:
        snap = np.asarray(pose[k], dtype=float)  # (n, 3)
        for i in range(run.n_vehicles):
            if not np.isfinite(snap[i]).all():
                continue
            circles.append(Circle(tuple(snap[i, :2]), radius[i]))
            faces.append(colors[i])
            tip = snap[i, :2] + radius[i] * np.array(
                [np.cos(snap[i, 2]), np.sin(snap[i, 2])]
            )
            heads.append([snap[i, :2], tip])
        first = snap[:, :2][np.isfinite(snap[:, :2]).all(axis=1)]
        if len(first):
            top = first[np.argmax(first[:, 1])]
            ax.annotate(
                f"{run.t[k]:.3g} s",
                top,
                xytext=(0, 6),
                textcoords="offset points",
                ha="center",
                fontsize=7,
                color="0.25",
            )
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
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x1 [m]")
    ax.set_ylabel("x2 [m]")
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_title(_title(run, "Trajectories"))
    _legend(ax, run, loc="best")
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
    colors = _colors(run)
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


def formation_error_figure(run: Run) -> Figure:
    """Draw each vehicle's distance to its slot against time.

    Parameters
    ----------
    run : Run

    Returns
    -------
    Figure
        One axes: ``t [s]`` against ``formation error [m]``; failures are vertical
        dashed lines in the vehicle's colour (dotted at their end), collisions are red
        stars.
    """
    fig = Figure(figsize=(8.0, 4.5), layout="constrained")
    ax = fig.add_subplot()
    colors = _colors(run)
    idx = _thin(run)
    t = np.asarray(run.t, dtype=float)
    err = np.linalg.norm(run.pose[idx, :, :2] - run.slot[idx], axis=-1)  # (T', n) [m]
    _lines(ax, t[idx], err, run, colors, lw=1.2)
    for n_f, (i, start, end, kind) in enumerate(_failure_spans(run)):
        label = "failure" if n_f == 0 else None
        ax.axvline(start, color=colors[i], ls="--", lw=1.2, label=label)
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
        if end is not None:
            ax.axvline(end, color=colors[i], ls=":", lw=1.2)
    marks = [
        (te, float(np.linalg.norm(run.pose[k, i, :2] - run.slot[k, i])))
        for te, k, who in _event_samples(run)
        for i in who
    ]
    marks = [m for m in marks if np.isfinite(m[1])]
    if marks:
        m = np.array(marks)
        ax.plot(m[:, 0], m[:, 1], "r*", ms=10, zorder=5, label="collision")
    ax.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("formation error [m]")
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_title(_title(run, "Distance to slot"))
    _legend(ax, run, loc="upper right", ncols=2)
    return fig


def commands_figure(run: Run) -> Figure:
    """Draw the applied commands ``v1`` and ``v2`` against time, on stacked axes.

    Parameters
    ----------
    run : Run

    Returns
    -------
    Figure
        Top: ``v1 [m/s]``; bottom: ``v2 [rad/s]``; shared ``t [s]`` axis.
    """
    fig = Figure(figsize=(8.0, 6.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    colors = _colors(run)
    idx = _thin(run)
    t = np.asarray(run.t, dtype=float)
    cmd = np.asarray(run.cmd[idx], dtype=float)
    _lines(top, t[idx], cmd[:, :, 0], run, colors, lw=1.0)
    _lines(bottom, t[idx], cmd[:, :, 1], run, colors, lw=1.0)
    for i, start, end, _ in _failure_spans(run):
        for ax in (top, bottom):
            ax.axvline(start, color=colors[i], ls="--", lw=1.0)
            if end is not None:
                ax.axvline(end, color=colors[i], ls=":", lw=1.0)
    top.set_ylabel("v1 [m/s]")
    bottom.set_ylabel("v2 [rad/s]")
    bottom.set_xlabel("t [s]")
    bottom.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)
    for ax in (top, bottom):
        ax.grid(True, lw=0.4, alpha=0.5)
    top.set_title(_title(run, "Commands"))
    _legend(top, run, loc="upper right", ncols=2)
    return fig


#: File names written by :func:`plot_run`, and their builders.
FIGURES: dict[str, Callable[[Run], Figure]] = {
    "trajectories.png": trajectories_figure,
    "leader_frame.png": leader_frame_figure,
    "formation_error.png": formation_error_figure,
    "commands.png": commands_figure,
}


def plot_run(
    run: Run, out_dir: str | os.PathLike[str], *, dpi: int = 120
) -> list[Path]:
    """Write the four report figures of ``run`` as PNG files.

    Parameters
    ----------
    run : Run
    out_dir : str or os.PathLike
        Directory, created if needed. Each file is written atomically.
    dpi : int [1/in]

    Returns
    -------
    list of Path
        ``trajectories.png``, ``leader_frame.png``, ``formation_error.png``,
        ``commands.png``, in that order.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, build in FIGURES.items():
        path = out / name
        _save(build(run), path, dpi)
        paths.append(path)
    return paths
