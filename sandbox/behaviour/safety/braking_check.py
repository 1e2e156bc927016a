"""The braking barrier's check of the filtered commands, beyond first order.

The braking barrier's conditions (:func:`sandbox.behaviour.safety.braking.braking_rows`)
are linear in a vehicle's command ``z = (v1, l v2)`` at its braking command ``z_b``:
the QP's command keeps them, and the next state's clearances only to first order. A
command that changes the speed and turn rate at their limits, step after step, can
lose more (the braking distance is convex in ``v1``, the braking path turns with the
heading), and was measured to lose millimetres a step in a standoff. This module
checks each vehicle's command against the drive's model itself: with the others
braking, the least clearance from the end of this period on, toward every neighbour
and obstacle the conditions were made for, must be at least what the condition
allowed, ``need = H_b' - rho (H_b' - min(H, 0))``. Where it is not, the command is
moved toward the braking command, ``z_b + t (z - z_b)``, to the largest ``t`` in
``[0, 1]`` that passes (a bisection; ``t = 0``, braking, always passes), which keeps
every bound (the box is convex) and every condition (so are the half-planes).

That alone holds a vehicle whose command has nothing left to lose (``H = 0``, the QP's
command on its condition's line: every ``t > 0`` loses beyond first order and fails).
So the command is also moved toward an *escape* (:func:`_escape`): the QP's solution
with each failing condition asking back twice its shortfall, along which the
first-order gain beats the loss for small ``t``. Of the two commands that pass, the
nearer to the QP's is applied; both keep every condition's ``need`` exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.safety.cars import solved_groups
from sandbox.behaviour.safety.qp import TOLERANCE, bounded_problems, solve
from sandbox.behaviour.safety.running import ray_floor, run_speeds
from sandbox.model.barriers import (
    braking_speeds,
    closest_approach,
    driven_path,
    path_floor,
    segment_floor,
)

if TYPE_CHECKING:
    from sandbox.behaviour.safety.cars import CarCone
    from sandbox.behaviour.safety.state import Brakings, CBFState
    from sandbox.plugins.contexts import FilterContext

#: Halvings of the bisection toward the braking command [1]: ``t`` within 2^-8.
HALVINGS = 8
#: Clearance [m] a check may miss by: rounding only.
SLACK = 1e-9
#: Rounds of :func:`_escape`'s tightening [1].
ESCAPES = 3
#: How many times its shortfall a tightened condition asks back [1] (more than once,
#: so that a loss that grows with the command's size is paid along the segment).
OVERPAY = 2.0


@dataclass
class Pending:
    """What the check needs of one step's conditions (filled by ``braking_rows``).

    Attributes
    ----------
    brakings : Brakings
        The vehicles' brakings at their own headings.
    me, other : ndarray, shape (k,) int
        Each pair's vehicle and neighbour.
    coop : ndarray, shape (k,) bool
        Whether the neighbour brakes (else it keeps its commands, for ever).
    theirs : ndarray, shape (k, S, 2) [m]
        The neighbour's look-ahead points (or centre) along its braking.
    start : ndarray, shape (k, 2) [m]
        A non-braking neighbour's centre.
    course, speed, turn : ndarray, shape (k,) [rad], [m/s], [rad/s]
        Its heading and the commands it keeps
        (:func:`sandbox.model.barriers.driven_path`).
    big_d, need : ndarray, shape (k,) [m]
        The pair's ``D`` and the clearance the condition allowed.
    rows, cols : ndarray, shape (q,) int
        Each obstacle pair's vehicle and obstacle.
    clear, wall_need : ndarray, shape (q,) [m]
        The clearance kept from the obstacle and what the condition allowed.
    run : dict or None
        The run pairs toward vehicles that do not brake, of the vehicles that run
        (``braking._run_rows``): checked with the run after the command, between
        the pairs' conditions and the obstacles'.
    """

    brakings: Brakings
    me: np.ndarray
    other: np.ndarray
    coop: np.ndarray
    theirs: np.ndarray
    start: np.ndarray
    course: np.ndarray
    speed: np.ndarray
    turn: np.ndarray
    big_d: np.ndarray
    need: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    clear: np.ndarray
    wall_need: np.ndarray
    run: dict | None = None


@dataclass
class Solved:
    """The braking conditions the QP kept, for :func:`_escape`.

    Attributes
    ----------
    veh : ndarray, shape (r,) int
        Each row's vehicle.
    a : ndarray, shape (r, 2) [1]
        Its unit normal in ``z = (v1, l v2)``: ``a . z <= b``.
    b : ndarray, shape (r,) [m/s]
    rank : ndarray, shape (r,) int
        Its place among its vehicle's rows.
    cond : ndarray, shape (r,) int
        Its condition of the check (a pair's, then an obstacle's, as in
        :class:`Pending`).
    norm : ndarray, shape (r,) [s]
        ``|g|`` of the row (inf where flat).
    """

    veh: np.ndarray
    a: np.ndarray
    b: np.ndarray
    rank: np.ndarray
    cond: np.ndarray
    norm: np.ndarray


def command_points(
    state: CBFState,
    ctx: FilterContext,
    b: Brakings,
    rows: np.ndarray,
    z: np.ndarray,
    samples: int,
    target: np.ndarray | None = None,
) -> np.ndarray:
    """Look-ahead points of vehicles ``rows`` under ``z`` for a period, then braking.

    The first period runs ``dt ((1 - lag) w(z) + lag w(z^))`` (``w(z) = z1 e + z2
    e^perp``, the drive reaching ``z`` a substep late) and turns the heading by ``dt
    (lag v2^ + (1 - lag) v2)``; the braking from ``v1 = z1`` then runs along the
    heading turned by ``lag dt v2`` more, its first substep still ``lag dt z2``
    sideways. Returns shape (k, samples, 2) [m], at the start of each period. With
    ``target`` (k,) [m/s], the run toward it
    (:func:`sandbox.behaviour.safety.running.run_speeds`) in place of the braking.
    """
    dt, look, lag = ctx.dt, state.look, b.lag
    e, side = b.heading[rows], b.side[rows]
    theta = ctx.theta[rows]
    last = np.zeros((len(rows), 2))
    if ctx.v1_prev is not None:
        last = np.stack((ctx.v1_prev[rows], look * ctx.v2_prev[rows]), -1)
    turn = lag * last[:, 1] / look + z[:, 1] / look
    bent = theta + dt * turn
    path = np.stack((np.cos(bent), np.sin(bent)), -1)
    start = ctx.pos[rows] + look * e
    mix = (1.0 - lag) * z + lag * last
    first = start + dt * (mix[:, :1] * e + mix[:, 1:] * side)
    if target is None:
        speeds = braking_speeds(z[:, 0], state.accel[rows] * dt, samples)
    else:
        speeds = run_speeds(z[:, 0], state.accel[rows] * dt, target, samples)
    run = (1.0 - lag) * speeds[:, 1:] + lag * speeds[:, :-1]  # periods 1, 2, ...
    travel = np.zeros((len(rows), samples - 1))
    travel[:, 1:] = dt * np.cumsum(run[:, :-1], axis=1)
    out = np.empty((len(rows), samples, 2))
    out[:, 0] = start
    out[:, 1:] = first[:, None] + path[:, None] * travel[..., None]
    out[:, 2:] += (lag * dt * z[:, 1:] * side)[:, None]
    return out


def clearances(
    state: CBFState, ctx: FilterContext, pending: Pending, z: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each condition's clearance from the end of the period under ``z`` less need.

    Returns the vehicle of each condition and its margin [m] (< 0: fails).
    """
    b = pending.brakings
    samples = b.travel.shape[1] + 2  # a command may speed up by two steps' worth
    out_v, out_m = [], []
    me, rows = pending.me, pending.rows
    who, at = np.unique(np.concatenate((me, rows)), return_inverse=True)
    paths = command_points(state, ctx, b, who, z[who], samples)
    if len(me):
        mine = paths[at[: len(me)]]
        theirs = np.concatenate(
            (
                pending.theirs,
                np.repeat(pending.theirs[:, -1:], samples - pending.theirs.shape[1], 1),
            ),
            axis=1,
        )
        course, speed, turn = pending.course, pending.speed, pending.turn
        dt = ctx.dt
        driving = driven_path(pending.start, course, speed, turn, dt, samples)
        coop = pending.coop
        theirs = np.where(coop[:, None, None], theirs, driving)
        rel = mine - theirs
        moves = np.ceil(np.abs(z[me, 0]) / (state.accel[me] * ctx.dt) - 1e-9)
        last = np.where(coop, samples - 1, np.minimum(moves + 1, samples - 1))
        last = last.astype(np.intp)
        k = np.arange(len(me))
        hold = np.arange(samples)[None, :] > last[:, None]
        rel = np.where(hold[..., None], rel[k, last][:, None], rel)
        dist, _ = closest_approach(rel[:, 1:])
        least = dist.min(axis=1)
        if not coop.all():  # the rest point against the rest of the path
            bent = course + last * turn * dt
            tail, _ = path_floor(mine[k, last], theirs[k, last], bent, speed, turn, dt)
            least = np.minimum(least, np.where(coop, np.inf, tail))
        out_v.append(me)
        out_m.append(least - pending.big_d - pending.need)
    run = pending.run
    if run is not None and len(run["me"]):
        out_v.append(run["me"])
        out_m.append(_run_margin(state, ctx, run, z))
    if len(rows):
        points = paths[at[len(me) :]]
        flat = points.reshape(-1, 2)
        index = np.arange(len(flat))
        field = ctx.obstacle_field
        signed, near = field.pair_distance(
            flat, index, np.repeat(pending.cols, samples)
        )
        signed = signed.reshape(len(rows), samples)
        near = near.reshape(len(rows), samples, 2)
        low = segment_floor(points, signed, near)
        out_v.append(rows)
        out_m.append(low[:, 1:].min(axis=1) - pending.clear - pending.wall_need)
    if not out_v:
        return np.zeros(0, dtype=np.intp), np.zeros(0)
    return np.concatenate(out_v), np.concatenate(out_m)


def _run_margin(
    state: CBFState, ctx: FilterContext, run: dict, z: np.ndarray
) -> np.ndarray:
    """Each run pair's clearance [m] from the end of the period under ``z``, less need.

    The command for one period, then the run, against the other's driven path:
    period by period, then :func:`sandbox.behaviour.safety.running.ray_floor`.
    """
    me, dt = run["me"], ctx.dt
    samples = run["runs"].travel.shape[1] + 2
    target = run["target"][me]
    mine = command_points(state, ctx, run["runs"], me, z[me], samples, target)
    course, speed, turn = run["course"], run["speed"], run["turn"]
    theirs = driven_path(run["start"], course, speed, turn, dt, samples)
    dist, _ = closest_approach((mine - theirs)[:, 1:])
    end, k = run["runs"].moves[me] + 2, np.arange(len(me))  # two periods later
    dist[np.arange(1, samples - 1)[None, :] >= end[:, None]] = np.inf
    velocity = (mine[k, end] - mine[k, end - 1]) / dt
    bent = course + end * turn * dt
    tail, _ = ray_floor(mine[k, end], velocity, theirs[k, end], bent, speed, turn, dt)
    least = np.minimum(dist.min(axis=1), tail)
    return least - run["big_d"] - run["need"]


def passes(
    state: CBFState, ctx: FilterContext, pending: Pending, z: np.ndarray
) -> np.ndarray:
    """Whether every condition of each vehicle keeps its clearance under ``z``."""
    veh, margin = clearances(state, ctx, pending, z)
    fails = np.zeros(len(z), dtype=bool)
    np.logical_or.at(fails, veh, margin < -SLACK)
    return ~fails


def _ids(pending: Pending, vehicles: np.ndarray) -> np.ndarray:
    """The conditions of :func:`_subset`, as places among all of ``pending``'s."""
    k, q = vehicles[pending.me], vehicles[pending.rows]
    r = np.zeros(0, dtype=bool) if pending.run is None else vehicles[pending.run["me"]]
    return np.concatenate(
        (
            np.flatnonzero(k),
            len(k) + np.flatnonzero(r),
            len(k) + len(r) + np.flatnonzero(q),
        )
    )


def _subset(pending: Pending, vehicles: np.ndarray) -> Pending:
    """The conditions of the vehicles ``vehicles`` (mask, shape (n,)) only."""
    k, q = vehicles[pending.me], vehicles[pending.rows]
    run = pending.run
    if run is not None:
        r = vehicles[run["me"]]
        run = dict(run)
        for key in ("me", "start", "course", "speed", "turn", "big_d", "need"):
            run[key] = run[key][r]
    return Pending(
        pending.brakings,
        pending.me[k],
        pending.other[k],
        pending.coop[k],
        pending.theirs[k],
        pending.start[k],
        pending.course[k],
        pending.speed[k],
        pending.turn[k],
        pending.big_d[k],
        pending.need[k],
        pending.rows[q],
        pending.cols[q],
        pending.clear[q],
        pending.wall_need[q],
        run,
    )


def _bisect(
    state: CBFState,
    ctx: FilterContext,
    few: Pending,
    z: np.ndarray,
    z_b: np.ndarray,
    moved: np.ndarray,
) -> np.ndarray:
    """``z_b + t (z - z_b)`` of the ``moved`` vehicles at the largest ``t`` that passes.

    ``HALVINGS`` halvings of ``[0, 1]``; ``t = 0``, the braking command, always passes.
    The other vehicles keep ``z``.
    """
    lo, hi = np.zeros(len(z)), np.ones(len(z))
    for _ in range(HALVINGS):
        mid = 0.5 * (lo + hi)
        trial = np.where(moved[:, None], z_b + mid[:, None] * (z - z_b), z)
        good = passes(state, ctx, few, trial)
        lo = np.where(moved & good, mid, lo)
        hi = np.where(moved & ~good, mid, hi)
    out = z.copy()
    out[moved] = z_b[moved] + lo[moved, None] * (z[moved] - z_b[moved])
    return out


def _escape(
    state: CBFState,
    ctx: FilterContext,
    pending: Pending,
    z: np.ndarray,
    moved: np.ndarray,
    solved: Solved,
    box: tuple[np.ndarray, ...],
    cone: CarCone | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Commands near ``z`` that pay, to first order, for what ``z`` loses beyond it.

    Where the check finds that a vehicle's command ``z`` keeps less clearance than a
    condition allowed, by ``s`` [m], that condition's rows ``g . (z - z_b) >= -rho
    left`` are tightened to ``>= -rho left + c s`` (``b`` less ``c s / |g|``, ``c`` =
    ``OVERPAY``) and ``z`` is projected onto the tightened conditions within the
    bounds, the others as they were; ``ESCAPES`` times, the shortfalls of the new
    command added. Along the segment from the braking command to such a command the
    first-order gain ``t c s`` beats the loss beyond first order, ``O(t^2)``, for small
    ``t``: the bisection then finds a command that moves, where toward ``z`` itself
    (``s`` lost on a condition with nothing left, ``H = 0``) it finds only braking.

    Returns the commands, and which vehicles have one (their tightened conditions had
    a common point within the bounds at every round; elsewhere the command is not
    to be used).
    """
    few = _subset(pending, moved)
    ids = _ids(pending, moved)
    total = len(_ids(pending, np.ones(len(z), dtype=bool)))
    mine = np.flatnonzero(moved[solved.veh])
    veh, cond, norm = solved.veh[mine], solved.cond[mine], solved.norm[mine]
    shift = np.zeros(len(mine))
    out, ok = z.copy(), moved.copy()
    counts = np.bincount(veh, minlength=len(z))
    for _ in range(ESCAPES):
        _, margin = clearances(state, ctx, few, out)
        short = np.zeros(total)
        short[ids] = np.maximum(-margin, 0.0)
        shift += OVERPAY * short[cond] / norm
        for m, group in solved_groups(np.flatnonzero(moved), counts, cone, False):
            slot = np.full(len(z), -1, dtype=np.intp)
            slot[group] = np.arange(len(group))
            rows = np.flatnonzero(slot[veh] >= 0)
            b = solved.b[mine[rows]] - shift[rows]
            mat, off, soft = bounded_problems(
                tuple(x[group] for x in box),
                slot[veh[rows]],
                solved.a[mine[rows]],
                b,
                solved.rank[mine[rows]],
                m,
            )
            if cone is None:
                zg, slack = solve(z[group], mat, off, soft)
            else:  # a car's better cone (cars.py)
                zg, slack, _ = cone.solve(group, z[group], (mat, off, soft))
            out[group] = zg
            ok[group] &= slack <= TOLERANCE
    return out, ok


def check_commands(
    state: CBFState,
    ctx: FilterContext,
    pending: Pending,
    z: np.ndarray,
    z_b: np.ndarray,
    solved: Solved | None = None,
    box: tuple[np.ndarray, ...] | None = None,
    cone: CarCone | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The commands moved toward braking where the drive's model says they must be.

    A command that fails the check is moved toward the braking command (the largest
    ``t`` of ``z_b + t (z - z_b)`` that passes), and, given the QP's conditions as
    solved (``solved``, ``box``), toward the command of :func:`_escape` too; of the
    two, the one nearer ``z`` is kept. Both pass the check, exactly (``SLACK``).

    Parameters
    ----------
    z, z_b : ndarray, shape (n, 2) [m/s]
        The QP's commands ``(v1, l v2)`` and the braking commands.
    solved : Solved, optional
        The conditions the QP kept.
    box : tuple of ndarray, each shape (n,), optional
        The bounds ``lo1, hi1, lo2, hi2`` of ``z`` [m/s].
    cone : CarCone, optional
        The cars' reachable sets, kept by the command toward which the QP's
        conditions are tightened (:mod:`sandbox.behaviour.safety.cars`).

    Returns
    -------
    z : ndarray, shape (n, 2) [m/s]
    moved : ndarray, shape (n,) bool
        The vehicles whose command was moved.
    """
    ok = passes(state, ctx, pending, z)
    moved = ~ok
    if not moved.any():
        return z, moved
    few = _subset(pending, moved)  # the conditions of the moved vehicles only
    out = _bisect(state, ctx, few, z, z_b, moved)
    if solved is None or box is None:
        return out, moved
    target, found = _escape(state, ctx, pending, z, moved, solved, box, cone)
    if found.any():
        other = _bisect(state, ctx, _subset(pending, found), target, z_b, found)
        nearer = np.hypot(*(other - z).T) < np.hypot(*(out - z).T)
        out = np.where((found & nearer)[:, None], other, out)
    return out, moved
