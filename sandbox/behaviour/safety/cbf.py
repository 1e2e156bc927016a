"""A control-barrier-function safety filter on the commands (``safety: {filter: cbf}``).

The unicycle ``x1' = v1 cos x3, x2' = v1 sin x3, x3' = v2`` (eq. (1) of the report) is
filtered through its look-ahead point ``p = x + l (cos x3, sin x3)``, whose velocity is
an invertible linear map of the inputs::

    p' = w = R(x3) diag(1, l) (v1, v2),
    v1 = cos x3 w1 + sin x3 w2,   v2 = (-sin x3 w1 + cos x3 w2) / l,

so ``p`` is a single integrator and every barrier below is linear in ``w``.

Barriers, with ``gamma`` [1/s] and ``margin`` [m]:

- **between two filtered vehicles** ``h_ij = |p_i - p_j|^2 - D^2``, ``D = (d_i + d_j)
  / 2 + 2 l + margin``; ``h_ij >= 0`` keeps the centres ``d + margin`` apart. The
  condition ``2 (p_i - p_j) . (w_i - w_j) >= -gamma h_ij`` is split between the two:
  each vehicle solves alone for its own ``w_i`` with half of the budget. With
  ``neighbour_velocity: broadcast`` (the default) each takes half of the *change*
  of the relative velocity from the velocities of the last period ``w^_i, w^_j``
  (which both know: the commands applied, broadcast)::

      2 (p_i - p_j) . w_i >= -gamma h_ij / 2 + (p_i - p_j) . (w^_i + w^_j);

  the two conditions add up to the pair's exactly, and a platoon moving together at a
  common velocity is not slowed. With ``zero`` each treats the other as standing
  still: ``2 (p_i - p_j) . w_i >= -gamma h_ij / 2`` (the textbook split, which brakes
  a moving platoon whose neighbours are nearer than the barrier allows at rest);
- **toward a vehicle the platoon believes failed** (``Simulation.known_failed``) **or
  one driven open loop** (``drive: commands``): full responsibility, against its
  centre ``c_j`` and its measured velocity ``c_j'``: ``h = |p_i - c_j|^2 - D'^2``,
  ``D' = (d_i + d_j) / 2 + l + margin``, ``2 (p_i - c_j) . (w_i - c_j') >= -gamma h``;
- **toward a static obstacle** (circles, boxes, polygons, walls of
  :class:`~sandbox.behaviour.recovery.ObstacleField`): full responsibility against the
  nearest surface point, ``h = s(p) - (d_i / 2 + l + margin)`` with ``s`` the signed
  distance of ``p`` to the surface and ``n`` its unit normal there:
  ``n . w >= -gamma h``.

Input bounds are hard: ``|v1| <= v1_max`` (``0 <= v1`` with ``reverse: false``),
``|v1 - v1(t_k-1)| <= max_accel h`` and ``|v2| <= v2_max``; where a vehicle has no
``v2_max`` the sideways speed of its look-ahead point ``l |v2|`` is bounded by its
``v1_max`` instead (an automatic ``range`` needs every ``v1_max``; the loader says so).
Each vehicle then solves ``min |w - w_nom|^2`` over those half-planes
(:mod:`sandbox.behaviour.safety.qp`, exact); when they have no common point the barrier
conditions are relaxed by the least slack (counted in ``metrics.json`` as
``safety.infeasible_steps``). ``projection: speed`` keeps the controller's ``v2`` and
changes ``v1`` only.

**The right-hand rule out of stalls** (``pass_right``, an angle [rad], default pi/2):
the filter's own deadlock is a look-ahead point in the corner of two barriers whose
nominal velocity points into the polar cone of that corner, so the nearest safe
velocity is 0 (the exact ring swaps: every vehicle cornered by its two neighbours). A
vehicle whose filtered speed keeps less than half of its nominal speed turns its
nominal velocity to the right, by up to ``pass_right`` as the cut grows (a smoothstep
from half to a tenth kept; in proportion to the nominal speed below 0.2 m/s, so a
vehicle at its slot is never turned) and is filtered again toward that (the barriers
and bounds unchanged, so is safety). The corner of two barriers with unit normals at
``+-a`` from the way out admits exactly the velocities within ``90 deg - a`` of it, so
a nominal pointing straight into the corner is freed only by a turn of more than
``a``; a ring of ``N`` jammed at its centre has ``a = 90 deg - 180 deg / N``, so a
right angle is the least turn that frees every ring. The same rule for every vehicle,
deterministic, breaks a symmetric stall the same way for all, like the rule of the
road (Grover et al.'s right-hand rotation of the nominal command at a CBF deadlock;
Wang, Ames and Egerstedt's perturbation when the filtered velocity collapses).
A stall symmetric under the half turn (a door passed both ways) is broken only by
rounding so; ``priority`` (:mod:`sandbox.behaviour.safety.priority`) orders the
vehicles, and a stalled vehicle outranking every one in range holds its course.

Only vehicles driven by the controller are filtered (not the open-loop ones, not those
believed failed); the filter acts before the step API's command overrides and the
failures (which replace the commands of the vehicles they hit). All of the above
without a ``priority`` is also one C loop over the vehicles of every world
(:mod:`sandbox.behaviour.safety.filter_kernel`), with numpy's numbers.

**Cars** (``model: bicycle``, ``FilterContext.steering``): a car's QP also keeps its
command within what its steering can reach this period, the two hard rows of its
forward or its reverse cone, the better solution kept
(:mod:`sandbox.behaviour.safety.cars`); a car takes no right-hand rule (it cannot
turn where it stands), and no cone with ``projection: speed``. The C loop does not
know the cones: a step with cars is made by it for the unicycles and by numpy for the
cars.

**The braking barrier** (``barrier: braking``; ``velocity``, all of the above, stays
the default). The velocity barrier asks ``h' >= -gamma h`` of a velocity the drive
can change only by ``max_accel dt`` a period, so near a barrier its conditions may
have no common point (the slack). The braking barrier
(:mod:`sandbox.behaviour.safety.braking`) gives every vehicle one braking command,
turn rate 0 and ``v1`` moved ``max_accel dt`` toward 0 each period, and makes the
barrier of a pair the least clearance beyond ``D`` if both brake from now on
(``H``, [m]: the look-ahead points' paths, with the drive's lag of one substep;
toward a vehicle believed failed or driven open loop, its centre along the path of
its last commands, for ever, and ``D'``, with the better of braking and a run at full
speed; toward an obstacle, the signed distance). Each condition asks
a vehicle's command to lose at most its share of what is left, to first order,
against its braking command::

    g . (z - z_b) >= -rho (H_b' - min(H, 0)),   g = dH_b' / dz at z_b,

(``H_b' >= H`` the next state's barrier if it brakes, at each of the two least local
minima of the distance along the brakings), so the braking command keeps every
condition by construction and the QP always has a point within the bounds: no
slack, and ``braking_fallback`` only for rounding. What it guarantees, and under
which assumptions, is in ``docs/concepts/safety.md``: braking keeps a braking-safe
state (every ``H >= 0``) so exactly in the drive's model; the QP's commands keep it
to first order, and :mod:`sandbox.behaviour.safety.braking_check` moves a command
toward braking, or toward the QP's solution with the conditions it fails asking back
twice their shortfall (the nearer), where the model, the others braking, says it
loses more.

Under sensing the braking barrier sees the others through an estimate of their
poses now (:class:`~sandbox.behaviour.estimation.BroadcastEstimate`: each broadcast
copy carried over the delay by the commands, then filtered with the least gain ``K =
estimate_gain``), the same for every vehicle, and grows ``D`` by the sensing margin
``3 sqrt(K) (sigma_p + (l + S) sigma_theta)``
(:func:`~sandbox.model.barriers.sensing_margin`); the velocity barrier keeps the
copies as received.

It needs every vehicle's finite ``max_accel`` and ``v1_max`` (a loader error) and
``neighbour_velocity: broadcast``, ``projection: look_ahead`` (the filter's check);
``gamma`` is not used. The automatic ``range`` is :func:`braking_range`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sandbox.behaviour.safety.accounting import FilterStep, account_step
from sandbox.behaviour.safety.braking import (
    braking_fallback,
    braking_rows,
    columns,
    look_ahead_points,
    obstacle_normals,
    pair_geometry,
)
from sandbox.behaviour.safety.braking_check import Solved, check_commands, passes
from sandbox.behaviour.safety.cars import CarCone, solved_groups, with_cars
from sandbox.behaviour.safety.filter_kernel import covers, usable, velocity_step
from sandbox.behaviour.safety.priority import PRIORITY, holding
from sandbox.behaviour.safety.qp import TOLERANCE, bounded_problems, solve
from sandbox.behaviour.safety.right_hand import pass_right
from sandbox.behaviour.safety.state import CBFState
from sandbox.model.barriers import (
    MIN_DIST,
)
from sandbox.model.dynamics import CLIP
from sandbox.plugins.contexts import FilterContext
from sandbox.plugins.registration import Param, register_filter

PARAMS = {
    "barrier": Param(
        "choice",
        "velocity",
        doc="velocity: h = |p_i - p_j|^2 - D^2 with h' >= -gamma h (assumes the "
        "speed can change at once); braking: the braking-safe barrier H = the least "
        "clearance beyond D if every vehicle brakes at its max_accel from now on, "
        "its conditions kept by the braking command (always feasible); under "
        "sensing it sees the others through an estimate, with a margin for its "
        "error (needs every vehicle's "
        "max_accel and v1_max)",
        choices=("velocity", "braking"),
    ),
    "gamma": Param(
        "number",
        2.0,
        "1/s",
        "Rate of the barrier condition h' >= -gamma h: near a barrier the gap may "
        "close at about gamma times itself (a braking of about gamma v); not used "
        "by barrier: braking",
        minimum=0.0,
        exclusive=True,
    ),
    "margin": Param(
        "length",
        0.05,
        "m",
        "Clearance kept between the surfaces of two vehicles (and to obstacles) "
        "beyond contact",
        minimum=0.0,
    ),
    "look_ahead": Param(
        "length",
        0.1,
        "m",
        "Distance l of the filtered point ahead of the centre; D = d + 2 l + margin",
        minimum=0.0,
        exclusive=True,
    ),
    "projection": Param(
        "choice",
        "look_ahead",
        doc="look_ahead: the nearest safe velocity of the look-ahead point (speed "
        "and turn rate both change, a turn rate costing l^2 as much); speed: keep "
        "the controller's turn rate, change only the speed",
        choices=("look_ahead", "speed"),
    ),
    "neighbour_velocity": Param(
        "choice",
        "broadcast",
        doc="What a vehicle assumes of a filtered neighbour: broadcast: it keeps "
        "the velocity of the last period, and each takes half of the change; zero: "
        "it stands still, and each takes half of the budget",
        choices=("broadcast", "zero"),
    ),
    "reverse": Param(
        "boolean", True, doc="Whether the filter may command a negative speed v1"
    ),
    "pass_right": Param(
        "number",
        1.5708,
        "rad",
        "The right-hand rule out of stalls: a vehicle whose nominal look-ahead "
        "velocity the filter cuts to less than half turns that velocity to its right "
        "by up to this angle, ramped with the cut, and is filtered again (default "
        "pi/2 = 1.5708, the least turn that leaves every corner of two barriers; "
        "0: off)",
        minimum=0.0,
        maximum=1.5708,
    ),
    "priority": PRIORITY,
    "estimate_gain": Param(
        "number",
        None,
        doc="barrier: braking under sensing: the least gain K of the estimate of the "
        "others' poses (each broadcast copy carried over the delay by the commands, "
        "then a filter x <- x + K (copy - x)); the sensing margin is 3 sqrt(K) "
        "(sigma_p + (l + S) sigma_theta). Smaller: less noise, slower to correct "
        "what the commands do not explain; 1: each copy alone (left out: 0.1)",
        minimum=0.0,
        maximum=1.0,
        exclusive=True,
    ),
    "range": Param(
        "length",
        None,
        "m",
        "Neighbours and obstacles beyond this are not constrained (default: the "
        "distance beyond which no barrier can bind at the vehicles' speed limits)",
        minimum=0.0,
        exclusive=True,
    ),
    "max_constraints": Param(
        "integer",
        8,
        doc="Most barrier conditions per vehicle and step (the most restrictive are "
        "kept)",
        minimum=1,
        maximum=16,
    ),
}


def _box(
    state: CBFState, ctx: FilterContext, z2_nom: np.ndarray, rows: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Bounds of ``z = (v1, l v2)``: ``lo1 <= z1 <= hi1``, ``lo2 <= z2 <= hi2``."""
    v1_max, lateral = state.v1_max[rows], state.lateral[rows]
    lo1 = -v1_max if state.reverse else np.zeros(len(rows))
    hi1 = v1_max
    if ctx.v1_prev is not None:
        step = state.accel[rows] * ctx.dt
        prev = ctx.v1_prev[rows]
        lo1 = np.maximum(lo1, prev - step)
        hi1 = np.minimum(hi1, prev + step)
        lo1 = np.minimum(lo1, hi1)
    if state.speed_only:
        lo2 = hi2 = z2_nom[rows]
    else:
        lo2, hi2 = -lateral, lateral
    return lo1, hi1, lo2, hi2


def barrier_rows(
    state: CBFState,
    ctx: FilterContext,
    filtered: np.ndarray,
    reach: np.ndarray | None = None,
    found: dict[str, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every barrier condition of the step as a half-plane ``a . w <= b``.

    Parameters
    ----------
    state : CBFState
    ctx : FilterContext
    filtered : ndarray, shape (n,), bool
        Vehicles the filter drives (the others are only obstacles to them).
    reach : ndarray, shape (n,) [m/s], optional
        The largest change of each vehicle's look-ahead velocity from the last
        period's within its bounds; conditions no such change can violate may be
        left out (default: all are made).
    found : dict, optional
        Receives ``min_barrier``, the least ``h`` [m^2] (and [m] toward obstacles)
        of the conditions made or pruned.

    Returns
    -------
    vehicle : ndarray, shape (r,) int
        The vehicle each condition belongs to.
    a : ndarray, shape (r, 2)
        Unit normal in the look-ahead velocity ``w`` [1].
    b : ndarray, shape (r,) [m/s]
        Offset.
    """
    gamma, look, margin = state.gamma, state.look, state.margin
    pos, d = ctx.pos, ctx.diameter
    heading, p, centre_seen, p_seen = look_ahead_points(ctx, look)
    cooperative = filtered
    if reach is None:
        reach = np.full(len(pos), np.inf)
    out_v, out_a, out_b = [], [], []
    least = np.inf
    # Each vehicle's least barrier value, for the worlds of a batched call.
    by = None if found is None else found.get("by_vehicle")

    if ctx.v1_prev is not None:
        w_hat = heading * ctx.v1_prev[:, None]
        w_hat += look * ctx.v2_prev[:, None] * heading[:, ::-1] * [-1.0, 1.0]
    else:
        w_hat = None
    i, j, rel = state.neighbours.near(p_seen)
    if len(i) and ctx.seen is None:
        # Without sensing both rows of a pair see the same geometry. A condition
        # a . w <= b can bind only if b - a . w^ < |w - w^| for some w within the
        # bounds (w^: the last period's velocity), so pairs of cooperating vehicles
        # whose slack at w^ is at least both vehicles' largest change `reach` are
        # dropped here, before their rows are made: exact, and cheap.
        dist = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), MIN_DIST)
        big_d = 0.5 * (d[i] + d[j]) + 2.0 * look + margin
        h = dist * dist - big_d * big_d
        pair = cooperative[i] | cooperative[j]
        if pair.any():
            least = min(least, float(h[pair].min()))
            if by is not None:
                np.minimum.at(by, i[pair], h[pair])
        base = 0.25 * gamma * h / dist
        if w_hat is None:
            slack_i = slack_j = base
        else:
            wi, wj = np.take(w_hat, i, axis=0), np.take(w_hat, j, axis=0)
            unit = rel / dist[:, None]
            along_i = unit[:, 0] * wi[:, 0] + unit[:, 1] * wi[:, 1]
            along_j = unit[:, 0] * wj[:, 0] + unit[:, 1] * wj[:, 1]
            if state.broadcast:  # the same for both: a quarter budget less closing
                slack_i = slack_j = base + 0.5 * (along_i - along_j)
            else:
                slack_i, slack_j = base + along_i, base - along_j
        keep = (slack_i < reach[i]) | (slack_j < reach[j])
        keep = (keep | ~(cooperative[i] & cooperative[j])).nonzero()[0]
        i, j = i.take(keep), j.take(keep)
    if len(i):
        # Both directions of each pair: vehicle `me` toward `other`.
        me, other, coop, rel, dist, big_d = pair_geometry(
            i, j, filtered, p, p_seen, centre_seen, d, look, margin
        )
        h = dist * dist - big_d * big_d
        if len(h):
            least = min(least, float(h.min()))
            if by is not None:
                np.minimum.at(by, me, h)
        if w_hat is not None and state.broadcast:
            shared = w_hat[me] + w_hat[other]
            share = np.einsum("kd,kd->k", rel, shared)
        else:
            share = np.zeros(len(me))
        moving = np.einsum("kd,kd->k", rel, ctx.vel[other])
        # 2 rel . w >= rhs
        rhs = np.where(coop, -0.5 * gamma * h + share, -gamma * h + 2.0 * moving)
        out_v.append(me)
        out_a.append(-rel / dist[:, None])
        out_b.append(-rhs / (2.0 * dist))

    near = obstacle_normals(state, ctx, p, filtered)
    if near is not None:
        rows, signed, away = near
        clearance = 0.5 * d[rows] + look + margin
        least = min(least, float(np.min(signed - clearance)))
        if by is not None:
            np.minimum.at(by, rows, signed - clearance)
        out_v.append(rows)
        out_a.append(-away)
        out_b.append(gamma * (signed - clearance))
    if found is not None:
        found["min_barrier"] = least
    if not out_v:
        empty = np.zeros(0, dtype=np.intp)
        return empty, np.zeros((0, 2)), np.zeros(0)
    return np.concatenate(out_v), np.concatenate(out_a), np.concatenate(out_b)


def filter_commands(
    state: CBFState,
    ctx: FilterContext,
    prune: bool = True,
    braked: np.ndarray | None = None,
    only: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, FilterStep]:
    """The filtered ``(v1, v2)`` of one step, and what the filter did.

    Under sensing with the braking barrier the step first takes the period's copies
    into the estimate (``state.estimate``), and the rest of the step sees the
    estimate in place of ``ctx.seen``: call it once a period. The velocity barrier
    without a priority runs as one C call where that is built and agrees
    (:func:`~sandbox.behaviour.safety.filter_kernel.velocity_step`, the same
    numbers); the numpy below is its definition.

    Parameters
    ----------
    state : CBFState
    ctx : FilterContext
    prune : bool
        Whether pairs that cannot bind are dropped before their conditions are made
        (the result is the same; False is for checking that).
    braked : ndarray, shape (n,), bool, optional
        Under the braking barrier, vehicles that may not take the run toward
        vehicles that do not brake (the second try of the step: ``ctx`` then
        holds the estimate already).
    only : ndarray, shape (n,), bool, optional
        Solve these vehicles' problems only (the others keep ``ctx``'s commands):
        the cars, after the compiled step (:func:`~sandbox.behaviour.safety.cars.
        with_cars`).

    Returns
    -------
    v1 : ndarray, shape (n,) [m/s]
    v2 : ndarray, shape (n,) [rad/s]
    step : FilterStep
    """
    if prune and braked is None and only is None and covers(state) and usable():
        fast = velocity_step(state, ctx)  # the same step in one C call
        car = None if ctx.steering is None else np.isfinite(ctx.steering.wheelbase)
        if car is None or not car.any():
            return fast
        return with_cars(car, fast, filter_commands(state, ctx, prune, only=car))
    n, look = len(ctx.pos), state.look
    if braked is None and state.estimate is not None and ctx.seen is not None:
        seen = state.estimate.update(ctx.seen, ctx.v1_prev, ctx.v2_prev)
        ctx = replace(ctx, seen=seen)
    filtered = np.ones(n, dtype=bool)
    if ctx.known_failed is not None:
        filtered &= ~ctx.known_failed
    if ctx.commanded is not None:
        filtered &= ~ctx.commanded
    v1 = np.array(ctx.v1, dtype=float)
    v2 = np.array(ctx.v2, dtype=float)
    z0 = columns(v1, look * v2)
    slack = np.zeros(n)
    active = np.zeros(n, dtype=bool)
    who = (filtered if only is None else filtered & only).nonzero()[0]
    if len(who) == 0:
        return v1, v2, FilterStep(active, slack, 0, np.inf, np.zeros(n, dtype=bool))
    lo1, hi1, lo2, hi2 = (np.zeros(n) for _ in range(4))
    lo1[who], hi1[who], lo2[who], hi2[who] = _box(state, ctx, z0[:, 1], who)
    # The cars' reachable set, two hard rows each (cars.py); None without a car.
    cone = CarCone.of(ctx, look, state.speed_only, (lo1, hi1, lo2, hi2), who)
    if cone is not None:  # a car's nominal: the command its steering executes
        z0 = columns(v1, look * cone.nominal(v1, v2))
    if ctx.v1_prev is None:
        z_hat = np.zeros((n, 2))
    else:
        z_hat = columns(ctx.v1_prev, look * ctx.v2_prev)
    reach = np.hypot(
        np.maximum(np.abs(lo1 - z_hat[:, 0]), np.abs(hi1 - z_hat[:, 0])),
        np.maximum(np.abs(lo2 - z_hat[:, 1]), np.abs(hi2 - z_hat[:, 1])),
    )
    reach = reach * (1.0 + 1e-9) + 1e-9 if prune else None
    fallback = np.zeros(n, dtype=bool)
    by_vehicle = np.full(n, np.inf)  # each vehicle's least h, for its world's
    hold = walls = None  # the priority's holders, and their obstacles' row count
    if state.priority != "none":
        hold, walls = holding(state, ctx, filtered)
    pending: dict = {}  # the braking barrier's check of the commands
    if state.braking:
        veh, a_w, b, h = braking_rows(state, ctx, filtered, pending, braked)
        least = float(h.min()) if len(h) else np.inf
        np.minimum.at(by_vehicle, veh, h)
    else:
        found: dict[str, object] = {"by_vehicle": by_vehicle}
        veh, a_w, b = barrier_rows(state, ctx, filtered, reach, found)
        least = found.get("min_barrier", np.inf)
    if "walls" in pending:  # the braking barrier's obstacle rows (two a pair at most)
        walls = pending["walls"] if walls is not None else None
    wall = np.arange(len(veh)) >= len(veh) - (walls or 0)  # rows of obstacles last
    # In z = (v1, l v2): w = R(x3) z, so a . w = (R^T a) . z and |w - w0| = |z - z0|.
    c, s = np.cos(ctx.theta[veh]), np.sin(ctx.theta[veh])
    a = columns(c * a_w[:, 0] + s * a_w[:, 1], -s * a_w[:, 0] + c * a_w[:, 1])
    # Conditions no input within the bounds can violate are dropped.
    reach = np.maximum(a[:, 0] * lo1[veh], a[:, 0] * hi1[veh]) + np.maximum(
        a[:, 1] * lo2[veh], a[:, 1] * hi2[veh]
    )
    keep = (reach > b - TOLERANCE).nonzero()[0]
    veh, a, b, wall, src = veh[keep], a[keep], b[keep], wall[keep], keep
    # At most max_rows per vehicle, the most restrictive (smallest b) first.
    order = np.lexsort((b, veh))
    veh, a, b, wall, src = veh[order], a[order], b[order], wall[order], src[order]
    counts = np.bincount(veh, minlength=n)
    start = np.concatenate(([0], np.cumsum(counts)[:-1]))
    rank = np.arange(len(veh)) - start[veh]
    keep = (rank < state.max_rows).nonzero()[0]
    veh, a, b, rank, wall = veh[keep], a[keep], b[keep], rank[keep], wall[keep]
    src = src[keep]  # each kept row's place among the rows as made
    counts = np.minimum(counts, state.max_rows)

    z = z0.copy()
    bare = who[counts[who] == 0]  # the bounds only: a clip
    if cone is not None:  # a car's: its cone too
        bare = bare[~cone.car[bare]]
    z[bare, 0] = CLIP(z0[bare, 0], lo1[bare], hi1[bare])
    z[bare, 1] = CLIP(z0[bare, 1], lo2[bare], hi2[bare])
    for m, group in solved_groups(who, counts, cone):  # the counts, sorted
        k = len(group)
        slot = np.full(n, -1, dtype=np.intp)
        slot[group] = np.arange(k)
        mine = (slot[veh] >= 0).nonzero()[0]
        box = (lo1[group], hi1[group], lo2[group], hi2[group])
        mat, off, soft = bounded_problems(
            box, slot[veh[mine]], a[mine], b[mine], rank[mine], m
        )
        if cone is None:
            zg, sg = solve(z0[group], mat, off, soft)
        else:  # a car's better cone (cars.py); unicycles as they are
            zg, sg, (mat, off, soft) = cone.solve(group, z0[group], (mat, off, soft))
        # the right-hand rule turns where a vehicle stands: not a car's (cars.py)
        car = cone is not None and bool(cone.car[group[0]])
        if state.pass_right > 0 and not state.speed_only and not car:
            held = None if hold is None else (hold[group], np.zeros(off.shape, bool))
            if held is not None:
                held[1][slot[veh[mine]], 4 + rank[mine]] = wall[mine]
            zg, sg = pass_right(state, z0[group], zg, sg, mat, off, soft, held)
        z[group], slack[group] = zg, sg
        if state.braking:  # no command keeps every condition: brake
            fallback[group[sg > TOLERANCE]] = True
    running = pending.get("run")  # the vehicles whose backup is the run
    braked = np.zeros(n, dtype=bool) if braked is None else braked
    if running is not None and (running & fallback).any():  # try again, braking
        return filter_commands(state, ctx, prune, braked | (running & fallback))
    if "check" in pending:  # beyond first order, against the others braking
        z_b = braking_fallback(state, ctx, np.arange(n))
        if running is not None:  # the run's command, which keeps its conditions
            z_b[running, 0] = pending["check"].run["runs"].first[running]
            z_b[running, 1] = 0.0
        solved = Solved(veh, a, b, rank, pending["cond"][src], pending["norm"][src])
        box = (lo1, hi1, lo2, hi2)
        z, _ = check_commands(state, ctx, pending["check"], z, z_b, solved, box, cone)
        if running is not None:
            bad = running & ~passes(state, ctx, pending["check"], z)
            if bad.any():
                return filter_commands(state, ctx, prune, braked | bad)
    braking = fallback.nonzero()[0]
    if len(braking):
        z[braking] = braking_fallback(state, ctx, braking)
    changed = np.any(z != z0, axis=1)
    rows = changed.nonzero()[0]
    v1[rows] = z[rows, 0]
    if not state.speed_only:  # else v2 is the controller's, exactly
        v2[rows] = z[rows, 1] / look
    if len(braking):  # v2 of the braking command, whatever the projection
        v2[braking] = z[braking, 1] / look
    active[rows] = True
    return v1, v2, FilterStep(active, slack, len(veh), least, fallback, by_vehicle)


def _check(values: dict, section: dict) -> list[tuple]:
    """Cross-key checks of the section: what ``barrier: braking`` works with."""
    if values.get("barrier") != "braking":
        return []
    out = []
    if values.get("neighbour_velocity") == "zero":
        out.append(
            (
                "neighbour_velocity",
                "barrier: braking shares the change from the broadcast velocities",
                "zero with barrier: braking",
                "broadcast, or barrier: velocity",
            )
        )
    if values.get("projection") == "speed":
        out.append(
            (
                "projection",
                "barrier: braking needs the turn rate free to be feasible from every "
                "safe state",
                "speed with barrier: braking",
                "look_ahead, or barrier: velocity",
            )
        )
    return out


@register_filter("cbf", params=PARAMS, check=_check, batched=True)
def cbf(ctx: FilterContext) -> tuple[np.ndarray, np.ndarray]:
    """Control-barrier-function filter through the look-ahead point.

    Its pieces are the modules of ``sandbox/behaviour/safety/``.
    """
    state = ctx.memory.get("cbf")
    if state is None:
        state = ctx.memory["cbf"] = CBFState(ctx)
    v1, v2, step = filter_commands(state, ctx)
    account_step(ctx, step, state.braking)
    return v1, v2
