"""ORCA as a safety filter on the commands (``safety: {filter: orca}``).

Optimal reciprocal collision avoidance (van den Berg, Guy, Lin and Manocha,
"Reciprocal n-body collision avoidance", Robotics Research, 2011), the field's common
baseline among many robots, for the unicycles of eq. (1) of the report as Alonso-Mora,
Breitenmoser, Rufli, Beardsley and Siegwart adapt it ("Optimal reciprocal collision
avoidance for multiple non-holonomic robots", DARS 2010):

1. each vehicle is a holonomic disc that its unicycle follows within the tracking
   error ``E`` (:mod:`sandbox.behaviour.safety.holonomic`): the disc's radius is
   ``d / 2 + E``, and the holonomic velocities it may take are those followed within
   ``E`` (a polygon, the *drive's* lines);
2. the controller's command ``(v1, v2)`` gives the preferred holonomic velocity
   (:func:`~sandbox.behaviour.safety.holonomic.holonomic_velocity`), and a vehicle's
   current velocity is the holonomic one it was given over the last period (ORCA's,
   or its command's where ORCA left it alone), as RVO2 keeps each agent's new
   velocity: the pairs' half-planes stay reciprocal while the drives lag them (with
   the measured velocities instead, the benchmark's jittered rings jam);
3. toward each of its ``neighbours`` nearest vehicles within ``neighbour_dist``, ORCA's
   half-plane for the horizon ``time_horizon`` (:mod:`~sandbox.behaviour.safety.
   orca_lines`: half of the change each, all of it toward a vehicle believed failed or
   driven open loop); toward each static obstacle within reach, the half-plane for
   ``obstacle_horizon`` (a circle as a disc standing still; a wall, box or polygon by
   the line tangent to it at its nearest point, as the CBF filter sees it);
4. a vehicle whose preferred velocity keeps all of its ORCA half-planes is left alone
   (its command passes unchanged, bit for bit); the others take the admissible
   velocity nearest to it, within the drive's polygon and the disc of ``v1_max``
   (:func:`~sandbox.behaviour.safety.orca_program.solve`: ORCA's 2-D linear program,
   and its 3-D program of least violation when the half-planes have no common point,
   the obstacles' and the drive's lines kept hard);
5. the new velocity is mapped back to ``(v1, v2)``
   (:func:`~sandbox.behaviour.safety.holonomic.unicycle_commands`);
6. the drive's own velocity ``v1 (cos x3, sin x3)`` is also kept within the obstacles'
   half-planes, up to its body and ``margin`` (:func:`obstacle_speed_cap`): the
   holonomic disc is planned afresh every period, so a vehicle turning toward its new
   velocity while it drives would otherwise creep into a wall by a part of its
   tracking error at every period (this module's addition to Alonso-Mora et al.'s
   construction, which follows each plan to its end);
7. every changed command within the vehicle's limits: ``0 <= v1 <= v1_max``,
   ``|v1 - v1(t_k-1)| <= max_accel h``, ``|v2| <= v2_max``.

ORCA assumes that a velocity is reached at once; the drive reaches it within
``max_accel`` (and the vehicles are rigid bodies that push each other), so what ORCA
guarantees for discs holds here only approximately: the benchmarks measure it
(``docs/results/state-of-the-art.md``). Symmetric swaps are ORCA's known deadlock:
reciprocal half-planes of a perfectly symmetric configuration can leave every vehicle
the velocity zero (the RVO2 library's examples perturb the preferred velocities by a
random 10^-4 m/s "to avoid deadlocks due to perfect symmetry"; this filter does not).

Only vehicles driven by the controller are filtered (not those believed failed, not
those driven open loop). Under sensing a vehicle sees the others where their broadcast
puts them (``ctx.seen``). The counters of ``metrics.json`` ``safety`` are the CBF
filter's (:mod:`sandbox.behaviour.safety.accounting`): ``active_steps`` counts the
vehicle-periods whose commands ORCA changed, ``infeasible_steps`` those whose
half-planes had no common point (the 3-D program), ``max_slack`` the largest violation
it accepted [m/s], ``min_barrier`` the least gap between two discs (or a disc and an
obstacle) [m] beyond contact of the enlarged radii and ``margin``, and ``constrained``
the episodes of each vehicle whose commands it changed
(:mod:`sandbox.behaviour.safety.constrained`).
"""

from __future__ import annotations

import numpy as np

from sandbox.behaviour.safety.accounting import FilterStep, account_step
from sandbox.behaviour.safety.cbf import PARAMS as CBF_PARAMS
from sandbox.behaviour.safety.holonomic import (
    CORNERS,
    drive_lines,
    holonomic_velocity,
    unicycle_commands,
)
from sandbox.behaviour.safety.orca_lines import surface_lines, vehicle_lines
from sandbox.behaviour.safety.orca_program import HalfPlanes, det, solve
from sandbox.geometry.neighbours import neighbour_search
from sandbox.model.barriers import MIN_DIST
from sandbox.model.dynamics import CLIP
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.contexts import FilterContext
from sandbox.plugins.registration import Param, register_filter

#: The speed bound used where a vehicle has no ``v1_max`` [m/s] (as the CBF filter).
UNLIMITED_SPEED = 1e3
#: Where the lines of a vehicle come in its program: obstacles, the drive's, vehicles.
OBSTACLE, DRIVE, VEHICLE = 0, 1, 2

PARAMS = {
    "time_horizon": Param(
        "number",
        2.0,
        "s",
        "tau of ORCA's velocity obstacles between vehicles (van den Berg et al. "
        "2011, eq. (2)): velocities that bring two discs into contact within tau are "
        "avoided; default 2 s, five times the 0.4 s braking from 2 m/s at 5 m/s^2",
        minimum=0.0,
        exclusive=True,
    ),
    "obstacle_horizon": Param(
        "number",
        1.0,
        "s",
        "tau of the velocity obstacles of static obstacles (RVO2's timeHorizonObst): "
        "a vehicle may close on an obstacle at most at its clearance / tau",
        minimum=0.0,
        exclusive=True,
    ),
    "neighbours": Param(
        "integer",
        10,
        doc="The most vehicles each vehicle avoids, the nearest first (RVO2's "
        "maxNeighbors, 10 in its examples)",
        minimum=1,
        maximum=64,
    ),
    "neighbour_dist": Param(
        "length",
        None,
        "m",
        "Vehicles farther than this are not avoided (RVO2's neighborDist; default: "
        "2 v1_max tau + the largest enlarged diameter, beyond which no velocity "
        "obstacle reaches a velocity within the speed limits)",
        minimum=0.0,
        exclusive=True,
    ),
    "margin": CBF_PARAMS["margin"],  # the same clearance as the CBF filter's
    "tracking_error": Param(
        "length",
        0.1,
        "m",
        "E: the largest distance between a vehicle and the holonomic disc it follows "
        "(Alonso-Mora et al. 2010); each disc's radius is d / 2 + E, and its "
        "velocities those the unicycle follows within E",
        minimum=0.0,
        exclusive=True,
    ),
    "align_time": Param(
        "number",
        0.4,
        "s",
        "T: the time in which a vehicle turns to head along its holonomic velocity "
        "(at least |phi| / v2_max); larger T: smaller sideways velocities "
        "(sqrt(2) E / T at a right angle to the heading); default 0.4 s, a right "
        "angle at 4 rad/s",
        minimum=0.0,
        exclusive=True,
    ),
}


def _per_vehicle(value: float | np.ndarray, n: int) -> np.ndarray:
    return np.array(np.broadcast_to(np.asarray(value, dtype=float), (n,)))


class ORCAState:
    """What the filter keeps between steps: its parameters, limits, neighbour index."""

    def __init__(self, ctx: FilterContext) -> None:
        p, n = ctx.params, len(ctx.pos)
        self.horizon = float(p["time_horizon"])
        self.obstacle_horizon = float(p["obstacle_horizon"])
        self.neighbours = int(p["neighbours"])
        self.margin = float(p["margin"])
        self.error = float(p["tracking_error"])
        self.align = float(p["align_time"])
        v1_max = _per_vehicle(ctx.v1_max, n)
        self.v1_max = np.where(np.isfinite(v1_max), v1_max, UNLIMITED_SPEED)
        self.v2_max = _per_vehicle(ctx.v2_max, n)
        self.accel = _per_vehicle(ctx.accel_max, n)
        #: Each vehicle's disc radius [m]: d / 2 + E.
        self.radius = 0.5 * np.asarray(ctx.diameter, dtype=float) + self.error
        #: The holonomic velocity each vehicle followed over the last period [m/s].
        self.velocity: np.ndarray | None = None
        radius = p.get("neighbour_dist")
        if radius is None:
            fastest = float(np.max(self.v1_max)) if n else 0.0
            widest = 2.0 * float(np.max(self.radius)) if n else 0.0
            radius = 2.0 * fastest * self.horizon + widest + self.margin
        self.range = float(radius)
        #: How far from a vehicle's surface an obstacle can matter [m].
        self.reach = (
            float(np.max(self.v1_max)) * self.obstacle_horizon
            + 2.0 * self.error
            + self.margin
            if n
            else 0.0
        )
        search = max(self.range, self.reach + float(np.max(self.radius, initial=0.0)))
        # pairs within each world only, every pair of a small world
        self.index = neighbour_search(ctx.worlds, n // ctx.worlds, search)


def _vehicle_rows(
    state: ORCAState,
    ctx: FilterContext,
    filtered: np.ndarray,
    seen: np.ndarray,
    current: np.ndarray,
    least: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """The half-planes toward the nearest vehicles: owner, point, direction, key.

    ``seen`` [m] are the others' positions as each vehicle receives them, ``current``
    (n, 2) [m/s] each vehicle's velocity of the last period (:func:`orca_commands`);
    ``least`` (n,) [m] receives each vehicle's least gap beyond contact of the discs.
    """
    i, j, _ = state.index.near(seen)
    me, other = np.concatenate((i, j)), np.concatenate((j, i))
    keep = filtered[me].nonzero()[0]
    me, other = me[keep], other[keep]
    rel_pos = seen[other] - ctx.pos[me]  # x_B - x_A, A at its true position
    dist_sq = rel_pos[:, 0] * rel_pos[:, 0] + rel_pos[:, 1] * rel_pos[:, 1]
    near = (dist_sq < state.range * state.range).nonzero()[0]
    me, other, rel_pos, dist_sq = me[near], other[near], rel_pos[near], dist_sq[near]
    # The nearest `neighbours` of each vehicle, ties by index (RVO2's sorted list).
    order = np.lexsort((other, dist_sq, me))
    me, other, rel_pos, dist_sq = (
        me[order],
        other[order],
        rel_pos[order],
        dist_sq[order],
    )
    first = np.searchsorted(me, me)
    rank = np.arange(len(me)) - first
    kept = (rank < state.neighbours).nonzero()[0]
    me, other, rel_pos, dist_sq = me[kept], other[kept], rel_pos[kept], dist_sq[kept]
    combined = state.radius[me] + state.radius[other] + state.margin
    np.minimum.at(least, me, np.sqrt(dist_sq) - combined)
    rel_vel = current[me] - current[other]
    direction, u = vehicle_lines(rel_pos, rel_vel, combined, state.horizon, ctx.dt)
    share = np.where(filtered[other], 0.5, 1.0)  # reciprocal, or all of it
    point = current[me] + share[:, None] * u
    return me, point, direction, dist_sq


def _obstacle_rows(
    state: ORCAState,
    ctx: FilterContext,
    filtered: np.ndarray,
    current: np.ndarray,
    least: np.ndarray,
) -> tuple[np.ndarray, ...] | None:
    """The half-planes toward the static obstacles in reach (None: none).

    Returns the owner, point, direction and sort key (the signed distance) of each
    half-plane, and each pair's unit normal away from the obstacle and the vehicle's
    clearance [m] beyond its body and ``margin`` (for :func:`obstacle_speed_cap`).
    """
    field = ctx.obstacle_field
    if field is None or field.empty:
        return None
    rows, cols = state.index.obstacle_pairs(ctx.pos, field)
    keep = filtered[rows].nonzero()[0]
    rows, cols = rows[keep], cols[keep]
    if not len(rows):
        return None
    signed, nearest = field.pair_distance(ctx.pos, rows, cols)
    radius = state.radius[rows] + state.margin
    gap = signed - radius
    near = (gap < state.reach).nonzero()[0]
    rows, cols, signed, nearest, radius = (
        rows[near],
        cols[near],
        signed[near],
        nearest[near],
        radius[near],
    )
    if not len(rows):
        return None
    np.minimum.at(least, rows, signed - radius)
    away = (ctx.pos[rows] - nearest) * np.where(signed < 0, -1.0, 1.0)[:, None]
    away /= np.maximum(np.hypot(away[:, 0], away[:, 1]), MIN_DIST)[:, None]
    clearance = signed - radius
    point, direction = surface_lines(away, clearance, state.obstacle_horizon)
    if isinstance(field, ObstacleField):  # a circle: a disc standing still
        circle = (field.kind[cols] == 0).nonzero()[0]
        if len(circle):
            k = field.index[cols[circle]]
            owner = rows[circle]
            rel_pos = field.circle_center[k] - ctx.pos[owner]
            combined = radius[circle] + field.circle_radius[k]
            d, u = vehicle_lines(
                rel_pos, current[owner], combined, state.obstacle_horizon, ctx.dt
            )
            point[circle] = current[owner] + u
            direction[circle] = d
    # the drive's own clearance: the vehicle's body and margin, its tracking error
    # used (obstacle_speed_cap)
    return rows, point, direction, signed, away, clearance + state.error


def obstacle_speed_cap(
    n: int,
    rows: np.ndarray,
    away: np.ndarray,
    clearance: np.ndarray,
    heading: np.ndarray,
    horizon: float,
) -> np.ndarray:
    """The largest ``v1`` [m/s] whose own velocity keeps each obstacle's half-plane.

    ``v1 (cos x3, sin x3)`` must keep ``away . v >= -clearance / horizon`` of every
    obstacle of the vehicle, with ``clearance`` the gap beyond the vehicle's body and
    ``margin`` (its disc's gap plus the tracking error ``E``, which the drive may use,
    as its disc's plan does): ``v1 <= clearance / (horizon cos a)`` where the vehicle
    heads into the obstacle at the angle ``a`` from its normal (0 once at the
    margin), inf where it heads away.

    >>> obstacle_speed_cap(1, np.array([0]), np.array([[-1.0, 0.0]]),
    ...                    np.array([0.5]), np.array([0.0]), 1.0).tolist()
    [0.5]
    """
    toward = -(away[:, 0] * np.cos(heading[rows]) + away[:, 1] * np.sin(heading[rows]))
    with np.errstate(divide="ignore"):
        limit = np.maximum(clearance, 0.0) / (horizon * toward)
    cap = np.full(n, np.inf)
    np.minimum.at(cap, rows, np.where(toward > 0.0, limit, np.inf))
    return cap


def _programs(
    who: np.ndarray,
    owner: np.ndarray,
    group: np.ndarray,
    key: np.ndarray,
    point: np.ndarray,
    direction: np.ndarray,
) -> HalfPlanes:
    """The lines of the vehicles ``who`` packed into one program each.

    Each vehicle's lines in the order of ``(group, key)``: its obstacles' (nearest
    first), the drive's polygon, the vehicles' (nearest first); the first two kinds
    hard.
    """
    slot = np.full(int(owner.max(initial=-1)) + 1, -1, dtype=np.intp)
    slot[who] = np.arange(len(who))
    mine = (slot[owner] >= 0).nonzero()[0]
    owner, group, key = slot[owner[mine]], group[mine], key[mine]
    point, direction = point[mine], direction[mine]
    order = np.lexsort((key, group, owner))
    owner, group = owner[order], group[order]
    point, direction = point[order], direction[order]
    count = np.bincount(owner, minlength=len(who))
    rank = np.arange(len(owner)) - np.searchsorted(owner, owner)
    m = int(count.max(initial=0))
    lines = HalfPlanes(
        np.zeros((len(who), m, 2)),
        np.zeros((len(who), m, 2)),
        np.zeros((len(who), m), dtype=bool),
        np.bincount(owner[group < VEHICLE], minlength=len(who)),
    )
    lines.point[owner, rank] = point
    lines.direction[owner, rank] = direction
    lines.valid[owner, rank] = True
    return lines


def orca_commands(
    state: ORCAState, ctx: FilterContext
) -> tuple[np.ndarray, np.ndarray, FilterStep]:
    """The filtered ``(v1, v2)`` of one step, and what the filter did.

    Parameters
    ----------
    state : ORCAState
    ctx : FilterContext

    Returns
    -------
    v1 : ndarray, shape (n,) [m/s]
    v2 : ndarray, shape (n,) [rad/s]
    step : FilterStep
    """
    n = len(ctx.pos)
    v1 = np.array(ctx.v1, dtype=float)
    v2 = np.array(ctx.v2, dtype=float)
    filtered = np.ones(n, dtype=bool)
    if ctx.known_failed is not None:
        filtered &= ~ctx.known_failed
    if ctx.commanded is not None:
        filtered &= ~ctx.commanded
    least = np.full(n, np.inf)
    heading = np.array(ctx.theta, dtype=float)
    seen = ctx.pos if ctx.seen is None else np.array(ctx.seen[:, :2], dtype=float)
    # The velocity each vehicle followed over the last period: the holonomic one it
    # was given (ORCA's, or its command's), as RVO2 keeps each agent's new velocity;
    # the measured one at the first step and for the vehicles not filtered.
    current = np.array(ctx.vel, dtype=float)
    if state.velocity is not None:
        current[filtered] = state.velocity[filtered]
    parts = [_vehicle_rows(state, ctx, filtered, seen, current, least)]
    walls = _obstacle_rows(state, ctx, filtered, current, least)
    if walls is not None:
        parts.insert(0, walls[:4])
    owner = np.concatenate([p[0] for p in parts])
    point = np.concatenate([p[1] for p in parts])
    direction = np.concatenate([p[2] for p in parts])
    key = np.concatenate([p[3] for p in parts])
    group = np.concatenate(
        [np.full(len(p[0]), VEHICLE if k == len(parts) - 1 else OBSTACLE) for k, p in
         enumerate(parts)]
    )  # fmt: skip
    preferred = holonomic_velocity(v1, v2, heading, state.align, state.v1_max)
    # The vehicles whose preferred velocity leaves one of their half-planes.
    gap = det(direction, point - preferred[owner])
    broken = np.zeros(n, dtype=bool)
    broken[owner[gap > 0.0]] = True
    who = (broken & filtered).nonzero()[0]
    slack = np.zeros(n)
    active = np.zeros(n, dtype=bool)
    rows = len(owner)
    if len(who):
        corner, edge = drive_lines(
            heading[who], state.v1_max[who], state.error, state.align, state.v2_max[who]
        )
        owner = np.concatenate((owner, np.repeat(who, CORNERS)))
        point = np.concatenate((point, corner.reshape(-1, 2)))
        direction = np.concatenate((direction, edge.reshape(-1, 2)))
        group = np.concatenate((group, np.full(len(who) * CORNERS, DRIVE)))
        key = np.concatenate((key, np.tile(np.arange(CORNERS, dtype=float), len(who))))
        lines = _programs(who, owner, group, key, point, direction)
        velocity, slack[who] = solve(lines, state.v1_max[who], preferred[who])
        preferred[who] = velocity
        new_v1, new_v2 = unicycle_commands(
            velocity, heading[who], state.align, state.v2_max[who]
        )
        v1[who], v2[who] = new_v1, new_v2
        active[who] = True
    if walls is not None:  # the drive's own velocity kept out of the obstacles too
        cap = obstacle_speed_cap(
            n, walls[0], walls[4], walls[5], heading, state.obstacle_horizon
        )
        over = filtered & (v1 > cap)
        v1[over], active[over] = cap[over], True
    rows_on = active.nonzero()[0]
    if len(rows_on):  # within the vehicles' limits
        lo = np.zeros(len(rows_on))
        hi = state.v1_max[rows_on]
        if ctx.v1_prev is not None:
            reach = state.accel[rows_on] * ctx.dt
            prev = ctx.v1_prev[rows_on]
            lo = np.minimum(np.maximum(lo, prev - reach), np.minimum(hi, prev + reach))
            hi = np.minimum(hi, prev + reach)
        v1[rows_on] = CLIP(v1[rows_on], lo, hi)
        limit = state.v2_max[rows_on]
        v2[rows_on] = CLIP(v2[rows_on], -limit, limit)
    state.velocity = preferred
    step = FilterStep(
        active,
        slack,
        rows,
        float(least.min(initial=np.inf)),
        np.zeros(n, dtype=bool),
        least,  # each vehicle's least barrier, for its world's
    )
    return v1, v2, step


@register_filter("orca", params=PARAMS, batched=True)
def orca(ctx: FilterContext) -> tuple[np.ndarray, np.ndarray]:
    """Optimal reciprocal collision avoidance for unicycles (van den Berg 2011)."""
    state = ctx.memory.get("orca")
    if state is None:
        state = ctx.memory["orca"] = ORCAState(ctx)
    v1, v2, step = orca_commands(state, ctx)
    account_step(ctx, step, False)
    return v1, v2
