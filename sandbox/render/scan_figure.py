"""A figure of one range-sensor scan: the beams, their hits and the obstacles.

:func:`scan_figure` draws the sample nearest a time ``t`` of a run recorded with
``sensors.range``: on the left the world around one sensing vehicle (the obstacles,
every vehicle's disc and heading, its beams to their readings, a dot on each hit),
on the right its readings against the beam angle (from
``-fov/2``, right, to ``+fov/2``, left), ``max_range`` dashed. ``sandbox plot RUN_DIR
--scan T`` writes it as ``scan_T.png``. Like :mod:`sandbox.render.figures` it uses an
explicit Agg canvas, never ``pyplot``.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from sandbox.render.figures import draw_obstacles, vehicle_colors
from sandbox.run.record import Run

__all__ = ["scan_figure"]


def scan_figure(run: Run, t: float, vehicle: str | None = None) -> Figure:
    """The scan of the sample nearest ``t`` [s], and ``vehicle``'s readings.

    Parameters
    ----------
    run : Run
        A run with scans (``run.ranges``).
    t : float [s]
        The time of the scan shown (the nearest recorded sample).
    vehicle : str, optional
        The vehicle whose scan is shown; default the first with a sensor.

    Raises
    ------
    ValueError
        The run has no scans, or ``vehicle`` is not a sensing vehicle of it.
    """
    if run.ranges is None or run.beam_angles is None:
        raise ValueError("the run has no range-sensor scans (no sensors.range)")
    k = int(np.argmin(np.abs(np.asarray(run.t) - float(t))))
    ranges = np.asarray(run.ranges[k], dtype=float)  # (n, B)
    angles = np.asarray(run.beam_angles, dtype=float)
    sensing = np.flatnonzero(np.isfinite(ranges).any(axis=1))
    if vehicle is None:
        row = int(sensing[0])
    elif vehicle in run.names and run.names.index(vehicle) in sensing:
        row = run.names.index(vehicle)
    else:
        raise ValueError(f"{vehicle!r} is not a vehicle with a range sensor")
    specs = run.scenario.range_specs() if run.scenario is not None else None
    reach = np.array(
        [
            np.nanmax(ranges[i])
            if specs is None or specs[i] is None
            else specs[i].max_range
            for i in range(run.n_vehicles)
        ]
    )
    pose = np.asarray(run.pose[k], dtype=float)
    colors = vehicle_colors(run)
    fig = Figure(figsize=(10.0, 4.6), layout="constrained")
    world, polar = fig.subplots(1, 2, width_ratios=(1.15, 1.0))
    draw_obstacles(world, run)
    a = pose[row, 2] + angles[row]
    ends = pose[row, :2] + ranges[row][:, None] * np.stack((np.cos(a), np.sin(a)), -1)
    ok = np.isfinite(ranges[row])
    for end in ends[ok]:
        world.plot([pose[row, 0], end[0]], [pose[row, 1], end[1]], color="0.65", lw=0.7)
    hit = ok & (ranges[row] < reach[row] - 1e-6)
    world.plot(ends[hit, 0], ends[hit, 1], "o", color="#d62728", ms=3, zorder=4)
    for i in range(run.n_vehicles):
        x, y, th = pose[i]
        if not np.isfinite([x, y, th]).all():
            continue
        r = float(run.diameter[i]) / 2
        disc = Circle((x, y), r, facecolor=colors[i], edgecolor="k", lw=0.8, zorder=3)
        world.add_patch(disc)
        tip = [x, x + r * np.cos(th)], [y, y + r * np.sin(th)]
        world.plot(*tip, color="k", lw=1, zorder=3)
    x, y = pose[row, :2]
    span = float(np.nanmax(reach[sensing])) * 1.15
    world.set_xlim(x - span, x + span)
    world.set_ylim(y - span, y + span)
    world.set_aspect("equal")
    world.set_xlabel("x1 [m]")
    world.set_ylabel("x2 [m]")
    world.set_title(f"{run.names[row]}'s scan at t = {run.t[k]:.2f} s: hits in red")
    ok = np.isfinite(ranges[row])
    polar.plot(np.degrees(angles[row, ok]), ranges[row, ok], ".-", color=colors[row])
    polar.axhline(reach[row], color="0.5", ls="--", lw=1, label="max_range")
    polar.set_xlabel("beam angle about the heading [deg] (right < 0 < left)")
    polar.set_ylabel("range [m]")
    polar.set_ylim(0, reach[row] * 1.08)
    polar.set_title(f"{run.names[row]}: {int(ok.sum())} beams")
    polar.legend(loc="lower right", fontsize=8)
    polar.grid(alpha=0.3)
    return fig
