"""What the velocity-producing formation laws share: the moving target and the goals.

The laws of :mod:`sandbox.model.potential` and :mod:`sandbox.model.flocking` give each
vehicle a velocity (the first) or an acceleration (the second), where eq. (6) of the
report tracks a point with its first two derivatives. They integrate their output into
a *moving target* for each vehicle, a point that starts where the vehicle is, and hand
the flatness controller the target's position, velocity and acceleration as ``(slot,
x_ref', x_ref'')``. The law's own goal for a vehicle, its place on the virtual leader's
formation, is :func:`goals`: the reference point plus the vehicle's offset (eq. (13) of
the report; turned with the reference's tangent, eqs. (14)-(15), with ``rotate``).

The arrays carry the loop's world axis: positions ``(K, n, 2)`` for a loop of K worlds,
``(n, 2)`` for one world called alone; everything here is elementwise over it, the sums
over the other vehicles taken one vehicle at a time in index order, so each world's
numbers are those it gets alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sandbox.model.laws import REST_SPEED, rotate_offsets
from sandbox.plugins.contexts import LawContext

#: The laws that hand the controller a moving target (their goals' metrics:
#: :mod:`sandbox.run.goals`).
MOVING_TARGET_LAWS = ("potential", "flocking")
#: A range hit within this many radii of another vehicle's centre is on that vehicle.
BODY_SLACK = 1.2


@dataclass
class MovingTarget:
    """The point each vehicle tracks, and its velocity (kept in the law's memory).

    Attributes
    ----------
    position : ndarray, shape (..., n, 2) [m]
    velocity : ndarray, shape (..., n, 2) [m/s]
    last_velocity : ndarray, shape (..., n, 2) [m/s] or None
        The velocity handed out at the last step (None at the first).
    tangent : ndarray, shape (..., 1) [rad]
        The reference's tangent angle of eq. (15) last defined (for ``rotate``).
    """

    position: np.ndarray
    velocity: np.ndarray
    last_velocity: np.ndarray | None
    tangent: np.ndarray


def moving_target(ctx: LawContext) -> MovingTarget:
    """The law's moving target: from its memory, or at the vehicles at the first call.

    A world called alone and one of a batch start alike: at the vehicles' positions
    and measured velocities.
    """
    target = ctx.memory.get("target")
    if target is None:
        pos = np.asarray(ctx.pos, dtype=float)
        target = MovingTarget(
            pos.copy(),
            np.array(ctx.vel, dtype=float),
            None,
            np.zeros(pos.shape[:-2] + (1,)),
        )
        ctx.memory["target"] = target
    return target


def goals(ctx: LawContext, target: MovingTarget, rotate: bool) -> np.ndarray:
    """Each vehicle's place around the virtual leader [m], shape of ``ctx.offset``.

    Implements eqs. (13)-(15) of the report: ``x_ref + Delta``, the offsets turned by
    the reference's tangent angle with ``rotate`` (the last angle defined while the
    reference rests, below :data:`~sandbox.model.laws.REST_SPEED`).
    """
    p, dp, _ = ctx.reference
    offset = np.asarray(ctx.offset, dtype=float)
    if not rotate:
        return p + offset
    if np.hypot(dp[0], dp[1]) >= REST_SPEED:
        target.tangent = np.full(target.tangent.shape, np.arctan2(dp[1], dp[0]))
    return p + rotate_offsets(offset, target.tangent)  # eqs. (14)-(15)


def advance(
    target: MovingTarget, velocity: np.ndarray, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hand out the target now, and move it along ``velocity`` for the period.

    Returns the target's position, ``velocity`` and the acceleration estimated by
    the backward difference of the velocities handed out (eq. (19) of the report; 0
    at the first step); the position of the next step is ``position + h velocity``.

    Parameters
    ----------
    target : MovingTarget
    velocity : ndarray, shape (..., n, 2) [m/s]
        The target's velocity over the period.
    h : float [s]
        The control period.
    """
    position = target.position
    if target.last_velocity is None:
        accel = np.zeros_like(velocity)
    else:
        accel = (velocity - target.last_velocity) / h
    target.last_velocity = velocity
    target.velocity = velocity
    target.position = position + h * velocity
    return position, velocity, accel


def saturate(v: np.ndarray, limit: float) -> np.ndarray:
    """``v`` scaled down to the length ``limit`` where longer (over the last axis).

    >>> saturate(np.array([[3.0, 4.0], [0.3, 0.4]]), 1.0).round(6).tolist()
    [[0.6, 0.8], [0.3, 0.4]]
    """
    length = np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1])
    scale = np.where(length > limit, limit / np.maximum(length, 1e-300), 1.0)
    return v * scale[..., None]


def neighbour_sum(
    term: Any,
    q: np.ndarray,
    others: np.ndarray,
    own_velocity: np.ndarray | None = None,
    others_velocity: np.ndarray | None = None,
) -> np.ndarray:
    """``sum_j term(x_j - q_i, v_j - p_i)`` over the other vehicles, in index order.

    Parameters
    ----------
    term : callable
        ``term(rel, rel_velocity) -> (..., n, 2)``: what a vehicle at ``rel = x_j -
        q_i`` (moving at ``rel_velocity`` relative to ``p_i``, None without
        velocities) adds to each vehicle's sum (0 beyond its range).
    q : ndarray, shape (..., n, 2) [m]
        The vehicles' own points (their targets).
    others : ndarray, shape (..., n, 2) [m]
        Where the vehicles are (the others' points).
    own_velocity, others_velocity : ndarray, shape (..., n, 2) [m/s], optional
        The targets' velocities and the vehicles' measured ones.

    Returns
    -------
    ndarray, shape (..., n, 2)
        The sums, terms that are not finite (a vehicle without a slot) left out.
    """
    n = q.shape[-2]
    total = np.zeros(q.shape)
    for j in range(n):
        rel = others[..., j : j + 1, :] - q
        rel_velocity = None
        if own_velocity is not None and others_velocity is not None:
            rel_velocity = others_velocity[..., j : j + 1, :] - own_velocity
        with np.errstate(invalid="ignore", divide="ignore"):
            part = term(rel, rel_velocity)
        part[..., j, :] = 0.0  # not itself
        total += np.where(np.isfinite(part), part, 0.0)
    return total


def point_sum(term: Any, q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``sum_b term(o_b - q_i)`` over each vehicle's obstacle points ``o_b``, in order.

    Parameters
    ----------
    term : callable
        ``term(rel) -> (..., n, 2)`` for ``rel = o - q_i`` of shape (..., n, 2).
    q : ndarray, shape (..., n, 2) [m]
    points : ndarray, shape (..., n, B, 2) [m]
        NaN where a beam gives no point (its term left out).
    """
    total = np.zeros(q.shape)
    for b in range(points.shape[-2]):
        with np.errstate(invalid="ignore", divide="ignore"):
            part = term(points[..., b, :] - q)
        total += np.where(np.isfinite(part), part, 0.0)
    return total


def sensed_points(
    ctx: LawContext, reach: float, body: float
) -> tuple[np.ndarray, np.ndarray]:
    """Obstacle points the range sensor saw within ``reach`` of each vehicle.

    A beam's hit point, in world coordinates from the vehicle's position and heading
    now, where its reading is a local minimum of the scan (each convex obstacle's
    nearest point, one per obstacle without a segmentation) and shorter than
    ``reach``; a miss reads the sensor's ``max_range``, so ``reach`` below it keeps
    misses out. The beams also hit the other vehicles, which the laws see where they
    are: a point within :data:`BODY_SLACK` times ``body`` of another vehicle's centre
    is that vehicle, and left out.

    Parameters
    ----------
    ctx : LawContext
    reach : float [m]
    body : float [m]
        A vehicle's radius.

    Returns
    -------
    points : ndarray, shape (..., n, B, 2) [m]
        NaN where a beam gives no point.
    seen : ndarray, shape (..., n, B), bool
    """
    pos = np.asarray(ctx.pos, dtype=float)
    shape = pos.shape[:-1]
    ranges = np.asarray(ctx.ranges, dtype=float).reshape(*shape, -1)
    angles = np.asarray(ctx.beam_angles, dtype=float).reshape(*shape, -1)
    theta = np.asarray(ctx.theta, dtype=float).reshape(shape)[..., None]
    with np.errstate(invalid="ignore"):
        low = (ranges <= np.roll(ranges, 1, axis=-1)) & (
            ranges <= np.roll(ranges, -1, axis=-1)
        )
        seen = np.isfinite(ranges) & low & (ranges < reach)
    angle = theta + angles
    points = np.empty((*ranges.shape, 2))
    points[..., 0] = pos[..., 0:1] + ranges * np.cos(angle)
    points[..., 1] = pos[..., 1:2] + ranges * np.sin(angle)
    limit = (BODY_SLACK * body) ** 2
    for j in range(pos.shape[-2]):  # the other vehicles' surfaces, in order
        rel = points - pos[..., None, j : j + 1, :]
        with np.errstate(invalid="ignore"):
            on_vehicle = rel[..., 0] ** 2 + rel[..., 1] ** 2 < limit
        on_vehicle[..., j, :] = False  # a vehicle does not see itself
        seen &= ~on_vehicle
    points[~seen] = np.nan
    return points, seen
