"""Collision-avoidance (recovery) strategies of section 4, selected by name.

Every strategy shifts each avoiding vehicle's target away from the obstacles within its
safe zone, eqs. (22)/(26):

    x_ref = slot + beta * sum_i alpha_i * vect_avoid_i,   vect_avoid_i = u_i / dist_i

with ``u_i`` the unit vector from obstacle i to the vehicle (eq. (24)) and ``dist_i``
the distance (eq. (25)). Strategies differ only in the weight ``alpha(dist)``:

- ``none``: 0;
- ``discontinuous`` (4.1): 1 inside R, 0 outside (a switch);
- ``continuous`` (4.2, eq. (27)): 1 inside r, a linear ramp from 1 to 0 between r and R;
- ``smooth`` (the conclusion's proposal): a hyperbolic-tangent transition between r and
  R, scaled to equal exactly 1 at r and 0 at R. It is continuous, not differentiable, at
  r and R: its slope there is ``s (1 - tanh(s)^2) / tanh(s)`` times the ramp's (0.15 for
  the default steepness s = 2), so the mode changes more gently than with the ramp.

Beyond the report, the weighted strategies take a tangential term (``recovery.
tangential``, the weight ``kappa >= 0``; 0, the default, is the report's field):

    shift = beta * sum_i alpha_i (u_i + kappa * s_i * J u_i) / dist_i

with ``J`` the +90 degree rotation and ``s_i = max(0, -g . u_i)``, ``g`` the unit
direction from the vehicle to its slot: 1 for an obstacle straight between the vehicle
and its slot, 0 once it is abeam or behind. Two vehicles meeting head-on both veer to
their right and pass (the rule of the road), where the radial field alone has a
symmetric equilibrium in which both stall. For walls, boxes and polygons ``u_i`` is
the normal from the nearest surface point, and of the two tangents along the surface
the one nearer ``g`` is taken (:func:`tangential_terms`).

Derivatives fed to eq. (6) with the shifted target (``recovery.target_derivatives``):

- ``hold`` (section 4.1): the law's own ``x_ref'``, ``x_ref''``, unchanged ("with all
  the other derivatives being unchanged"); only the position term sees the shift;
- ``estimate`` (the conclusion's second proposal): the backward-Euler estimates
  (eqs. (8)-(9)) of the shift's first and second derivatives are added to the law's.
  The differences are linear, so for a law that estimates its slot's motion
  (``own_estimate``, eqs. (18)-(19)) this is exactly the estimate of the shifted target
  ``slot + shift`` itself; for ``fixed`` (a constant offset) and unrotated ``virtual``
  it differs only in using the exact instead of the estimated motion of the slot; for
  ``rotating``, ``leader_ref`` and rotated ``virtual`` it keeps those laws' own
  approximation (the leader's or the reference's derivatives for every slot, eq. (12))
  and adds what recovery changes.

  Two caveats. A switch (``discontinuous``) makes the shift jump, so its estimated
  derivatives are impulses (a 0.67 m jump reads as 67 m/s, then +-6700 m/s^2). And the
  shift depends on the vehicle's own position x: its estimated acceleration feeds the
  vehicle's own acceleration back, one and two periods late, with the gain
  ``J = d shift / d x`` (``beta / dist^2`` for the switch, more with the slope of the
  ramp or of the tanh). To leading order in h the loop's extra poles are the roots of
  ``z^2 = J``: for ``|J| > 1`` it oscillates at the control rate, growing until the
  limits bound it, and v2 chatters between its limits when the vehicle is slow.

Obstacles are the other vehicles (centre-to-centre distance) and the static obstacles
(distance from the vehicle centre to the nearest surface point, pushing away from it).
Numpy, with the vehicles' pair terms of the discontinuous and continuous weights in one
C call where the compiled path ``pair_field`` is on
(:mod:`sandbox.behaviour.pair_field`, within rtol 1e-12); neighbours come from a KD-tree
(scipy) above a few dozen vehicles, kept between control steps as a Verlet list
(:class:`NeighbourList`), so the cost per step stays about linear in the number of
vehicles.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from sandbox.behaviour import pair_field
from sandbox.geometry.neighbours import NeighbourList, neighbour_pairs
from sandbox.model.dynamics import CLIP
from sandbox.model.obstacle_field import MIN_DIST, ObstacleField
from sandbox.plugins.registration import (
    Param,
    StrategyContext,
    get,
    register_strategy,
    runnable,
)

__all__ = [
    "WEIGHTS",
    "avoidance_shift",
    "slot_directions",
    "tangential_terms",
    "weighted_shift",
]

#: A weight ``alpha(dist, R, r, steepness)`` of the built-in strategies, eq. (22).
Weight = Callable[[np.ndarray, float, float | None, float], np.ndarray]
#: The weights of the built-in strategies by name.
WEIGHTS: dict[str, Weight] = {}

#: The parameters of the built-in strategies.
BETA = Param(
    "number",
    1.0,
    unit="m^2",
    doc="Weight of the avoidance vectors, eq. (22)",
    minimum=0.0,
)
SMALL_R = Param(
    "length",
    None,
    unit="m",
    doc="Inner radius, < R (default: R / 2)",
    minimum=0.0,
    exclusive=True,
)
STEEPNESS = Param(
    "number",
    2.0,
    doc="Steepness s of the tanh transition",
    minimum=0.0,
    exclusive=True,
)
TANGENTIAL = Param(
    "number",
    0.0,
    doc="Weight kappa of the tangential term (0: the report's field)",
    minimum=0.0,
)


def _inner_radius(values: dict[str, Any], section: dict[str, Any]) -> list[tuple]:
    """Default ``r = R / 2``; ``r < R`` (the ramp runs from R in to r)."""
    big_r = section.get("R")
    if big_r is None:
        return []
    if values.get("r") is None:
        values["r"] = big_r / 2.0
        return []
    if values["r"] >= big_r:
        return [
            (
                "r",
                "r must be smaller than R",
                f"r = {values['r']:g} m, R = {big_r:g} m",
                "r < R: avoidance ramps up between R and r, eqs. (26)-(27)",
            )
        ]
    return []


def _weighted(name: str, weight: Weight) -> Callable[[StrategyContext], Any]:
    """The strategy of eqs. (22)-(27) with the weight ``alpha`` of ``name``."""
    WEIGHTS[name] = weight

    def strategy(ctx: StrategyContext) -> tuple[np.ndarray, np.ndarray]:
        p = ctx.params
        return weighted_shift(
            ctx,
            weight,
            p["beta"],
            p.get("r"),
            p.get("steepness", 2.0),
            p.get("tangential", 0.0),
        )

    strategy.__doc__ = weight.__doc__
    strategy.__name__ = strategy.__qualname__ = name
    strategy.__module__ = weight.__module__
    return strategy


def no_avoidance(
    dist: np.ndarray, R: float, r: float | None, steepness: float
) -> np.ndarray:
    """No recovery: alpha = 0."""
    return np.zeros_like(dist)


def discontinuous(
    dist: np.ndarray, R: float, r: float | None, steepness: float
) -> np.ndarray:
    """Section 4.1: alpha = 1 within the safe zone R, else 0 (eq. (22))."""
    return (dist < R).astype(float)


def continuous(
    dist: np.ndarray, R: float, r: float | None, steepness: float
) -> np.ndarray:
    """Section 4.2, eq. (27): 1 below r, ``1 - (dist - r)/(R - r)``, 0 above R."""
    return CLIP(1.0 - (dist - r) / (R - r), 0.0, 1.0)  # eq. (27)


def smooth(dist: np.ndarray, R: float, r: float | None, steepness: float) -> np.ndarray:
    """Conclusion: a tanh transition centred between r and R, 1 at r and 0 at R.

    ``alpha = (tanh(s (c - dist) / w) + tanh(s)) / (2 tanh(s))`` with ``c = (R + r)/2``,
    ``w = (R - r)/2`` and ``s`` the steepness; clipped to [0, 1] outside [r, R].
    """
    c, w = 0.5 * (R + r), 0.5 * (R - r)
    t = np.tanh(steepness)
    return CLIP((np.tanh(steepness * (c - dist) / w) + t) / (2.0 * t), 0.0, 1.0)


#: The weights whose pair terms :mod:`sandbox.behaviour.pair_field` computes in C.
_C_KINDS: dict[Callable[..., np.ndarray], int] = {
    discontinuous: pair_field.DISCONTINUOUS,
    continuous: pair_field.CONTINUOUS,
}


@register_strategy("none", batched=True)
def no_recovery(ctx: StrategyContext) -> tuple[np.ndarray, np.ndarray]:
    """No recovery: targets are never shifted."""
    return np.zeros((ctx.n, 2)), np.zeros(ctx.n, dtype=bool)


WEIGHTS["none"] = no_avoidance
register_strategy(
    "discontinuous", {"beta": BETA, "tangential": TANGENTIAL}, batched=True
)(_weighted("discontinuous", discontinuous))
register_strategy(
    "continuous",
    {"beta": BETA, "r": SMALL_R, "tangential": TANGENTIAL},
    batched=True,
    check=_inner_radius,
)(_weighted("continuous", continuous))
register_strategy(
    "smooth",
    {"beta": BETA, "r": SMALL_R, "steepness": STEEPNESS, "tangential": TANGENTIAL},
    batched=True,
    check=_inner_radius,
)(_weighted("smooth", smooth))


def avoidance_shift(
    pos: np.ndarray,
    avoiders: np.ndarray,
    strategy: str,
    beta: float,
    R: float,
    r: float | None,
    steepness: float,
    obstacles: ObstacleField,
    neighbours: NeighbourList | None = None,
    slot: np.ndarray | None = None,
    tangential: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The shift ``beta * sum_i alpha_i vect_avoid_i`` of a built-in strategy.

    Implements eqs. (22)-(27) for all vehicles at once: the registered strategy
    ``strategy`` called with a :class:`~sandbox.plugins.StrategyContext` of these
    positions (the simulation builds the full context).

    Parameters
    ----------
    pos : ndarray, shape (n, 2) [m]
        Vehicle positions.
    avoiders : ndarray, shape (n,), bool
        Vehicles that apply the strategy (others get a zero shift, but are still
        obstacles for the rest).
    strategy : str
        A registered strategy of :data:`WEIGHTS` (``none``, ``discontinuous``, ...).
    beta : float
        Aggressiveness of the avoidance [m^2].
    R, r : float [m]
        Safe-zone radius and (continuous/smooth) inner radius.
    steepness : float
        Steepness of the ``smooth`` transition.
    obstacles : ObstacleField
    neighbours : NeighbourList, optional
        Reused between calls (with radius ``R``) to find the vehicle pairs; default: a
        fresh search with :func:`neighbour_pairs`.
    slot : ndarray, shape (n, 2) [m], optional
        Each vehicle's slot (default: none, NaN), for the tangential term.
    tangential : float
        The tangential weight ``kappa`` (``recovery.tangential``), >= 0.

    Returns
    -------
    shift : ndarray, shape (n, 2) [m]
    active : ndarray, shape (n,), bool
        Vehicles with at least one obstacle weighted above zero (mode ``avoid``).
    """
    n = len(pos)
    ctx = StrategyContext(
        t=0.0,
        dt=0.0,
        pos=pos,
        theta=np.zeros(n),
        vel=np.zeros((n, 2)),
        slot=np.full((n, 2), np.nan) if slot is None else np.asarray(slot, float),
        diameter=np.zeros(n),
        may_avoid=avoiders,
        failed=np.zeros(n, dtype=bool),
        params={"beta": beta, "r": r, "steepness": steepness, "tangential": tangential},
        R=R,
        obstacle_field=obstacles,
        neighbours=neighbours,
    )
    return runnable(get("strategy", strategy))(ctx)


def weighted_shift(
    ctx: StrategyContext,
    weight: Weight,
    beta: float,
    r: float | None,
    steepness: float,
    kappa: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Eqs. (22)-(27): ``beta * sum_i alpha(dist_i) u_i / dist_i`` for each vehicle.

    The obstacles are the other vehicles within ``ctx.R`` and the static obstacles;
    ``weight`` is ``alpha(dist, R, r, steepness)``, zero beyond ``R``. With the
    tangential weight ``kappa > 0`` each term becomes ``alpha_i (u_i + kappa s_i t_i)
    / dist_i`` (:func:`tangential_terms`); ``kappa = 0`` computes exactly the
    report's field.
    """
    pos, avoiders, R = ctx.pos, ctx.may_avoid, ctx.R
    obstacles, neighbours = ctx.obstacle_field, ctx.neighbours
    n = len(pos)
    shift = np.zeros((n, 2))
    active = np.zeros(n, dtype=bool)
    if not np.count_nonzero(avoiders):
        return shift, active
    goal = slot_directions(pos, ctx.slot) if kappa > 0 else None
    kind = _C_KINDS.get(weight) if goal is None and neighbours is not None else None
    if kind is not None and pair_field.usable():
        # The pairs' terms in one C call (the numpy below, within rtol 1e-12), and
        # without static obstacles, for one beta of all rows, the field finished too.
        one_beta = not isinstance(beta, np.ndarray) or beta.ndim == 0
        if obstacles.empty and one_beta:
            pair_field.add_pair_terms(
                pos, ctx.seen_pos, neighbours, R, r, kind, shift, active, beta,
                avoiders,
            )  # fmt: skip
            return shift, active
        pair_field.add_pair_terms(
            pos, ctx.seen_pos, neighbours, R, r, kind, shift, active
        )
    else:
        _pair_terms(ctx, weight, r, steepness, kappa, goal, shift, active)
    if not obstacles.empty and neighbours is not None:
        # Only the obstacles near each vehicle (alpha is 0 beyond R for every strategy);
        # the same terms as below, summed over the candidate pairs.
        rows, cols = neighbours.obstacle_pairs(pos, obstacles)
        signed, point = obstacles.pair_distance(pos, rows, cols)
        dist = np.maximum(np.abs(signed), MIN_DIST)  # eq. (25)
        alpha = weight(np.maximum(signed, MIN_DIST), R, r, steepness)
        outward = np.where(signed < 0, -1.0, 1.0)[:, None]
        rel = (np.take(pos, rows, axis=0) - point) * outward
        dd = dist * dist
        if goal is not None:
            u = rel / dist[:, None]
            t = tangential_terms(u, goal[rows], kappa, obstacles.kind[cols] > 0)
            rel = rel + t * dist[:, None]
        for axis in (0, 1):  # eqs. (23)-(24)
            c = alpha * (rel[:, axis] / dd)
            shift[:, axis] += np.bincount(rows, c, minlength=n)
        active[rows[alpha > 0]] = True
    elif not obstacles.empty:
        signed, point = obstacles.nearest(pos)
        # A centre inside an obstacle (negative distance; possible only at the start) is
        # pushed out of it with full weight: u_i points from the surface point outward.
        dist = np.maximum(np.abs(signed), MIN_DIST)  # eq. (25)
        alpha = weight(np.maximum(signed, MIN_DIST), R, r, steepness)
        rel = (pos[:, None, :] - point) * np.where(signed < 0, -1.0, 1.0)[..., None]
        if goal is not None:
            m = signed.shape[1]
            u = (rel / dist[..., None]).reshape(-1, 2)
            g = np.repeat(goal, m, axis=0)
            flat = np.tile(obstacles.kind > 0, len(pos))
            t = tangential_terms(u, g, kappa, flat).reshape(rel.shape)
            rel = rel + t * dist[..., None]
        vect = rel / (dist * dist)[..., None]  # eqs. (23)-(24)
        shift += np.sum(alpha[..., None] * vect, axis=1)
        active |= np.any(alpha > 0, axis=1)
    shift *= beta  # eq. (22) / (26)
    shift[~avoiders] = 0.0
    active &= avoiders
    return shift, active


def _pair_terms(
    ctx: StrategyContext,
    weight: Weight,
    r: float | None,
    steepness: float,
    kappa: float,
    goal: np.ndarray | None,
    shift: np.ndarray,
    active: np.ndarray,
) -> None:
    """The vehicles' terms of :func:`weighted_shift`, into ``shift`` and ``active``.

    The definition (numpy) of what :func:`~sandbox.behaviour.pair_field.add_pair_terms`
    computes in C for the discontinuous and continuous weights without ``kappa``.
    """
    pos, R, neighbours, n = ctx.pos, ctx.R, ctx.neighbours, len(ctx.pos)
    if neighbours is not None:
        i, j, rel = neighbours.near(pos)  # rel: from j to i
    else:
        i, j = neighbour_pairs(pos, R)
        rel = pos[i] - pos[j]  # from j to i
    if len(i):
        dist2 = rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]
        dist = np.maximum(np.sqrt(dist2), MIN_DIST)  # eq. (25)
        alpha = weight(dist, R, r, steepness)
        dd = dist * dist
        on = alpha > 0
        # Sum over the pairs, +alpha u/dist on i and -alpha u/dist on j (eqs. (23)-
        # (24)), in pair order: the same sums as np.add.at, several times faster.
        both = np.concatenate((i, j))
        seen = ctx.seen_pos
        if seen is None and goal is None:
            for axis in (0, 1):
                c = alpha * (rel[:, axis] / dd)
                shift[:, axis] = np.bincount(both, np.concatenate((c, -c)), minlength=n)
            active[i[on]] = True
            active[j[on]] = True
        elif goal is None:
            # Each vehicle sees itself exactly and the other's broadcast position: i
            # reads pos[i] - seen[j], j reads seen[i] - pos[j] (the pairs are those
            # of the true positions).
            rel_i = pos[i] - seen[j]
            rel_j = seen[i] - pos[j]
            terms = []
            for r_ in (rel_i, rel_j):
                d2 = r_[:, 0] * r_[:, 0] + r_[:, 1] * r_[:, 1]
                d = np.maximum(np.sqrt(d2), MIN_DIST)  # eq. (25)
                terms.append((weight(d, R, r, steepness), r_, d * d))
            for axis in (0, 1):
                (a_i, r_i, dd_i), (a_j, r_j, dd_j) = terms
                c = np.concatenate(
                    (a_i * r_i[:, axis] / dd_i, -a_j * r_j[:, axis] / dd_j)
                )
                shift[:, axis] = np.bincount(both, c, minlength=n)
            active[i[terms[0][0] > 0]] = True
            active[j[terms[1][0] > 0]] = True
        else:
            # With the tangential term: each side's vector from its obstacle, u, and
            # the term kappa s J u, over the true or the broadcast positions.
            if seen is None:
                rel_i, rel_j = rel, rel
            else:
                rel_i, rel_j = pos[i] - seen[j], seen[i] - pos[j]
            sides = []
            for v, g in ((rel_i, goal[i]), (-rel_j, goal[j])):
                d = np.maximum(np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]), MIN_DIST)
                u = v / d[:, None]
                vect = (u + tangential_terms(u, g, kappa)) / d[:, None]
                sides.append((weight(d, R, r, steepness), vect))
            (a_i, c_i), (a_j, c_j) = sides
            for axis in (0, 1):
                c = np.concatenate((a_i * c_i[:, axis], a_j * c_j[:, axis]))
                shift[:, axis] = np.bincount(both, c, minlength=n)
            active[i[a_i > 0]] = True
            active[j[a_j > 0]] = True


def slot_directions(pos: np.ndarray, slot: np.ndarray) -> np.ndarray:
    """Unit direction ``g`` from each vehicle to its slot, (n, 2); 0 when undefined.

    Zero for a vehicle on its slot (closer than :data:`MIN_DIST`) or without one (a
    NaN slot: open loop), so that its tangential term vanishes.
    """
    rel = np.asarray(slot, dtype=float) - pos
    norm = np.hypot(rel[:, 0], rel[:, 1])
    ok = np.isfinite(norm) & (norm > MIN_DIST)
    out = np.zeros_like(pos, dtype=float)
    out[ok] = rel[ok] / norm[ok, None]
    return out


def tangential_terms(
    u: np.ndarray,
    goal: np.ndarray,
    kappa: float,
    surface: np.ndarray | None = None,
) -> np.ndarray:
    """The tangential terms ``kappa s_i t_i`` of the avoidance vectors, (m, 2).

    ``s_i = max(0, -g . u_i)`` is 1 when obstacle i lies straight between the vehicle
    and its slot and 0 once it is abeam or behind; ``t_i = J u_i`` with ``J`` the +90
    degree rotation, so that two vehicles meeting head-on both pass on the same hand
    (each turns to its right). For an extended obstacle (``surface`` true: walls,
    boxes, polygons) ``u_i`` is the normal from its nearest point and ``J u_i`` runs
    along the surface; the sign of the tangent is chosen whose dot product with ``g``
    is the larger (the tangent nearest the slot direction; ``+J u_i`` on a tie).

    Parameters
    ----------
    u : ndarray, shape (m, 2)
        Unit vectors from the obstacles to the vehicles.
    goal : ndarray, shape (m, 2)
        Unit direction from each vehicle to its slot (0 when undefined).
    kappa : float
        Tangential weight, >= 0.
    surface : ndarray of bool, shape (m,), optional
        Terms of extended obstacles (default: none).
    """
    s = np.maximum(0.0, -(goal[:, 0] * u[:, 0] + goal[:, 1] * u[:, 1]))
    t = np.column_stack((-u[:, 1], u[:, 0]))  # J u
    if surface is not None:
        along = goal[:, 0] * t[:, 0] + goal[:, 1] * t[:, 1]
        t = np.where((surface & (along < 0))[:, None], -t, t)
    return (kappa * s)[:, None] * t
