"""The alignment, separation and cohesion law of the report's reference [3].

The report's introduction describes [3]: each vehicle's control law has "a component
that makes them head in the same direction as their neighbors, and another component
that makes them steer away if they get too close to another particle, or steer towards
each other if they are too far apart", the separation set by a parameter. Its
standard form with a virtual leader as the group objective is Olfati-Saber's ("Flocking
for multi-agent dynamic systems: algorithms and theory", IEEE TAC 51(3), 2006,
Algorithms 2 and 3), for agents ``q' = p, p' = u`` (``formation: {law: flocking}``)::

    u_i = sum_j phi_a(|x_j - q_i|_s) n_ij                     (separation, cohesion)
        + c_al sum_j a_ij (v_j - p_i)                         (alignment)
        + c_b sum_o phi_b(|o - q_i|_s) n_io + c2 b_io (P_io p_i - p_i)   (obstacles)
        - c1 s1(q_i - g_i) - c2 (p_i - x_ref')                (virtual leader)   (F1)

with the paper's sigma-norm and the functions built on it, ``eps = 0.1``::

    |z|_s = (sqrt(1 + eps |z|^2) - 1) / eps,
    n_ij = (x_j - q_i) / sqrt(1 + eps |x_j - q_i|^2),
    s1(z) = z / sqrt(1 + |z|^2),
    rho_h(z) = 1 on [0, h), (1 + cos(pi (z - h) / (1 - h))) / 2 on [h, 1], 0 beyond,
    phi(z) = ((a + b) s1(z + c) + (a - b)) / 2,  c = |a - b| / sqrt(4 a b),
    phi_a(z) = rho_h(z / r_s) phi(z - d_s),   a_ij = rho_h(|x_j - q_i|_s / r_s),
    phi_b(z) = rho_h(z / d'_s) (s1(z - d'_s) - 1),
    b_io = rho_h(|o - q_i|_s / d'_s),                                   (F2)

``d_s = |d|_s``, ``r_s = |1.2 d|_s``, ``d'_s = |0.6 d|_s`` (the paper's ``r = kappa d``
with ``kappa = 1.2`` and ``d' = 0.6 d``), ``h = 0.2`` for the vehicles' bump and 0.9
for the obstacles' (the paper's values), and ``P_io = I - n n^T`` the projection on the
obstacle's tangent at the point ``o`` (the paper's beta-agent moves along the surface).
``phi_a`` repels below the distance ``d``, attracts between ``d`` and ``1.2 d`` and
vanishes beyond; the obstacle term only repels.

Adapted to the report's formations: the group objective ``q_r`` of each agent is its
own place ``g_i = x_ref + Delta_i`` on the virtual leader's formation (eqs. (13)-(15) of
the report), not one point for all, so that the flock settles into the formation's
slots; with slots farther apart than ``1.2 d`` the flocking terms vanish there and
only the leader's term (a critically damped pull, ``c2 = 2 sqrt(c1)`` by default)
remains.

How it drives a vehicle of eq. (1): the agent is the vehicle's moving target
(:mod:`sandbox.model.moving_target`), a double integrator that starts at the vehicle
with its velocity: ``u_i`` at the target ``(q_i, p_i)`` is integrated
(``p_i <- sat_vmax(p_i + h u_i)``, ``q_i <- q_i + h p_i``), and the flatness controller
tracks ``(q_i, p_i, u_i)`` as its ``(slot, x_ref', x_ref'')``. The neighbours are the
other vehicles where they are, with their measured velocities ``v_j`` (a stopped or
failed vehicle is avoided where it is, and aligned with at rest). The obstacle points
``o`` are what the vehicle's range sensor sees (``sensors.range``;
:func:`~sandbox.model.moving_target.sensed_points`), none without one.

Symbols and units: ``d`` (``distance``) [m], ``a = b`` (``separation``) [m/s^2],
``c_al`` (``alignment``) [1/s], ``c1`` (``gain``) [1/s^2], ``c2`` (``damping``) [1/s],
``c_b`` = ``separation`` [m/s^2], ``max_speed`` [m/s], ``contact`` [m] (the
centre distance of two vehicles in contact, to tell their range hits from
obstacles'). Cost: every pair of vehicles of
a world, ``O(n^2)``.
"""

from __future__ import annotations

import math

import numpy as np

from sandbox.model.laws import ROTATE
from sandbox.model.moving_target import (
    goals,
    moving_target,
    neighbour_sum,
    point_sum,
    saturate,
    sensed_points,
)
from sandbox.plugins.contexts import LawContext
from sandbox.plugins.registration import Param, register_law

#: The sigma-norm's epsilon, the bumps' h (vehicles, obstacles), kappa = r / d and the
#: obstacles' d' / d: Olfati-Saber's (2006) values.
EPSILON, H_VEHICLES, H_OBSTACLES, KAPPA, OBSTACLE_FRACTION = 0.1, 0.2, 0.9, 1.2, 0.6

PARAMS = {
    "rotate": ROTATE,
    "distance": Param(
        "length",
        "2.5d",
        "m",
        "d of (F2): the distance the separation and cohesion terms keep between two "
        "vehicles (repelling below d, attracting up to 1.2 d; default 2.5d, so that "
        "1.2 d is the report's safe-zone radius R = 3d: slots R apart are not pulled)",
        minimum=0.0,
        exclusive=True,
    ),
    "separation": Param(
        "number",
        5.0,
        "m/s^2",
        "a = b of phi (F2), and c_b of the obstacles' term: the largest acceleration "
        "of the separation and cohesion term (default 5 m/s^2, the benchmark robot's "
        "max_accel)",
        minimum=0.0,
    ),
    "alignment": Param(
        "number",
        1.0,
        "1/s",
        "c_al of (F1): the rate at which a vehicle matches its neighbours' velocities "
        "(weighted by the bump a_ij; the paper's weight 1)",
        minimum=0.0,
    ),
    "gain": Param(
        "number",
        1.0,
        "1/s^2",
        "c1 of (F1): the virtual leader's pull, c1 s1(q - g) (at most c1 per m of "
        "the sigma-saturated error; default 1 1/s^2)",
        minimum=0.0,
        exclusive=True,
    ),
    "damping": Param(
        "number",
        None,
        "1/s",
        "c2 of (F1): the damping toward the virtual leader's velocity (default "
        "2 sqrt(c1), critically damped)",
        minimum=0.0,
    ),
    "contact": Param(
        "length",
        "1d",
        "m",
        "The centre distance of two vehicles in contact: a range hit within 0.6 of it "
        "of another vehicle is that vehicle, not an obstacle (default 1d, the vehicle "
        "diameter)",
        minimum=0.0,
    ),
    "max_speed": Param(
        "number",
        2.0,
        "m/s",
        "The largest speed of the moving target (default 2 m/s, the benchmark "
        "robot's v1_max)",
        minimum=0.0,
        exclusive=True,
    ),
}


def sigma_norm(z: np.ndarray) -> np.ndarray:
    """(F2): ``|z|_s = (sqrt(1 + eps |z|^2) - 1) / eps`` over the last axis [m].

    >>> float(sigma_norm(np.array([0.0, 0.0])))
    0.0
    """
    return (np.sqrt(1.0 + EPSILON * (z[..., 0] ** 2 + z[..., 1] ** 2)) - 1.0) / EPSILON


def sigma_length(length: float) -> float:
    """The sigma-norm of a vector of length ``length`` [m]."""
    return (math.sqrt(1.0 + EPSILON * length * length) - 1.0) / EPSILON


def sigma_gradient(z: np.ndarray) -> np.ndarray:
    """(F2): ``n = z / sqrt(1 + eps |z|^2)``, the gradient of the sigma-norm."""
    scale = 1.0 / np.sqrt(1.0 + EPSILON * (z[..., 0] ** 2 + z[..., 1] ** 2))
    return z * scale[..., None]


def sigma_1(z: np.ndarray) -> np.ndarray:
    """(F2): ``s1(z) = z / sqrt(1 + z^2)`` (a scalar's)."""
    return z / np.sqrt(1.0 + z * z)


def bump(z: np.ndarray, h: float) -> np.ndarray:
    """(F2): the bump ``rho_h``: 1 below ``h``, a half cosine to 0 at 1, 0 beyond.

    >>> bump(np.array([0.1, 0.6, 1.5]), 0.2).round(6).tolist()
    [1.0, 0.5, 0.0]
    """
    ramp = 0.5 * (1.0 + np.cos(np.pi * (z - h) / (1.0 - h)))
    return np.where(z < h, 1.0, np.where(z <= 1.0, ramp, 0.0))


def action(z: np.ndarray, a: float, b: float, d_s: float, r_s: float) -> np.ndarray:
    """(F2): ``phi_a(z) = rho_h(z / r_s) phi(z - d_s)`` [m/s^2], z in sigma-norm [m].

    Negative (repelling) below ``d_s``, positive (attracting) above, 0 beyond ``r_s``.
    """
    c = abs(a - b) / math.sqrt(4.0 * a * b) if a > 0.0 and b > 0.0 else 0.0
    phi = 0.5 * ((a + b) * sigma_1(z - d_s + c) + (a - b))
    return bump(z / r_s, H_VEHICLES) * phi


def obstacle_action(z: np.ndarray, d_s: float) -> np.ndarray:
    """(F2): ``phi_b(z) = rho_h(z / d'_s) (s1(z - d'_s) - 1)`` [1], repelling only."""
    return bump(z / d_s, H_OBSTACLES) * (sigma_1(z - d_s) - 1.0)


def flocking_acceleration(
    ctx: LawContext, q: np.ndarray, p: np.ndarray, goal: np.ndarray
) -> np.ndarray:
    """(F1): the acceleration of each vehicle's agent at ``(q, p)`` [m/s^2]."""
    params = ctx.params
    d = float(params["distance"])
    a = float(params["separation"])
    c_al = float(params["alignment"])
    c1 = float(params["gain"])
    damping = params.get("damping")
    c2 = 2.0 * math.sqrt(c1) if damping is None else float(damping)
    d_s, r_s = sigma_length(d), sigma_length(KAPPA * d)
    pos = np.asarray(ctx.pos, dtype=float)
    vel = np.asarray(ctx.vel, dtype=float)

    def vehicle_term(rel: np.ndarray, rel_velocity: np.ndarray) -> np.ndarray:
        z = sigma_norm(rel)
        out = action(z, a, a, d_s, r_s)[..., None] * sigma_gradient(rel)
        return out + (c_al * bump(z / r_s, H_VEHICLES))[..., None] * rel_velocity

    u = neighbour_sum(vehicle_term, q, pos, p, vel)
    if ctx.ranges is not None and a > 0.0:
        d_b = sigma_length(OBSTACLE_FRACTION * d)
        body = 0.5 * float(params["contact"])
        points, _ = sensed_points(ctx, OBSTACLE_FRACTION * d + body, body)

        def obstacle_term(rel: np.ndarray) -> np.ndarray:
            z = sigma_norm(rel)
            unit = rel / np.sqrt(rel[..., 0] ** 2 + rel[..., 1] ** 2)[..., None]
            normal_speed = unit[..., 0] * p[..., 0] + unit[..., 1] * p[..., 1]
            along = a * obstacle_action(z, d_b)[..., None] * sigma_gradient(rel)
            brake = -(c2 * bump(z / d_b, H_OBSTACLES) * normal_speed)[..., None] * unit
            return along + brake  # P p - p = -(n . p) n

        u += point_sum(obstacle_term, q, points)
    leader = -c1 * sigma_1_vector(q - goal) - c2 * (p - ctx.reference[1])
    return u + leader


def sigma_1_vector(z: np.ndarray) -> np.ndarray:
    """``s1(z) = z / sqrt(1 + |z|^2)`` of vectors (the last axis), Olfati-Saber's."""
    return z / np.sqrt(1.0 + z[..., 0] ** 2 + z[..., 1] ** 2)[..., None]


@register_law(
    "flocking",
    PARAMS,
    needs_leader=False,
    needs_reference=True,
    frame="reference",
    batched=True,
)
def flocking(ctx: LawContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flocking with a virtual leader, the report's reference [3] (F1)-(F2)."""
    target = moving_target(ctx)
    goal = goals(ctx, target, bool(ctx.params["rotate"]))
    q, p = target.position, target.velocity
    u = flocking_acceleration(ctx, q, p, goal)
    target.position = q + ctx.dt * p
    target.velocity = saturate(p + ctx.dt * u, float(ctx.params["max_speed"]))
    target.last_velocity = p
    return q, p, u
