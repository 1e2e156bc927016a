"""The platoons' slots of one world or of K worlds, their laws evaluated together.

Every platoon of every world has its own reference and law
(:mod:`sandbox.loop.platoons`), and a merge, a split or a reconfiguration changes one
world's platoons alone. The laws whose only state is the tangent angle of eq. (15),
``virtual`` (eq. (13)) and ``leader_ref`` (eq. (16)), are evaluated here for all
platoons at once: the platoons of one law, one ``rotate`` and one size, of any worlds,
are one numpy pass (:func:`_stacked`), each platoon's offsets, leader and reference
read from it and its tangent written back to its law, the numbers of the law's own
``targets`` (``tests/test_one_loop.py`` and ``tests/test_platoons.py``). Any other
law (one with estimators, a plug-in) is called platoon by platoon.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.model.laws import (
    REST_SPEED,
    LeaderReferenceFormation,
    VirtualLeaderFormation,
    rotate_offsets,
)
from sandbox.model.references import TABULATED_REFERENCES
from sandbox.plugins.registration import LawContext

#: The laws evaluated for many platoons at once (their only state: the tangent).
STACKED_LAWS = (VirtualLeaderFormation, LeaderReferenceFormation)
#: How many periods of a platoon's reference are evaluated at once.
CHUNK = 128


def platoon_targets(
    worlds: list[tuple[int, Any]],
    t: float,
    pos: np.ndarray,
    theta: np.ndarray,
    vel: np.ndarray,
    seen: np.ndarray | None,
    n: int,
    K: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Slots, ``x_ref'``, ``x_ref''`` of every vehicle and each world's point.

    Parameters
    ----------
    worlds : list of (int, Platoons)
        The worlds to plan (the live ones), each its index and its platoons, whose
        events and reconfigurations have been handled at ``t``
        (:meth:`~sandbox.loop.platoons.Platoons.prepare`).
    t : float [s]
    pos, theta, vel : ndarray, shapes (K n, 2), (K n,), (K n, 2)
        The fleet's positions [m], headings [rad] and velocities [m/s].
    seen : ndarray, shape (K n, 3), or None
        What the followers read of their leader (None: the truth).
    n, K : int
        Vehicles per world, and worlds.

    Returns
    -------
    slot, v_ref, a_ref : ndarray, shape (K n, 2)
        NaN slots for open-loop vehicles and the worlds not planned.
    point : ndarray, shape (K, 2)
        Each world's first platoon's reference point (NaN without one).
    """
    N = K * n
    slot = np.full((N, 2), np.nan)
    v_ref, a_ref = np.zeros((N, 2)), np.zeros((N, 2))
    point = np.full((K, 2), np.nan)
    buckets: dict[tuple, list] = {}
    tracked: list[tuple[np.ndarray, tuple]] = []  # rows that track their reference
    commanded: list[np.ndarray] = []
    for w, platoons in worlds:
        base = w * n
        for k, g in enumerate(platoons.groups):
            ref = reference_at(g, t, platoons.h)
            if k == 0 and ref is not None:
                point[w] = ref[0]
            if len(g.commanded):
                commanded.append(base + g.commanded)
            law = g.law
            if law is not None:
                if _stackable(law, g, ref):
                    key = (type(law), law.rotate, len(g.rows))
                    buckets.setdefault(key, []).append((base, g, ref))
                else:
                    rows = base + g.rows
                    got = _one(platoons, g, k, t, ref, pos, theta, vel, seen, base)
                    shape = (len(rows), 2)
                    slot[rows] = np.broadcast_to(got[0], shape)
                    v_ref[rows] = np.broadcast_to(got[1], shape)
                    a_ref[rows] = np.broadcast_to(got[2], shape)
            if ref is not None and len(g.track):
                tracked.append((base + g.track, ref))
    src = pos if seen is None else seen[:, :2]
    for (cls, rotate, _), members in buckets.items():
        _stacked(cls, rotate, members, src, slot, v_ref, a_ref)
    if tracked:  # each row its platoon's reference
        rows = np.concatenate([r for r, _ in tracked])
        counts = [len(r) for r, _ in tracked]
        for out, j in ((slot, 0), (v_ref, 1), (a_ref, 2)):
            out[rows] = np.repeat(np.stack([ref[j] for _, ref in tracked]), counts, 0)
    if commanded:
        slot[np.concatenate(commanded)] = np.nan
    return slot, v_ref, a_ref, point


def reference_at(g: Any, t: float, h: float) -> tuple | None:
    """Platoon ``g``'s reference ``(p, p', p'')`` at ``t`` [s] (None: it has none).

    A reference elementwise in time
    (:data:`~sandbox.model.references.TABULATED_REFERENCES`) is evaluated for
    :data:`CHUNK` periods at once and read row by row at the loop's times ``k h``
    (each row the bits of the evaluation at its time); any other at ``t``.
    """
    ref = g.reference
    if ref is None:
        return None
    k = round(t / h)
    if type(ref) not in TABULATED_REFERENCES or k * h != t:
        return ref.evaluate(t)
    start, rows = g.reference_rows
    if rows is None or not start <= k < start + CHUNK:
        start, rows = k, ref.evaluate(np.array([(k + i) * h for i in range(CHUNK)]))
        g.reference_rows = start, rows
    i = k - start  # views of rows never written
    return rows[0][i], rows[1][i], rows[2][i]


def _stackable(law: Any, g: Any, ref: tuple | None) -> bool:
    """Whether platoon ``g``'s law is evaluated with others (:data:`STACKED_LAWS`)."""
    if type(law) not in STACKED_LAWS or ref is None:
        return False
    return type(law) is VirtualLeaderFormation or g.leader >= 0


def _stacked(
    cls: type,
    rotate: bool,
    members: list[tuple[int, Any, tuple]],
    src: np.ndarray,
    slot: np.ndarray,
    v_ref: np.ndarray,
    a_ref: np.ndarray,
) -> None:
    """The targets of platoons of one law, ``rotate`` and size, in one pass.

    Eq. (13) (``virtual``: around the reference point) or eq. (16) (``leader_ref``:
    around the leader), the offsets turned by the tangent of eq. (15) with
    ``rotate`` (each platoon keeps its last tangent while its reference rests);
    ``x_ref'`` and ``x_ref''`` are the reference's.
    """
    laws = [g.law for _, g, _ in members]
    delta = np.stack([law.delta for law in laws])  # (B, m, 2) [m]
    dp = np.stack([np.asarray(ref[1], dtype=float) for _, _, ref in members])
    ddp = np.stack([np.asarray(ref[2], dtype=float) for _, _, ref in members])
    if rotate:
        tangent = np.array([law._tangent for law in laws], dtype=float)
        moving = np.hypot(dp[:, 0], dp[:, 1]) >= REST_SPEED
        if moving.any():
            tangent = np.where(moving, np.arctan2(dp[:, 1], dp[:, 0]), tangent)
            for law, angle in zip(laws, tangent.tolist(), strict=True):
                law._tangent = angle
        offsets = rotate_offsets(delta, tangent[:, None])  # eq. (14)
    else:
        offsets = delta
    if cls is VirtualLeaderFormation:
        where = np.stack([np.asarray(ref[0], dtype=float) for _, _, ref in members])
    else:
        where = src[[base + g.rows[g.leader] for base, g, _ in members]]
    targets = where[:, None, :] + offsets  # eq. (13) / (16)
    rows = np.concatenate([base + g.rows for base, g, _ in members])
    m = delta.shape[1]
    slot[rows] = targets.reshape(-1, 2)
    v_ref[rows] = np.repeat(dp, m, axis=0)
    a_ref[rows] = np.repeat(ddp, m, axis=0)


def _one(platoons, g, k, t, ref, pos, theta, vel, seen, base) -> tuple:
    """Platoon ``g``'s law called alone on its rows (world rows from ``base``)."""
    rows, lead = base + g.rows, g.leader
    if lead < 0:
        lpos, ltheta = None, None
    elif seen is None:
        lpos, ltheta = pos[rows[lead]], float(theta[rows[lead]])
    else:
        lpos, ltheta = seen[rows[lead], :2], float(seen[rows[lead], 2])
    ctx = LawContext(
        t=t,
        dt=platoons.h,
        pos=pos[rows],
        theta=theta[rows],
        vel=vel[rows],
        offset=g.offset,
        leader=lead,
        leader_pos=lpos,
        leader_theta=ltheta,
        reference=None if ref is None else tuple(np.array(x) for x in ref),
        params=g.params,
        memory=g.memory,
        platoon=np.full(len(rows), k, dtype=np.intp),
    )
    return tuple(np.asarray(x, dtype=float) for x in g.law.targets(ctx))
