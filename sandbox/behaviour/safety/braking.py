"""The braking-safe barrier of the CBF filter (``safety: {barrier: braking}``).

Every vehicle has one *braking command*: turn rate 0 and the speed ``max_accel dt``
nearer 0 each period (:func:`braking_fallback`), along which its look-ahead point runs
straight along its heading and stops. The barrier of a pair is the least clearance
beyond ``D`` if both brake from now on (:func:`braking_rows`)::

    H_ij(x) = min_(tau >= 0) |q_i(tau) - q_j(tau)| - D,

``q`` the look-ahead points along those brakings (toward a vehicle believed failed or
driven open loop: its centre along the path of its last commands, for ever, the
braking vehicle's rest point included, and ``D'``, or the better backup of
:mod:`sandbox.behaviour.safety.running`; toward an obstacle: its signed distance).
A state with every ``H >= 0`` is *braking-safe*, and stays so while every vehicle
brakes: the brakings from the next state are the rest of the brakings from this one.
Each vehicle's
condition asks that its command ``z = (v1, l v2)`` lose at most its share of what is
left against its braking command ``z_b``, to first order::

    g_ij . (z_i - z_b,i) >= -rho_i (H_b' - min(H, 0)),   g_ij = dH_b' / dz_i at z_b,

``H_b' >= H`` the next state's barrier if it brakes, so the braking command keeps every
condition by construction, and a vehicle's conditions always have a common point
within its bounds. :mod:`sandbox.behaviour.safety.braking_check` then checks the QP's
command beyond first order. The distance beyond which no condition can bind is
:func:`~sandbox.behaviour.safety.state.braking_range`; the equations and what they
guarantee are in ``docs/concepts/safety.md``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.safety.braking_check import Pending
from sandbox.behaviour.safety.running import ray_floor, run_target, runs
from sandbox.behaviour.safety.state import Brakings
from sandbox.model.barriers import (
    MIN_DIST,
    braking_periods,
    braking_speeds,
    closest_approach,
    driven_path,
    local_minima,
    path_floor,
    segment_floor,
)

if TYPE_CHECKING:
    from sandbox.behaviour.safety.state import CBFState
    from sandbox.plugins.contexts import FilterContext


def columns(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The (n, 2) float array of the columns ``x`` and ``y``: ``np.stack((x, y), -1)``.

    The same values for float arrays of length n, without ``np.stack``'s checks (a
    few microseconds a call, which a small fleet's filter pays dozens of times).
    """
    out = np.empty((len(x), 2))
    out[:, 0] = x
    out[:, 1] = y
    return out


#: Conditions a pair makes: one at each of the least local minima of its distance
#: along the brakings [1] (two minima, e.g. passing then following, may trade places
#: from one step to the next; a condition at one alone lets the other go).
MINIMA = 2
#: Below this size of a condition's gradient ``|g|`` [m s] the condition is left out:
#: no command changes that pair's clearance to first order.
FLAT_GRADIENT = 1e-12


def look_ahead_points(ctx: FilterContext, look: float) -> tuple[np.ndarray, ...]:
    """Headings, look-ahead points, and the centres and points as broadcast.

    ``p = x + l (cos x3, sin x3)`` of every vehicle; without sensing the broadcast
    ones are the true ones.
    """
    pos, theta = ctx.pos, ctx.theta
    heading = columns(np.cos(theta), np.sin(theta))
    p = pos + look * heading
    if ctx.seen is None:
        return heading, p, pos, p
    centre_seen = ctx.seen[:, :2]
    seen_heading = columns(np.cos(ctx.seen[:, 2]), np.sin(ctx.seen[:, 2]))
    return heading, p, centre_seen, centre_seen + look * seen_heading


def pair_geometry(
    i: np.ndarray,
    j: np.ndarray,
    filtered: np.ndarray,
    p: np.ndarray,
    p_seen: np.ndarray,
    centre_seen: np.ndarray,
    d: np.ndarray,
    look: float,
    margin: float,
) -> tuple[np.ndarray, ...]:
    """Both directions of the pairs ``(i, j)``, from each filtered vehicle ``me``.

    Toward a cooperating ``other`` (filtered too) the gap is between look-ahead
    points and ``D = (d_me + d_other) / 2 + 2 l + margin``; toward another, against
    its centre with ``l`` once. Returns ``me, other, coop, rel, dist, D``, ``rel`` from
    the other's point (or centre) to ``p[me]``.
    """
    me = np.concatenate((i, j))
    other = np.concatenate((j, i))
    keep = filtered[me].nonzero()[0]
    me, other = me[keep], other[keep]
    coop = filtered[other]
    target = np.where(coop[:, None], p_seen[other], centre_seen[other])
    rel = p[me] - target
    dist = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), MIN_DIST)
    big_d = 0.5 * (d[me] + d[other]) + np.where(coop, 2.0 * look, look) + margin
    return me, other, coop, rel, dist, big_d


def obstacle_normals(
    state: CBFState, ctx: FilterContext, p: np.ndarray, filtered: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The filtered vehicles near an obstacle: rows, signed distances, unit normals.

    For each candidate pair of a filtered vehicle's look-ahead point ``p`` and a static
    obstacle: the vehicle's row, the signed distance of ``p`` to the surface [m] and
    the unit normal away from it there; None when there is no such pair.
    """
    field = ctx.obstacle_field
    if field is None or field.empty:
        return None
    rows, cols = state.neighbours.obstacle_pairs(p, field)
    keep = np.flatnonzero(filtered[rows])
    rows, cols = rows[keep], cols[keep]
    if not len(rows):
        return None
    signed, point = field.pair_distance(p, rows, cols)
    away = (p[rows] - point) * np.where(signed < 0, -1.0, 1.0)[:, None]
    norm = np.maximum(np.hypot(away[:, 0], away[:, 1]), MIN_DIST)
    away /= norm[:, None]
    return rows, signed, away


def brakings(ctx: FilterContext, state: CBFState, theta: np.ndarray) -> Brakings:
    """Every vehicle's braking (:class:`Brakings`), at the headings ``theta``."""
    n, dt = len(ctx.pos), ctx.dt
    lag = 1.0 / max(int(ctx.substeps), 1)
    step = state.accel * dt
    last = np.zeros(n) if ctx.v1_prev is None else ctx.v1_prev
    turn = np.zeros(n) if ctx.v2_prev is None else ctx.v2_prev
    first = np.sign(last) * np.maximum(np.abs(last) - step, 0.0) + 0.0
    moves = braking_periods(first, step)
    # the command's period and two at rest: the lag's substep, then none (a
    # horizon that does not depend on the slowest vehicle's stop, nor on the worlds)
    periods = int(moves.max(initial=0)) + 3
    speeds = braking_speeds(first, step, periods + 1)
    before = np.concatenate((last[:, None], speeds[:, :-1]), axis=1)
    run = (1.0 - lag) * speeds + lag * before
    moving = (speeds != 0.0).astype(float)
    moving[:, 0] = 1.0  # the command's own period, whatever its speed
    was = np.concatenate((np.zeros((n, 1)), moving[:, :-1]), axis=1)
    grows = (1.0 - lag) * moving + lag * was
    travel, slope = np.zeros_like(speeds), np.zeros_like(speeds)
    travel[:, 1:] = dt * np.cumsum(run[:, :-1], axis=1)
    slope[:, 1:] = dt * np.cumsum(grows[:, :-1], axis=1)
    heading = np.stack((np.cos(theta), np.sin(theta)), -1)
    bent = theta + lag * dt * turn
    path = np.stack((np.cos(bent), np.sin(bent)), -1)
    return Brakings(
        first=first,
        speeds=run,
        travel=travel,
        slope=slope,
        heading=heading,
        side=heading[:, ::-1] * [-1.0, 1.0],
        path=path,
        path_side=path[:, ::-1] * [-1.0, 1.0],
        moves=moves,
        lag=lag,
    )


def braking_points(
    ctx: FilterContext, b: Brakings, rows: np.ndarray, start: np.ndarray, look: float
) -> np.ndarray:
    """The look-ahead points of vehicles ``rows`` braking from ``start``, (k, S, 2).

    Sampled at the start of each period: the first period along the heading (and
    ``lag dt l v2^`` sideways), the rest along the braking's heading.
    """
    turn = np.zeros(len(rows)) if ctx.v2_prev is None else ctx.v2_prev[rows]
    one = b.travel[rows, 1]
    out = (
        start[:, None]
        + b.path[rows][:, None] * (b.travel[rows] - one[:, None])[..., None]
    )
    shift = one[:, None] * b.heading[rows] + (
        b.lag * ctx.dt * look * turn[:, None] * b.side[rows]
    )
    out[:, 1:] += shift[:, None]
    out[:, 0] = start
    return out


def driven(ctx: FilterContext, rows: np.ndarray) -> tuple[np.ndarray, ...]:
    """Headings [rad], speeds [m/s] and turn rates [rad/s] of vehicles that drive on.

    A vehicle believed failed or driven open loop is taken to keep the commands its
    drive applied over the last period (``v1^``, ``v2^``; at rest before any), from
    its heading as the filter sees it (the estimate under sensing).
    """
    course = ctx.theta[rows] if ctx.seen is None else ctx.seen[rows, 2]
    if ctx.v1_prev is None:
        return course, np.zeros(len(rows)), np.zeros(len(rows))
    return course, ctx.v1_prev[rows], ctx.v2_prev[rows]


def _gradient(
    state: CBFState,
    ctx: FilterContext,
    me: np.ndarray,
    normal: np.ndarray,
    period: np.ndarray,
    frac: np.ndarray,
    b: Brakings,
) -> np.ndarray:
    """``dH / dz`` at the braking command, ``z = (v1, l v2)``, shape (k, 2) [s].

    The clearance is reached at ``tau = (period + frac) dt >= dt`` along the unit
    ``normal`` (away from the other). A command ``z`` for the first period and the
    braking from it after: ``v1`` moves the point ``(1 - lag) dt`` along ``e`` in
    the first period and by the rest of ``d travel / d v1`` along the braking's
    heading after; ``l v2`` moves it along ``e^perp`` for ``(1 - lag) dt`` and, the
    drive reaching the braking's turn rate 0 one substep late, ``lag dt`` more, and
    turns the rest of the braking, ``travel(tau) - travel(dt)``, by ``v2 dt``.
    """
    dt, look = ctx.dt, state.look
    own = (1.0 - b.lag) * dt
    slope = b.slope[me, period] + frac * (b.slope[me, period + 1] - b.slope[me, period])
    ran = b.travel[me, period] + frac * dt * b.speeds[me, period]
    rest = ran - b.travel[me, 1]
    g1 = own * np.einsum("kd,kd->k", normal, b.heading[me])
    g1 += (slope - b.slope[me, 1]) * np.einsum("kd,kd->k", normal, b.path[me])
    # l v2 runs sideways for the period's (1 - lag) and the next one's lag
    late = dt * np.clip(period + frac - 1.0, 0.0, b.lag)
    g2 = (own + late) * np.einsum("kd,kd->k", normal, b.side[me])
    g2 += dt * rest / look * np.einsum("kd,kd->k", normal, b.path_side[me])
    return np.stack((g1, g2), -1)


def _need(after: np.ndarray, now: np.ndarray, share) -> np.ndarray:
    """The clearance [m] a condition allows the next state: ``H_b' - rho left``."""
    return after - share * np.maximum(after - np.minimum(now, 0.0), 0.0)


def _rows(
    ctx: FilterContext,
    me: np.ndarray,
    grad: np.ndarray,
    after: np.ndarray,
    now: np.ndarray,
    share: np.ndarray,
    first: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The half-planes ``a . w <= b`` of ``g . (z - z_b) >= -rho (H_b' - min(H, 0))``.

    ``H_b'`` (``after``) is the next state's barrier if the vehicle brakes, ``H``
    (``now``) this state's, ``H <= H_b'``: a command may lose the share ``rho`` of
    what is left above 0 (above ``H`` where ``H < 0``). In ``z``, ``-g / |g| . z <=
    (-g . z_b + rho (H_b' - min(H, 0))) / |g|`` with ``z_b = (first, 0)``; ``a`` is
    turned into ``w = R(x3) z``. A flat gradient gives the always-kept row ``a = 0,
    b = 1``. Also returns ``|g|`` [s] (inf where flat): a clearance [m] over it is
    the row's ``b`` [m/s].
    """
    norm = np.hypot(grad[:, 0], grad[:, 1])
    flat = norm < FLAT_GRADIENT
    norm = np.where(flat, 1.0, norm)
    a_z = -grad / norm[:, None]
    left = np.maximum(after - np.minimum(now, 0.0), 0.0)  # >= 0 but for rounding
    b = (-grad[:, 0] * first[me] + share * left) / norm
    a_z[flat], b[flat] = 0.0, 1.0
    c, s = np.cos(ctx.theta[me]), np.sin(ctx.theta[me])
    a_w = np.stack((c * a_z[:, 0] - s * a_z[:, 1], s * a_z[:, 0] + c * a_z[:, 1]), -1)
    return a_w, b, np.where(flat, np.inf, norm)


def braking_rows(
    state: CBFState,
    ctx: FilterContext,
    filtered: np.ndarray,
    pending: dict | None = None,
    braked: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every braking-barrier condition of the step, ``a . w <= b``, with its ``H``.

    For vehicle ``i`` toward ``j``: both brake from now on (:class:`Brakings`;
    toward a vehicle believed failed or driven open loop, its centre along the path
    of its last commands and ``D'``, for ever: period by period until ``i`` has
    stopped, then its rest point against all of the path,
    :func:`sandbox.model.barriers.path_floor`; or ``i``'s run where that is better,
    ``_run_rows``, unless ``braked`` (n,) says it brakes), their
    look-ahead points ``q`` sampled at the periods, and the least distance less
    ``D`` exactly (:func:`sandbox.model.barriers.closest_approach`; straight motion
    within each period): ``H`` over all of it, ``H_b'`` from the end of this period
    on (the next state's barrier if both brake). Toward an obstacle the least over
    each period is bounded below by the tangent lines of its signed distance, convex,
    at the period's two ends (:func:`sandbox.model.barriers.segment_floor`), less
    ``d / 2 + l + margin``. The condition is ``g .
    (z - z_b) >= -rho (H_b' - min(H, 0))`` (``_gradient``, ``_rows``), ``rho = a_i
    / (a_i + a_j)`` toward a cooperating vehicle, 1 otherwise. Under sensing the
    neighbours' poses are their estimate (``ctx.seen``, set by
    :func:`~sandbox.behaviour.safety.cbf.filter_commands`) and ``D``, ``D'`` grow
    by the sensing margin. ``pending``,
    if given, receives under ``"check"`` what
    :func:`sandbox.behaviour.safety.braking_check.check_commands` needs.

    Returns
    -------
    vehicle : ndarray, shape (r,) int
    a : ndarray, shape (r, 2)
        Unit normal in ``w`` [1] (0 where the condition is flat).
    b : ndarray, shape (r,) [m/s]
    h : ndarray, shape (r,) [m]
        The barrier ``H`` of the state (< 0: not braking-safe).
    """
    look, margin, dt = state.look, state.margin + state.sensed, ctx.dt
    d, accel = ctx.diameter, state.accel
    _, p, centre_seen, p_seen = look_ahead_points(ctx, look)
    own = brakings(ctx, state, ctx.theta)
    seen = own if ctx.seen is None else brakings(ctx, state, ctx.seen[:, 2])
    samples = own.travel.shape[1]

    out_v, out_a, out_b, out_h, out_c, out_g = [], [], [], [], [], []
    pairs = runners = 0  # the check's conditions: the pairs', the runs', obstacles'
    run = None
    i, j, _ = state.neighbours.near(p_seen)
    if len(i):
        me, other, coop, _, _, big_d = pair_geometry(
            i, j, filtered, p, p_seen, centre_seen, d, look, margin
        )
        mine = braking_points(ctx, own, me, p[me], look)
        theirs = braking_points(ctx, seen, other, p_seen[other], look)
        # A vehicle that does not brake keeps its commands, for ever: its centre
        # along its driven path, sampled while the braking one stops, then the
        # least distance from the braking one's rest point to all of the path on.
        course, speed, turn = driven(ctx, other)
        driving = driven_path(centre_seen[other], course, speed, turn, dt, samples)
        theirs = np.where(coop[:, None, None], theirs, driving)
        rel = mine - theirs
        rows = np.arange(len(me))
        last = np.where(coop, samples - 1, np.minimum(own.moves[me] + 1, samples - 1))
        hold = np.arange(samples)[None, :] > last[:, None]
        rel = np.where(hold[..., None], rel[rows, last][:, None], rel)
        # H over all of the brakings; the next state's from the end of this period
        # on, one condition at each of its least local minima along the way.
        dist, frac = closest_approach(rel)
        tail_n = None
        if not coop.all():  # the rest point against the path, as a last column
            bent = course + last * turn * dt
            tail, tail_n = path_floor(
                mine[rows, last], theirs[rows, last], bent, speed, turn, dt
            )
            dist = np.concatenate((dist, np.where(coop, np.inf, tail)[:, None]), 1)
            frac = np.concatenate((frac, np.ones((len(me), 1))), 1)
        now = pair_now = dist.min(axis=1) - big_d
        share = np.where(coop, accel[me] / (accel[me] + accel[other]), 1.0)
        pair_after = dist[:, 1:].min(axis=1) - big_d
        pair = (me, other, coop, theirs, big_d, _need(pair_after, now, share))
        period, ok = local_minima(dist[:, 1:], MINIMA)
        keep = ok | (np.arange(MINIMA) == 0)
        pick, period = np.nonzero(keep)[0], period[keep] + 1
        frac, after = frac[pick, period], dist[pick, period]
        at_tail = period == samples - 1  # the rest point, at the last sample
        period = np.where(at_tail, samples - 2, period)
        near = rel[pick, period] + frac[:, None] * (
            rel[pick, period + 1] - rel[pick, period]
        )
        normal = near / np.maximum(after, MIN_DIST)[:, None]
        if tail_n is not None:
            normal = np.where(at_tail[:, None], tail_n[pick], normal)
        me, other, coop, big_d, now = (
            me[pick],
            other[pick],
            coop[pick],
            big_d[pick],
            now[pick],
        )
        grad = _gradient(state, ctx, me, normal, period, frac, own)
        share = share[pick]
        a_w, b, norm = _rows(ctx, me, grad, after - big_d, now, share, own.first)
        out_v.append(me)
        out_a.append(a_w)
        out_b.append(b)
        out_h.append(now)
        out_c.append(pick)
        out_g.append(norm)
        pairs = len(pair[0])
        if not pair[2].all():  # the better of braking and the run, toward them
            run = _run_rows(state, ctx, own, pair, pair_now, braked, p, centre_seen)
            mode, rows, pair_need = run["mode"], run["rows"], pair[5]
            drop = ~coop & mode[me]  # the braking's rows of the vehicles that run
            for out in (out_v, out_a, out_b, out_h, out_c, out_g):
                out[0] = out[0][~drop]
            pair = pair[:5] + (np.where(mode[pair[0]] & ~pair[2], -np.inf, pair_need),)
            out_v.append(rows[0])
            out_a.append(rows[1])
            out_b.append(rows[2])
            out_h.append(rows[3])
            out_c.append(pairs + rows[4])
            out_g.append(rows[5])
            runners = len(run["me"])

    field = ctx.obstacle_field
    rows = cols = np.zeros(0, dtype=np.intp)
    if field is not None and not field.empty:
        rows, cols = state.neighbours.obstacle_pairs(p, field)
        keep = np.flatnonzero(filtered[rows])
        rows, cols = rows[keep], cols[keep]
    if len(rows):
        points = braking_points(ctx, own, rows, p[rows], look)
        flat = points.reshape(-1, 2)
        index = np.arange(len(flat))
        signed, point = field.pair_distance(flat, index, np.repeat(cols, samples))
        signed = signed.reshape(len(rows), samples)
        low = segment_floor(points, signed, point.reshape(len(rows), samples, 2))
        clear = 0.5 * d[rows] + look + state.margin
        now = low.min(axis=1) - clear
        wall = (rows, cols, clear, _need(low[:, 1:].min(axis=1) - clear, now, 1.0))
        seg, ok = local_minima(low[:, 1:], MINIMA)  # from the end of this period on
        keep = ok | (np.arange(MINIMA) == 0)
        k, seg = np.nonzero(keep)[0], seg[keep] + 1
        after, now = low[k, seg] - clear[k], now[k]
        at = np.where(signed[k, seg] <= signed[k, seg + 1], seg, seg + 1)
        away = flat[k * samples + at] - point[k * samples + at]
        away *= np.where(signed[k, at] < 0, -1.0, 1.0)[:, None]
        away /= np.maximum(np.hypot(away[:, 0], away[:, 1]), MIN_DIST)[:, None]
        at_end = at == samples - 1  # the last sample: the period before it, ended
        period, frac = np.where(at_end, at - 1, at), np.where(at_end, 1.0, 0.0)
        rows = rows[k]
        grad = _gradient(state, ctx, rows, away, period, frac, own)
        a_w, b, norm = _rows(ctx, rows, grad, after, now, np.ones(len(rows)), own.first)
        out_v.append(rows)
        out_a.append(a_w)
        out_b.append(b)
        out_h.append(now)
        out_c.append(pairs + runners + k)
        out_g.append(norm)
    if pending is not None:
        none = np.zeros(0, dtype=np.intp)
        if not len(i):
            pair = (none, none, none.astype(bool), np.zeros((0, samples, 2)))
            pair += (np.zeros(0), np.zeros(0))
        if not len(rows):
            wall = (none, none, np.zeros(0), np.zeros(0))
        me, other, coop, theirs, big_d, need = pair
        pending["walls"] = len(rows)  # the obstacle rows, last
        # each row's condition of the check, and its |g| [s]
        pending["cond"] = np.concatenate(out_c) if out_c else none
        pending["norm"] = np.concatenate(out_g) if out_g else np.zeros(0)
        pending["check"] = Pending(
            own,
            me,
            other,
            coop,
            theirs,
            centre_seen[other],
            *driven(ctx, other),
            big_d,
            need,
            *wall,
            run=run,
        )
        pending["run"] = None if run is None else run["mode"]
    if not out_v:
        empty = np.zeros(0, dtype=np.intp)
        return empty, np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    return (
        np.concatenate(out_v),
        np.concatenate(out_a),
        np.concatenate(out_b),
        np.concatenate(out_h),
    )


def _run_rows(
    state: CBFState,
    ctx: FilterContext,
    own: Brakings,
    pair: tuple,
    pair_now: np.ndarray,
    braked: np.ndarray | None,
    p: np.ndarray,
    centre_seen: np.ndarray,
) -> dict:
    """The run's conditions toward vehicles that do not brake, where it is better.

    For every pair of a filtered vehicle and one that does not brake, the run's
    barrier ``H^r`` (:mod:`sandbox.behaviour.safety.running`); a vehicle *runs*
    where the least ``H^r`` over its such pairs is larger than the least ``H``
    of its braking (``pair_now``), and ``braked`` (n,) does not forbid it. Returns
    ``mode`` (n,) bool, the run pairs of the vehicles that run (``me``, ``start``,
    ``course``, ``speed``, ``turn``, ``big_d``, ``need``, ``runs``, ``target``) and
    their ``rows`` (vehicle, ``a``, ``b``, ``H``, the pair, ``|g|``).
    """
    dt, look, n = ctx.dt, state.look, len(ctx.pos)
    me, other, coop, _, big_d, _ = pair
    f = np.flatnonzero(~coop)
    me, other, big_d = me[f], other[f], big_d[f]
    b = runs(ctx, state, ctx.theta, own)
    samples = b.travel.shape[1]
    mine = braking_points(ctx, b, me, p[me], look)
    course, speed, turn = driven(ctx, other)
    theirs = driven_path(centre_seen[other], course, speed, turn, dt, samples)
    dist, frac = closest_approach(mine - theirs)
    end, k = b.moves[me], np.arange(len(me))  # each run sampled to its own end
    dist[np.arange(samples - 1)[None, :] >= end[:, None]] = np.inf
    velocity = (mine[k, end] - mine[k, end - 1]) / dt  # at full speed from then on
    bent = course + end * turn * dt
    tail, tail_n = ray_floor(
        mine[k, end], velocity, theirs[k, end], bent, speed, turn, dt
    )
    dist = np.concatenate((dist, tail[:, None]), 1)
    frac = np.concatenate((frac, np.ones((len(me), 1))), 1)
    now = dist.min(axis=1) - big_d
    worst_b, worst_r = np.full(n, np.inf), np.full(n, np.inf)
    np.minimum.at(worst_b, me, pair_now[f])
    np.minimum.at(worst_r, me, now)
    mode = worst_r > worst_b
    if braked is not None:
        mode &= ~braked
    use = np.flatnonzero(mode[me])
    me, big_d, now, dist, frac = me[use], big_d[use], now[use], dist[use], frac[use]
    mine, theirs, tail_n, end = mine[use], theirs[use], tail_n[use], end[use]
    need = _need(dist[:, 1:].min(axis=1) - big_d, now, 1.0)
    period, ok = local_minima(dist[:, 1:], MINIMA)
    keep = ok | (np.arange(MINIMA) == 0)
    pick, period = np.nonzero(keep)[0], period[keep] + 1
    frac, after = frac[pick, period], dist[pick, period]
    at_tail = period == samples - 1  # the bound from the run's end on
    period = np.where(at_tail, end[pick] - 1, period)
    rel = mine - theirs
    near = rel[pick, period] + frac[:, None] * (
        rel[pick, period + 1] - rel[pick, period]
    )
    normal = near / np.maximum(after, MIN_DIST)[:, None]
    normal = np.where(at_tail[:, None], tail_n[pick], normal)
    who = me[pick]
    grad = _gradient(state, ctx, who, normal, period, frac, b)
    a_w, rhs, norm = _rows(
        ctx, who, grad, after - big_d[pick], now[pick], np.ones(len(pick)), b.first
    )
    target = run_target(state, ctx)
    return {
        "mode": mode,
        "me": me,
        "start": centre_seen[other[use]],
        "course": course[use],
        "speed": speed[use],
        "turn": turn[use],
        "big_d": big_d,
        "need": need,
        "runs": b,
        "target": target,
        "rows": (who, a_w, rhs, now[pick], pick, norm),
    }


def braking_fallback(
    state: CBFState, ctx: FilterContext, rows: np.ndarray
) -> np.ndarray:
    """The braking command ``z = (v1, l v2)`` of vehicles ``rows``.

    Turn rate 0 and the last period's ``v1^`` moved ``max_accel dt`` toward 0 (to 0
    below): within every bound, and the command every braking-barrier condition
    is made to keep; at the first step (no last period) the vehicle stands still.
    """
    if ctx.v1_prev is None:
        return np.zeros((len(rows), 2))
    v1 = ctx.v1_prev[rows]
    step = state.accel[rows] * ctx.dt
    v1 = np.sign(v1) * np.maximum(np.abs(v1) - step, 0.0) + 0.0
    return np.stack((v1, np.zeros(len(rows))), -1)
