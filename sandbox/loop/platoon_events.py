"""Merges and splits of platoons during a run (``events:``), on plain arrays.

:func:`due` says whether an event fires at ``t``; :func:`merge` and :func:`split`
return the platoons after it. A merge of B into A appends B's slots behind A's
(B's offsets shifted along the formation's first axis so that its first slot lies
one spacing behind A's last, the spacing the smallest distance between two slots of
A or B) and assigns the followers of both to the slots by minimum total squared
distance between their positions and the slots' positions now
(:func:`scipy.optimize.linear_sum_assignment`, the assignment of
:mod:`sandbox.behaviour.reconfigure`); A's leader keeps the lead and its slot. A
split makes the listed vehicles a platoon of their own, led by the first listed
that holds a slot, with the law of the platoon they leave, their offsets taken
relative to the new leader's and the new reference; the others keep their slots.
The laws of the platoons that change restart (their estimators start from the new
configuration). See :mod:`sandbox.scenario.events` for the grammar and the checks.

A vehicle without a slot (a NaN offset: a failed vehicle a reconfiguration took the
slot from, or a leader that handed the lead over, :mod:`sandbox.behaviour.
reconfigure`) keeps none through a merge or split: it is in the platoon (an obstacle
to its recovery) but no slot is made for it, and none is given to it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.plugins.registration import LawContext

#: Spacing of the appended slots when neither platoon has two slots [m].
DEFAULT_SPACING = 1.0


def due(event: Any, t: float, groups: dict[str, Any], pos: np.ndarray) -> bool:
    """Whether ``event`` fires at ``t`` (positions ``pos`` (n, 2) [m])."""
    if event.at is not None:
        return t >= event.at - 1e-9
    name, within, other = event.when
    a, b = groups.get(name), groups.get(other)
    if a is None or b is None or not len(a.rows) or not len(b.rows):
        return False
    d = pos[a.rows][:, None, :] - pos[b.rows][None, :, :]
    return bool(np.min(d[..., 0] ** 2 + d[..., 1] ** 2) <= within * within)


def _spacing(offsets: np.ndarray) -> float:
    """The smallest distance between two offsets (m, 2) [m]."""
    if len(offsets) < 2:
        return DEFAULT_SPACING
    d = offsets[:, None, :] - offsets[None, :, :]
    dist = np.hypot(d[..., 0], d[..., 1])
    dist = dist[np.triu_indices(len(offsets), 1)]
    dist = dist[dist > 1e-9]
    return float(dist.min()) if len(dist) else DEFAULT_SPACING


def merge(
    into: Any,
    source: Any,
    t: float,
    h: float,
    state: tuple[np.ndarray, np.ndarray, np.ndarray],
    make: Any,
) -> tuple[Any, dict[str, Any]]:
    """The platoon ``into`` with ``source``'s vehicles, and the record of the event.

    Parameters
    ----------
    into, source : PlatoonGroup
        The platoons (:class:`sandbox.loop.platoons.PlatoonGroup`).
    t, h : float [s]
        Time of the event and control period.
    state : tuple of ndarray
        The fleet's positions (n, 2) [m], headings (n,) [rad], velocities (n, 2).
    make : callable
        Builds a platoon: ``make(name, rows, offset, law, params, reference,
        leader)``.
    """
    from scipy.optimize import linear_sum_assignment  # only at an event

    pos, theta, vel = state
    both = np.concatenate((into.offset, source.offset))
    held = np.isfinite(both).all(axis=1)  # the vehicles that hold a slot
    spacing = _spacing(both[held])
    mine, theirs = held[: len(into.offset)], held[len(into.offset) :]
    last = float(np.min(into.offset[mine, 0])) if mine.any() else 0.0
    first = float(np.max(source.offset[theirs, 0])) if theirs.any() else 0.0
    shift = last - spacing - first
    slots = np.concatenate((into.offset, source.offset + [shift, 0.0]))
    rows = np.concatenate((into.rows, source.rows))
    lead = into.leader
    probe = make(
        into.name, rows, slots, into.law_name, into.params, into.reference, lead
    )
    ctx = _context(probe, t, h, pos, theta, vel)
    where = (
        np.asarray(probe.law.targets(ctx)[0], dtype=float)
        if probe.law is not None
        else np.broadcast_to(ctx.reference[0], (len(rows), 2)) + slots
    )
    # The slots but the leader's, and the vehicles that hold them.
    movable = np.array(
        [k for k in range(len(rows)) if k != lead and held[k]], dtype=np.intp
    )
    free = movable
    offset = slots.copy()
    if len(movable):
        rel = pos[rows[movable]][:, None, :] - where[free][None, :, :]
        cost = rel[..., 0] ** 2 + rel[..., 1] ** 2  # [m^2]
        if np.isfinite(cost).all():  # else each keeps its slot
            r, c = linear_sum_assignment(cost)
            offset[movable[r]] = slots[free[c]]
    merged = make(
        into.name, rows, offset, into.law_name, into.params, into.reference, lead
    )
    record = {
        "t": round(t, 9),
        "merge": {"into": into.name, "from": source.name},
        "offsets": {
            int(i): ([round(float(x), 9) for x in o] if np.isfinite(o).all() else None)
            for i, o in zip(rows, offset, strict=True)
        },
    }
    return merged, record


def split(
    group: Any, event: Any, names: list[str], make: Any, t: float
) -> tuple[Any, Any, dict[str, Any]]:
    """The platoon ``group`` less ``event.vehicles``, the new platoon, the record."""
    chosen = [names.index(v) for v in event.vehicles]
    local = [int(np.flatnonzero(group.rows == i)[0]) for i in chosen]
    keep = [k for k in range(len(group.rows)) if k not in local]
    lead = group.leader
    new_lead = keep.index(lead) if lead in keep else -1
    rest = make(
        group.name,
        group.rows[keep],
        group.offset[keep],
        group.law_name,
        group.params,
        group.reference,
        new_lead,
    )
    # Led by the first listed that holds a slot (the first listed if none does).
    held = [k for k, j in enumerate(local) if np.isfinite(group.offset[j]).all()]
    first = held[0] if held else 0
    offset = group.offset[local] - group.offset[local[first]]
    made = make(
        event.new,
        group.rows[local],
        offset,
        group.law_name,
        group.params,
        event.reference.build(),
        first,
    )
    record = {
        "t": round(t, 9),
        "split": {
            "platoon": group.name,
            "new": event.new,
            "vehicles": list(event.vehicles),
        },
    }
    return rest, made, record


def _context(
    g: Any, t: float, h: float, pos: np.ndarray, theta: np.ndarray, vel: np.ndarray
) -> LawContext:
    """The law context of platoon ``g`` at ``t`` on the true state."""
    rows, lead = g.rows, g.leader
    ref = g.reference.evaluate(t) if g.reference is not None else None
    return LawContext(
        t=t,
        dt=h,
        pos=pos[rows],
        theta=theta[rows],
        vel=vel[rows],
        offset=g.offset,
        leader=lead,
        leader_pos=pos[rows[lead]] if lead >= 0 else None,
        leader_theta=float(theta[rows[lead]]) if lead >= 0 else None,
        reference=ref,
        params=g.params,
        memory={},
    )
