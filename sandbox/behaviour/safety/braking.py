"""The braking barrier of the CBF filter (``safety: {filter: cbf, barrier: braking}``).

Its conditions (:func:`braking_rows`), the braking command of a vehicle whose state is
already unsafe (:func:`braking_fallback`) and the distance beyond which no condition
binds (:func:`braking_range`); the equations and what they guarantee are in
:mod:`sandbox.behaviour.safety.cbf` and ``docs/concepts/safety.md``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sandbox.model.barriers import MIN_DIST, MIN_SPEED, braking_speed

if TYPE_CHECKING:
    from sandbox.behaviour.safety.cbf import CBFState
    from sandbox.plugins.contexts import FilterContext

#: The braking barrier's time step T = BRAKING_PERIODS dt in F(g) = sqrt((A T / 2)^2
#: + 2 A g) - A T / 2 [1]: one period for the sampling, two for the drive, which
#: reaches a commanded speed within a period (so a vehicle travels up to two periods
#: at its old speed before its braking shows).
BRAKING_PERIODS = 3.0
#: The share kappa of the braking along the line of centres the barrier plans with,
#: F = F_{kappa A} [1]: the rest, (1 - kappa) A dt a period, is the reserve for the
#: line of centres and the headings turning, which the sampled barrier holds fixed.
BRAKING_SHARE = 0.75


def look_ahead_points(ctx: FilterContext, look: float) -> tuple[np.ndarray, ...]:
    """Headings, look-ahead points, and the centres and points as broadcast.

    ``p = x + l (cos x3, sin x3)`` of every vehicle; without sensing the broadcast
    ones are the true ones.
    """
    pos, theta = ctx.pos, ctx.theta
    heading = np.stack((np.cos(theta), np.sin(theta)), -1)
    p = pos + look * heading
    if ctx.seen is None:
        return heading, p, pos, p
    centre_seen = ctx.seen[:, :2]
    seen_heading = np.stack((np.cos(ctx.seen[:, 2]), np.sin(ctx.seen[:, 2])), -1)
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
    keep = np.flatnonzero(filtered[me])
    me, other = me[keep], other[keep]
    coop = filtered[other]
    target = np.where(coop[:, None], p_seen[other], centre_seen[other])
    rel = p[me] - target
    dist = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), MIN_DIST)
    big_d = 0.5 * (d[me] + d[other]) + np.where(coop, 2.0 * look, look) + margin
    return me, other, coop, rel, dist, big_d


def braking_range(
    v1_max: np.ndarray,
    lateral: np.ndarray,
    accel: np.ndarray,
    diameter: np.ndarray,
    margin: float,
    look_ahead: float,
    dt: float,
) -> float:
    """Distance [m] beyond which no braking-barrier condition can bind.

    Look-ahead points move at most ``s = sqrt(v1_max^2 + lateral^2)`` and their
    velocity changes in one period by at most ``q = a_max dt + 2 lateral``; a
    condition ``-n . (w - w^) <= rho h`` (``h = F(gap) - c^``, ``c^ <= 2 s``) can
    bind only if ``rho h < q``. With ``rho >= a_min / (2 a_max)`` (1 toward a
    vehicle that does not brake, an obstacle, a wall) none binds once ``F(gap) >= K
    = 2 s + 2 q a_max / a_min`` at the least braking ``a_min``: ``gap >= (K^2 +
    a_min dt K) / (2 a_min)``, plus the largest ``D`` and ``l``.

    >>> round(braking_range(np.array([2.0]), np.array([0.4]), np.array([5.0]),
    ...                     np.array([0.5]), 0.05, 0.1, 0.01), 3)
    4.219
    """
    s = float(np.max(np.hypot(v1_max, lateral)))
    a_min, a_max = float(np.min(accel)), float(np.max(accel))
    if not (np.isfinite(s) and np.isfinite(a_max) and a_min > 0):
        return np.inf
    q = a_max * dt + 2.0 * float(np.max(lateral))
    k = 2.0 * s + 2.0 * q * a_max / a_min
    gap = (k * k + a_min * dt * k) / (2.0 * a_min)
    big_d = float(np.max(diameter)) + 2.0 * look_ahead + margin
    return gap + big_d + look_ahead


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


def braking_rows(
    state: CBFState, ctx: FilterContext, filtered: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every braking-barrier condition of the step, ``a . w <= b``, with its ``h``.

    For vehicle ``i`` toward ``j`` (look-ahead points ``p``, ``dp = p_i - p_j``,
    ``n = dp / |dp|``, gap ``g = |dp| - D``, the last period's velocities ``w^``,
    headings ``e``)::

        c^ = -n . (w^_i - w^_j),   a_i^n = |n . e_i| min(a_i, room_i / dt),
        A = a_i^n + a_j^n,
        h = F_A(g) + A dt - c^,
        -n . (w_i - w^_i) <= rho_i (F_A(g) - c^),

    with ``F_A`` of :func:`sandbox.model.barriers.braking_speed` over ``T = 3 dt``
    and ``kappa A`` (``h = min(h, g)`` inside ``D``); ``rho_i = a_i / (a_i + a_j)``
    of a budget (``F_A >= c^``), ``a_i^n / A`` of a deficit (1/2 where ``A = 0``).
    The two conditions of a pair add up to ``c <= F_A(g)``; where ``h >= 0`` each
    asks its vehicle to slow its closing by at most ``a_i^n dt``, which a change of
    ``v1`` within its bounds (``room_i``: down to ``-v1_max``, or 0 without
    ``reverse``, heading toward; up to ``v1_max`` heading away) does. Toward a
    vehicle believed failed or driven open loop ``a_j = 0`` (``rho_i = 1``) and
    ``w^_j`` is its centre's measured velocity, against its centre (``D' = (d_i +
    d_j) / 2 + l + margin``); toward an obstacle ``a_j = 0``, ``w^_j = 0`` and the
    gap is ``s(p) - (d_i / 2 + l + margin)``. Neighbours' poses are the sensed ones
    and ``D``, ``D'`` grow by the sensing margin.

    Returns
    -------
    vehicle : ndarray, shape (r,) int
    a : ndarray, shape (r, 2)
        Unit normal in ``w`` [1].
    b : ndarray, shape (r,) [m/s]
    h : ndarray, shape (r,) [m/s]
        The barrier at the last period's velocities (< 0: unsafe).
    """
    look, margin, dt = state.look, state.margin + state.sensed, ctx.dt
    lag = BRAKING_PERIODS * dt
    pos, d, accel = ctx.pos, ctx.diameter, state.accel
    heading, p, centre_seen, p_seen = look_ahead_points(ctx, look)
    if ctx.v1_prev is not None:
        w_hat = heading * ctx.v1_prev[:, None]
        w_hat += look * ctx.v2_prev[:, None] * heading[:, ::-1] * [-1.0, 1.0]
    else:
        w_hat = np.zeros_like(pos)
    # The braking each can apply a period through v1 [m/s^2]: slowing the closing
    # (cos > 0: heading toward, v1 down; else up) by a dt, or what its bounds leave.
    lo = -state.v1_max if state.reverse else np.zeros(len(pos))
    if ctx.v1_prev is None:
        room = (np.full(len(pos), np.inf), np.full(len(pos), np.inf))
    else:
        room = (
            np.maximum(ctx.v1_prev - lo, 0.0) / dt,
            np.maximum(state.v1_max - ctx.v1_prev, 0.0) / dt,
        )

    def along_line(cos: np.ndarray, room: tuple, rows: np.ndarray) -> np.ndarray:
        down, up = room[0][rows], room[1][rows]
        return np.abs(cos) * np.minimum(accel[rows], np.where(cos > 0, down, up))

    out_v, out_a, out_b, out_h = [], [], [], []
    i, j, _ = state.neighbours.near(p_seen)
    if len(i):
        me, other, coop, rel, dist, big_d = pair_geometry(
            i, j, filtered, p, p_seen, centre_seen, d, look, margin
        )
        unit = rel / dist[:, None]
        # Braking along the line of centres: changing v1 by a_i dt within its
        # bounds changes the closing at a_i^n = |cos| of the heading to that line.
        a_me = along_line(-np.einsum("kd,kd->k", unit, heading[me]), room, me)
        toward = np.einsum("kd,kd->k", unit, heading[other])
        a_other = np.where(coop, along_line(toward, room, other), 0.0)
        pair = a_me + a_other
        w_other = np.where(coop[:, None], w_hat[other], ctx.vel[other])
        closing = -np.einsum("kd,kd->k", unit, w_hat[me] - w_other)
        budget = braking_speed(dist - big_d, BRAKING_SHARE * pair, lag) - closing
        h = budget + pair * dt
        h = np.where(dist >= big_d, h, np.minimum(h, dist - big_d))
        # A budget to spend is shared by the drives' bounds, a deficit to brake
        # away by the braking along the line (half each where neither can).
        share = np.where(coop, accel[me] / (accel[me] + accel[other]), 1.0)
        owed = np.where(
            pair > 0, a_me / np.maximum(pair, MIN_SPEED), np.where(coop, 0.5, 1.0)
        )
        rho = np.where(budget >= 0, share, owed)
        out_v.append(me)
        out_a.append(-unit)
        out_b.append(rho * budget - np.einsum("kd,kd->k", unit, w_hat[me]))
        out_h.append(h)

    near = obstacle_normals(state, ctx, p, filtered)
    if near is not None:
        rows, signed, away = near
        gap = signed - (0.5 * d[rows] + state.look + state.margin)
        closing = -np.einsum("kd,kd->k", away, w_hat[rows])
        a_me = along_line(-np.einsum("kd,kd->k", away, heading[rows]), room, rows)
        budget = braking_speed(gap, BRAKING_SHARE * a_me, lag) - closing
        h = budget + a_me * dt
        h = np.where(gap >= 0, h, np.minimum(h, gap))
        out_v.append(rows)
        out_a.append(-away)
        out_b.append(budget - np.einsum("kd,kd->k", away, w_hat[rows]))
        out_h.append(h)
    if not out_v:
        empty = np.zeros(0, dtype=np.intp)
        return empty, np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    return (
        np.concatenate(out_v),
        np.concatenate(out_a),
        np.concatenate(out_b),
        np.concatenate(out_h),
    )


def braking_fallback(
    state: CBFState, ctx: FilterContext, rows: np.ndarray
) -> np.ndarray:
    """The braking command ``z = (v1, l v2)`` of vehicles in an unsafe state.

    The last period's ``z^`` scaled by ``sigma = max(0, 1 - a dt / |v1^|)``: the
    look-ahead velocity keeps its direction and loses ``a dt`` of its speed (all of
    it below), within every bound (``|v1 - v1^| <= a dt``, ``|l v2| <= |l v2^|``);
    at the first step (no last period) the vehicle stands still.
    """
    if ctx.v1_prev is None:
        return np.zeros((len(rows), 2))
    v1, v2 = ctx.v1_prev[rows], ctx.v2_prev[rows]
    step = state.accel[rows] * ctx.dt
    speed = np.abs(v1)
    sigma = np.where(speed > step, 1.0 - step / np.maximum(speed, MIN_SPEED), 0.0)
    return np.stack((sigma * v1, sigma * state.look * v2), -1)
