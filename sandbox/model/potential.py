"""The virtual-leader potential approach of the report's reference [2] (``potential``).

The report's introduction describes [2]: each vehicle is attracted to its goal, "a
circle around a virtual leader", and repelled by obstacles and the other vehicles;
"by adding these virtual forces, the desired direction the vehicle should head in is
computed", the potential descent enforced at all times (where the report's section 4
switches it on within R only). As a velocity field (the classic artificial-potential
navigation, Khatib 1986; with a virtual leader, Leonard and Fiorelli 2001), each
vehicle's desired velocity is::

    v_i = sat_vmax( x_ref' + F_att,i + F_veh,i + F_obs,i )              (P1)
    F_att,i = -k_att (q_i - g_i)                                        (P2)
    F_veh,i = sum_j  k_rep (1 / rho_ij - 1 / (R - d_c)) (q_i - x_j) / |q_i - x_j|,
              rho_ij = |q_i - x_j| - d_c,   for |q_i - x_j| < R          (P3)
    F_obs,i = sum_o  k_rep (1 / rho_io - 1 / (R - d_c / 2)) (q_i - o) / |q_i - o|,
              rho_io = |q_i - o| - d_c / 2,  for |q_i - o| < R           (P4)

with ``g_i = x_ref + Delta_i`` the vehicle's place on the virtual leader's formation
(eqs. (13)-(15) of the report), ``x_j`` the other vehicles where they are, ``o`` the
obstacle points the vehicle's range sensor sees (:func:`~sandbox.model.moving_target.
sensed_points`, its hits on other vehicles left out), and ``sat_vmax`` the scaling
down to the speed ``max_speed``. A vehicle repels within the centre distance ``R``,
the report's safe-zone radius (eq. (27)'s R), so a formation whose slots are at
least ``R`` apart holds them exactly. (P3) and (P4) are the negative gradient of
``U = k_rep (ln(rho_0 / rho) + rho / rho_0 - 1)`` with ``rho_0`` the gap at ``R``, zero
and flat there, infinite at contact (``rho`` is floored at :data:`MIN_GAP`). The
feed-forward
``x_ref'`` (the virtual leader's velocity) is this module's addition: without it the
formation trails a leader moving at speed ``V`` by ``V / k_att``.

How it drives a vehicle of eq. (1): ``v_i`` is integrated into the vehicle's moving
target ``q_i`` (:mod:`sandbox.model.moving_target`), which starts at the vehicle, and
the flatness controller tracks ``(q_i, v_i, (v_i - v_i(t - h)) / h)`` as its ``(slot,
x_ref', x_ref'')``; the forces are evaluated at the target, the other vehicles at their
measured positions (a stopped or failed vehicle repels where it is).

The static obstacles are seen through the range sensor (``sensors.range``; the law
receives no map of them): without a sensor only the vehicles repel, and a scenario's
obstacles are left to a recovery strategy or a safety filter. The sensor's
``max_range`` should exceed ``range``, a miss reading ``max_range``.

Symbols: ``k_att`` (``attraction``) [1/s], ``k_rep`` (``repulsion``) [m^2/s],
``R`` (``range``) [m], ``d_c`` (``contact``) [m], ``max_speed`` [m/s]. Cost: every
pair of vehicles of a world, ``O(n^2)``.
"""

from __future__ import annotations

import numpy as np

from sandbox.model.laws import ROTATE
from sandbox.model.moving_target import (
    advance,
    goals,
    moving_target,
    neighbour_sum,
    point_sum,
    saturate,
    sensed_points,
)
from sandbox.plugins.contexts import LawContext
from sandbox.plugins.registration import Param, register_law

#: The gap below which (P3)-(P4) stop growing [m] (overlapping discs included).
MIN_GAP = 0.01

PARAMS = {
    "rotate": ROTATE,
    "attraction": Param(
        "number",
        1.0,
        "1/s",
        "k_att of (P2): the pull toward the vehicle's place on the virtual leader's "
        "formation, a velocity of k_att per metre of error (default 1 1/s: 2 m "
        "away asks for 2 m/s, the benchmark robot's v1_max)",
        minimum=0.0,
        exclusive=True,
    ),
    "repulsion": Param(
        "number",
        0.5,
        "m^2/s",
        "k_rep of (P3)-(P4): the push k_rep (1 / rho - 1 / rho_0) away from a vehicle "
        "or obstacle point at the gap rho (default 0.5 m^2/s: 2 m/s at a gap of "
        "0.2 m between two vehicles with R = 3d = 1.5 m)",
        minimum=0.0,
    ),
    "range": Param(
        "length",
        "3d",
        "m",
        "R of (P3)-(P4): the centre distance beyond which nothing repels (default 3d, "
        "the report's safe-zone radius R)",
        minimum=0.0,
        exclusive=True,
    ),
    "contact": Param(
        "length",
        "1d",
        "m",
        "d_c of (P3)-(P4): the centre distance of two vehicles in contact, the gap's "
        "zero (default 1d, the vehicle diameter)",
        minimum=0.0,
    ),
    "max_speed": Param(
        "number",
        2.0,
        "m/s",
        "The largest speed of (P1)'s velocity (default 2 m/s, the benchmark robot's "
        "v1_max)",
        minimum=0.0,
        exclusive=True,
    ),
}


def repulsion(rel: np.ndarray, gain: float, reach: float, contact: float) -> np.ndarray:
    """(P3)-(P4): the push away from a point at ``rel = x - q`` [m], in [m/s].

    ``gain (1 / rho - 1 / rho_0) (-rel / |rel|)`` with the gap ``rho = |rel| -
    contact`` (floored at :data:`MIN_GAP`) and ``rho_0 = reach - contact`` where
    ``|rel| < reach``, else 0.

    >>> repulsion(np.array([[1.0, 0.0]]), 0.5, 1.5, 0.5).round(6).tolist()
    [[-0.5, -0.0]]
    """
    dist = np.sqrt(rel[..., 0] * rel[..., 0] + rel[..., 1] * rel[..., 1])
    gap = np.maximum(dist - contact, MIN_GAP)
    far = reach - contact
    size = np.where(dist < reach, gain * (1.0 / gap - 1.0 / far), 0.0)
    return -(size / np.maximum(dist, 1e-300))[..., None] * rel


def potential_velocity(ctx: LawContext, q: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """(P1): the desired velocity of each vehicle's target ``q`` [m/s]."""
    p = ctx.params
    gain, reach = float(p["repulsion"]), float(p["range"])
    contact = float(p["contact"])
    velocity = -float(p["attraction"]) * (q - goal)  # (P2)
    pos = np.asarray(ctx.pos, dtype=float)
    if gain > 0.0:
        velocity += neighbour_sum(
            lambda rel, _: repulsion(rel, gain, reach, contact), q, pos
        )  # (P3)
        if ctx.ranges is not None:
            points, _ = sensed_points(ctx, reach, 0.5 * contact)
            velocity += point_sum(
                lambda rel: repulsion(rel, gain, reach, 0.5 * contact), q, points
            )  # (P4)
    return saturate(ctx.reference[1] + velocity, float(p["max_speed"]))  # (P1)


@register_law(
    "potential",
    PARAMS,
    needs_leader=False,
    needs_reference=True,
    frame="reference",
    batched=True,
)
def potential(ctx: LawContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Virtual leader and potential fields, the report's reference [2] (P1)-(P4)."""
    target = moving_target(ctx)
    goal = goals(ctx, target, bool(ctx.params["rotate"]))
    velocity = potential_velocity(ctx, target.position, goal)
    return advance(target, velocity, ctx.dt)
