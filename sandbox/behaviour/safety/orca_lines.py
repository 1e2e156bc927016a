"""ORCA's half-planes: toward another vehicle, a circular obstacle, a wall or polygon.

The velocity obstacle of a disc ``B`` of radius ``R`` at ``x_B - x_A`` for the horizon
``tau`` is the cone of relative velocities that bring the two discs into contact within
``tau`` (van den Berg, Guy, Lin and Manocha, "Reciprocal n-body collision avoidance",
2011, eq. (2)): the cone from the origin tangent to the disc of radius ``R / tau`` at
``(x_B - x_A) / tau``, cut off by that disc. ``u`` is the smallest change of the
relative velocity ``v_A - v_B`` that leaves it (to the nearest point of the cone's
boundary, the cut-off circle or a leg); ORCA's half-plane of ``A`` is

    ORCA_A|B = {v : (v - (v_A + share u)) . n >= 0},      (eq. (3) of the paper)

with ``n`` the outward normal at that point and ``share = 1/2`` between two vehicles
that both avoid (each takes half of the change), 1 toward one that does not (a vehicle
believed failed, one driven open loop, an obstacle). Overlapping discs take the
cut-off of one control period instead of ``tau`` (RVO2's rule: separate within a
step).

A half-plane is returned as a line, a point and a unit direction, the admissible side
on its left (:mod:`sandbox.behaviour.safety.orca_program`): the direction is the
normal turned a right angle clockwise.
"""

from __future__ import annotations

import numpy as np

from sandbox.behaviour.safety.orca_program import TINY, det, dot


def vehicle_lines(
    rel_pos: np.ndarray,
    rel_vel: np.ndarray,
    radius: np.ndarray,
    horizon: float,
    period: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The ORCA line of discs ``A`` toward discs ``B``: its direction and ``u``.

    Implements eqs. (2)-(3) of van den Berg et al. (2011) as the RVO2 library
    computes them (``Agent::computeNewVelocity``): the projection of the relative
    velocity on the cut-off circle or on the nearer leg of the truncated cone.

    Parameters
    ----------
    rel_pos : ndarray, shape (k, 2) [m]
        ``x_B - x_A``.
    rel_vel : ndarray, shape (k, 2) [m/s]
        ``v_A - v_B``.
    radius : ndarray, shape (k,) [m]
        ``R``, the sum of the two discs' radii (with margins).
    horizon : float [s]
        ``tau``.
    period : float [s]
        The control period: the cut-off of discs already overlapping.

    Returns
    -------
    direction : ndarray, shape (k, 2) [1]
        The line's unit direction (admissible side on its left).
    u : ndarray, shape (k, 2) [m/s]
        The smallest change of the relative velocity out of the velocity obstacle;
        the line passes through ``v_A + share u``.

    Examples
    --------
    Head-on, 4 m apart, closing at 1.75 m/s, R = 1 m, tau = 2 s: the relative
    velocity (1.75, 0) lies 0.25 m/s inside the cut-off circle of radius R / tau =
    0.5 m/s about (2, 0), so ``u = (-0.25, 0)``, and the line is vertical with the
    admissible side ``v_x <= v_A,x + share u_x``.

    >>> d, u = vehicle_lines(np.array([[4.0, 0.0]]), np.array([[1.75, 0.0]]),
    ...                      np.array([1.0]), 2.0, 0.01)
    >>> d.tolist(), u.tolist()
    ([[0.0, 1.0]], [[-0.25, 0.0]])
    """
    dist_sq = dot(rel_pos, rel_pos)
    r_sq = radius * radius
    apart = dist_sq > r_sq
    # The cut-off circle: of the horizon, or of one period for overlapping discs.
    inverse = np.where(apart, 1.0 / horizon, 1.0 / period)
    w = rel_vel - inverse[:, None] * rel_pos  # from the cut-off centre to rel_vel
    w_sq = dot(w, w)
    along = dot(w, rel_pos)
    on_circle = ~apart | ((along < 0.0) & (along * along > r_sq * w_sq))
    w_len = np.sqrt(np.maximum(w_sq, TINY))
    unit = w / w_len[:, None]
    circle_dir = np.empty_like(unit)
    circle_dir[:, 0], circle_dir[:, 1] = unit[:, 1], -unit[:, 0]
    circle_u = (radius * inverse - w_len)[:, None] * unit
    # The legs: tangents from the origin to the disc of radius R at rel_pos.
    leg = np.sqrt(np.maximum(dist_sq - r_sq, 0.0))
    scale = 1.0 / np.maximum(dist_sq, TINY)
    x, y = rel_pos[:, 0], rel_pos[:, 1]
    left = det(rel_pos, w) > 0.0
    leg_dir = np.empty_like(rel_pos)
    leg_dir[:, 0] = np.where(left, x * leg - y * radius, -(x * leg + y * radius))
    leg_dir[:, 1] = np.where(left, x * radius + y * leg, -(-x * radius + y * leg))
    leg_dir *= scale[:, None]
    leg_u = dot(rel_vel, leg_dir)[:, None] * leg_dir - rel_vel
    direction = np.where(on_circle[:, None], circle_dir, leg_dir)
    u = np.where(on_circle[:, None], circle_u, leg_u)
    return direction, u


def surface_lines(
    away: np.ndarray, clearance: np.ndarray, horizon: float
) -> tuple[np.ndarray, np.ndarray]:
    """The ORCA line of a disc toward a wall or polygon, seen at its nearest point.

    The obstacle lies beyond the line tangent to its surface at the point nearest to
    the disc's centre (for a convex obstacle, the whole of it: the supporting line
    there), so the disc does not reach it within ``horizon`` if it does not cross
    that line: ``away . v >= -clearance / horizon``, with ``clearance`` the distance
    from the disc to the line (negative: overlapping, the half-plane then asks the
    disc to move away). This is RVO2's cut-off line of a segment seen face on
    (``Agent::computeNewVelocity``), without the legs of its end points; it keeps the
    velocity obstacle of a convex obstacle inside it, and treats a non-convex outline
    as the CBF filter does, by its nearest point.

    Parameters
    ----------
    away : ndarray, shape (k, 2) [1]
        Unit normal from the obstacle toward the disc.
    clearance : ndarray, shape (k,) [m]
        Distance from the disc's surface (with its margins) to the obstacle's.
    horizon : float [s]
        The obstacles' time horizon.

    Returns
    -------
    point : ndarray, shape (k, 2) [m/s]
    direction : ndarray, shape (k, 2) [1]

    Examples
    --------
    A wall 0.5 m to the right of a disc (normal (-1, 0)), a horizon of 1 s: the line
    ``-v_x >= -0.5``, i.e. ``v_x <= 0.5`` m/s.

    >>> p, d = surface_lines(np.array([[-1.0, 0.0]]), np.array([0.5]), 1.0)
    >>> p.tolist(), d.tolist()
    ([[0.5, -0.0]], [[0.0, 1.0]])
    """
    point = (-clearance / horizon)[:, None] * away
    direction = np.empty_like(away)
    direction[:, 0], direction[:, 1] = away[:, 1], -away[:, 0]
    return point, direction
