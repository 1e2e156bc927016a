"""Pictures of a run of several platoons (``platoons:``): legends, paths, errors.

With ``platoons:`` every vehicle is drawn in its platoon's colour (the loader gives
the platoon's colour to each vehicle that names none), the legends name the platoons
instead of the vehicles, each platoon's reference path is drawn, and the
formation-error figure has one panel per platoon (:func:`platoon_error_figure`).
Runs of one platoon are drawn as before: every function here returns None for them.
:func:`platoon_tracks` gives every platoon of the run over time, those a split forms
too (the browser replay draws them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from sandbox.run.platoons import membership, platoon_view
from sandbox.run.record import Run


def platoon_groups(run: Run) -> list[tuple[str, list[int]]] | None:
    """Each platoon's name and vehicle rows, or None for a run of one platoon."""
    found = membership(run)
    if found is None:
        return None
    names, of = found
    return [
        (name, [i for i, v in enumerate(run.names) if of[v] == k])
        for k, name in enumerate(names)
    ]


def platoon_paths(run: Run) -> list[tuple[str, np.ndarray]] | None:
    """Each platoon's reference path (m, 2) [m] while it exists, or None.

    The platoons of :func:`platoon_tracks`: those of the file, a platoon merged into
    another until its merge, one formed by a split from its split on.
    """
    tracks = platoon_tracks(run)
    if tracks is None:
        return None
    out = []
    for track in tracks:
        pts = track.reference[np.isfinite(track.reference).all(axis=1)]
        if len(pts) >= 2:
            out.append((track.name, pts))
    return out


def platoon_references(run: Run) -> np.ndarray | None:
    """Each platoon's reference point at each sample, shape (T, P, 2) [m], or None.

    One column per platoon of :func:`platoon_tracks` (NaN while it does not exist).
    """
    tracks = platoon_tracks(run)
    if tracks is None:
        return None
    return np.stack([track.reference for track in tracks], axis=1)


@dataclass(frozen=True)
class PlatoonTrack:
    """One platoon of a run over time (see :func:`platoon_tracks`).

    Attributes
    ----------
    name, color : str
        The platoon's name and colour (a colour name of the scenario).
    reference : ndarray, shape (T, 2) [m]
        Its reference point at each sample; NaN while the platoon does not exist
        (before the split that forms it, from the merge that ends it) or without a
        reference.
    since, until : float or None [s]
        When the split that formed it fired, and when it merged into another
        (None: from the start, to the end).
    """

    name: str
    color: str
    reference: np.ndarray
    since: float | None = None
    until: float | None = None


def platoon_tracks(run: Run) -> list[PlatoonTrack] | None:
    """Every platoon of the run with its reference while it exists, or None.

    The platoons of ``platoons:`` first, then those formed by a split that fired
    (``info["platoon_events"]``), in the order they formed. A platoon formed by a
    split has the split's reference (of the run's time) from the split on, and the
    first colour of :data:`~sandbox.scenario.platoons.PLATOON_COLORS` no platoon of
    the file has (the scenario gives it none); a platoon merged into another has its
    reference until the merge. Returns None for a run of one platoon.
    """
    from sandbox.scenario.platoons import PLATOON_COLORS

    groups = platoon_groups(run)
    if groups is None:
        return None
    t = np.asarray(run.t, dtype=float)
    fired = run.info.get("platoon_events", []) if isinstance(run.info, dict) else []
    until = {e["merge"]["from"]: float(e["t"]) for e in fired if "merge" in e}

    def track(
        name: str, color: str, ref: np.ndarray, since: float | None = None
    ) -> PlatoonTrack:
        ref = np.broadcast_to(np.asarray(ref, dtype=float), (len(t), 2)).copy()
        if since is not None:
            ref[t < since - 1e-9] = np.nan  # before its split
        if name in until:
            ref[t >= until[name] - 1e-9] = np.nan  # from its merge
        return PlatoonTrack(name, color, ref, since, until.get(name))

    specs = {p.name: p for p in run.scenario.platoons}
    out = [
        track(name, specs[name].color, platoon_view(run, name).reference)
        for name, _ in groups
    ]
    splits = {e.new: e for e in run.scenario.events if e.kind == "split"}
    used = {str(p.color).lower() for p in run.scenario.platoons}
    free = [c for c in PLATOON_COLORS if c not in used] or list(PLATOON_COLORS)
    for k, e in enumerate(e for e in fired if "split" in e):
        name = e["split"]["new"]
        ref = splits[name].reference.build().evaluate(t)[0]
        out.append(track(name, free[k % len(free)], ref, float(e["t"])))
    return out


def platoon_error_figure(run: Run) -> Figure | None:
    """Draw the distance to slot of each platoon's vehicles, one panel per platoon.

    Parameters
    ----------
    run : Run

    Returns
    -------
    Figure or None
        One row per platoon, ``t [s]`` against ``formation error [m]`` of its
        vehicles (in their colours, a legend per panel; a failed vehicle's error is
        not drawn while it is failed), collisions as red stars (on every panel of a
        platoon involved), merges and splits (``events:``) as grey dash-dotted lines
        on every panel; None for a run of one platoon. The panels are the platoons
        of the file (a platoon formed by a split is drawn with the one it left).
    """
    groups = platoon_groups(run)
    if groups is None:
        return None
    t = np.asarray(run.t, dtype=float)
    err = np.linalg.norm(np.asarray(run.pose)[:, :, :2] - run.slot, axis=-1)
    err = np.where(np.asarray(run.failed, dtype=bool), np.nan, err)
    fig = Figure(figsize=(9.0, 1.2 + 2.2 * len(groups)), layout="constrained")
    axes = fig.subplots(len(groups), 1, sharex=True, squeeze=False)[:, 0]
    index = {name: i for i, name in enumerate(run.names)}
    for ax, (name, rows) in zip(axes, groups, strict=True):
        for i in rows:
            ax.plot(t, err[:, i], color=run.colors[i], lw=1.2, label=run.names[i])
        hits = []
        for e in run.events:
            who = [index[x] for x in (e.a, e.b) if x in index and index[x] in rows]
            k = int(np.clip(np.searchsorted(t, e.t), 0, len(t) - 1))
            hits += [(t[k], err[k, i]) for i in who if np.isfinite(err[k, i])]
        if hits:
            h = np.array(hits)
            ax.plot(h[:, 0], h[:, 1], "r*", ms=10, ls="none", label="collision")
        for e in run.info.get("platoon_events", []):  # merges and splits
            what = (
                f"{e['merge']['from']} merges into {e['merge']['into']}"
                if "merge" in e
                else f"{e['split']['new']} splits from {e['split']['platoon']}"
            )
            ax.axvline(e["t"], color="0.4", ls="-.", lw=1.0)
            ax.annotate(
                what,
                (e["t"], 1.0),
                xycoords=("data", "axes fraction"),
                xytext=(3, -3),
                textcoords="offset points",
                va="top",
                fontsize=7,
            )
        ax.set_ylim(bottom=0.0)
        ax.set_ylabel("error [m]")
        ax.set_title(f"platoon {name}", fontsize="medium", loc="left")
        ax.grid(True, lw=0.4, alpha=0.5)
        ax.legend(fontsize="small", loc="best", ncols=min(len(rows) + 1, 4))
    axes[-1].set_xlabel("t [s]")
    axes[-1].set_xlim(t[0], t[-1] if len(t) and t[-1] > t[0] else t[0] + 1.0)
    label = run.scenario.name if run.scenario is not None else "run"
    fig.suptitle(f"{label}: distance to slot, per platoon")
    return fig
