"""The braking-safe barrier and the sensing margin: pure functions of arrays.

Used by the safety filter (``safety: {filter: cbf, barrier: braking}``,
:mod:`sandbox.behaviour.safety.cbf`, :mod:`sandbox.behaviour.safety.braking`) and by
the loader's checks of a scenario (an unsafe start, a margin the broadcast needs);
see ``docs/concepts/safety.md``.

A vehicle *brakes* when its turn rate is 0 and its speed moves toward 0 by its
``max_accel dt`` a period of ``dt`` [s]: its look-ahead point then runs straight
along its heading and stops. :func:`braking_speeds` gives the speeds of those
periods, and :func:`closest_approach` the least distance of two points moving at
constant velocity within each period (two braking vehicles, or a braking vehicle
and one that keeps its velocity): exactly, period by period; :func:`local_minima`
picks the periods where it has a local minimum.
"""

from __future__ import annotations

import math

import numpy as np

#: Standard deviations of the estimate's error the sensing margin covers [1].
SIGMAS = 3.0
#: The least gain ``K`` of the estimate of the others' poses under sensing (the key
#: ``safety.estimate_gain`` left out) [1]: a time constant of ``dt / K``.
ESTIMATE_GAIN = 0.1


#: Shortest distance treated as a direction [m].
MIN_DIST = 1e-9
#: Smallest speed a division by a speed is guarded with [m/s].
MIN_SPEED = 1e-9


def braking_speeds(first: np.ndarray, step: np.ndarray, periods: int) -> np.ndarray:
    """Speeds [m/s] of the periods of a braking, from the first period's speed.

    ``s_m = sign(first) max(|first| - m step, 0)``, ``m = 0 .. periods - 1``: the
    first period at ``first``, each later one ``step`` nearer 0, then at rest.

    Parameters
    ----------
    first : ndarray, shape (k,) [m/s]
        The speed of the first period.
    step : ndarray, shape (k,) [m/s]
        The change a period, ``max_accel dt`` (> 0).
    periods : int

    Returns
    -------
    ndarray, shape (k, periods) [m/s]

    >>> braking_speeds(np.array([0.625, -0.25]), np.array([0.25, 0.25]), 4).tolist()
    [[0.625, 0.375, 0.125, 0.0], [-0.25, 0.0, 0.0, 0.0]]
    """
    m = np.arange(periods)
    left = np.abs(first)[:, None] - m[None, :] * step[:, None]
    return np.sign(first)[:, None] * np.maximum(left, 0.0) + 0.0  # no -0.0


def braking_periods(speed: np.ndarray, step: np.ndarray) -> np.ndarray:
    """How many periods a braking from ``speed`` [m/s] moves (``ceil(|v| / step)``).

    >>> braking_periods(np.array([0.12, 0.0, 0.1]), np.array([0.05, 0.05, 0.05]))
    array([3, 0, 2])
    """
    return np.ceil(np.abs(speed) / step - 1e-9).astype(np.intp).clip(0)


def closest_approach(rel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least distance, period by period, of a relative position moving straight.

    ``rel[:, m]`` is the relative position at the start of period ``m`` (``M + 1``
    samples, ``M`` periods); within a period it moves at constant velocity, so the
    least distance over the period is at ``f = clip(-r_m . d_m / |d_m|^2, 0, 1)``,
    ``d_m = r_(m+1) - r_m``.

    Parameters
    ----------
    rel : ndarray, shape (k, M + 1, 2) [m]

    Returns
    -------
    dist : ndarray, shape (k, M) [m]
        The least distance over each period.
    frac : ndarray, shape (k, M) [1]
        How far into the period it is reached, in [0, 1].

    >>> rel = np.array([[[-2.0, 1.0], [0.0, 1.0], [2.0, 3.0]]])
    >>> [x.tolist() for x in closest_approach(rel)]
    [[[1.0, 1.0]], [[1.0, 0.0]]]
    """
    r0, d = rel[:, :-1], rel[:, 1:] - rel[:, :-1]
    dd = np.einsum("kmd,kmd->km", d, d)
    f = np.clip(-np.einsum("kmd,kmd->km", r0, d) / np.maximum(dd, 1e-30), 0.0, 1.0)
    near = r0 + f[..., None] * d
    return np.hypot(near[..., 0], near[..., 1]), f


def local_minima(dist: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` least local minima of each row of ``dist`` (k, M), by column.

    A column is a local minimum when it is no larger than the one before and smaller
    than the one after (the ends count as larger); a row with fewer minima repeats
    its least. Returns the columns (k, count) and whether each is a minimum.
    ``dist`` needs at least one column.

    >>> cols, ok = local_minima(np.array([[3.0, 1.0, 2.0, 0.5, 0.5, 4.0]]), 2)
    >>> cols.tolist(), ok.tolist()
    ([[4, 1]], [[True, True]])
    """
    pad = np.pad(dist, ((0, 0), (1, 1)), constant_values=np.inf)
    is_min = (pad[:, 1:-1] <= pad[:, :-2]) & (pad[:, 1:-1] < pad[:, 2:])
    score = np.where(is_min, dist, np.inf)
    if score.shape[1] < count:
        score = np.pad(score, ((0, 0), (0, count - score.shape[1])), "edge")
        score[:, dist.shape[1] :] = np.inf
    order = np.argsort(score, axis=1, kind="stable")[:, :count]
    ok = np.isfinite(np.take_along_axis(score, order, axis=1))
    least = np.argmin(dist, axis=1)[:, None]
    return np.where(ok, order, least), ok


def segment_floor(
    points: np.ndarray, signed: np.ndarray, surface: np.ndarray
) -> np.ndarray:
    """A lower bound of a convex obstacle's signed distance over each straight segment.

    The signed distance ``f`` of a convex obstacle (a circle, a wall's capsule, a
    convex polygon) is a convex function of the position, so along a segment from
    ``q_m`` to ``q_(m+1)`` (``f(t)``, ``t`` in [0, 1]) it lies above its tangent lines
    at both ends, ``f_m + a t`` and ``f_(m+1) + b (t - 1)``, with the slopes ``a =
    n_m . (q_(m+1) - q_m)``, ``b = n_(m+1) . (q_(m+1) - q_m)`` (``n`` the unit normal
    away from the surface, the gradient of ``f``)::

        min_t f >= f_m                          where a >= 0,
                   f_(m+1)                      where b <= 0,
                   f_m + a (b - f_(m+1) + f_m) / (b - a)   else (where they cross).

    Exact where the least is at an end, and off by the second order of the segment's
    length where it is inside (a segment along the surface loses nothing to first
    order, where the bound ``(f_m + f_(m+1) - L_m) / 2`` of a 1-Lipschitz ``f``
    loses half its length ``L_m``). Where a normal is not defined (a sample on the
    surface, or at the centre of a circle) that 1-Lipschitz bound is used.

    Parameters
    ----------
    points : ndarray, shape (k, S, 2) [m]
        The samples.
    signed : ndarray, shape (k, S) [m]
        Their signed distances (negative inside).
    surface : ndarray, shape (k, S, 2) [m]
        Their nearest points on the surface.

    Returns
    -------
    ndarray, shape (k, S - 1) [m]

    >>> q = np.array([[[-1.0, 2.0], [1.0, 2.0]]])  # past a unit circle at the origin
    >>> f = np.hypot(q[..., 0], q[..., 1]) - 1.0
    >>> s = q / np.hypot(q[..., 0], q[..., 1])[..., None]
    >>> round(float(segment_floor(q, f, s)[0, 0]), 4)  # least 1; 1-Lipschitz 0.236
    0.7889
    """
    away = (points - surface) * np.where(signed < 0, -1.0, 1.0)[..., None]
    size = np.hypot(away[..., 0], away[..., 1])
    normal = away / np.maximum(size, MIN_DIST)[..., None]
    step = points[:, 1:] - points[:, :-1]
    reach = np.hypot(step[..., 0], step[..., 1])
    f0, f1 = signed[:, :-1], signed[:, 1:]
    a = np.einsum("kmd,kmd->km", normal[:, :-1], step)
    b = np.einsum("kmd,kmd->km", normal[:, 1:], step)
    span = np.maximum(b - a, MIN_DIST)
    cross = f0 + a * np.clip((b - f1 + f0) / span, 0.0, 1.0)
    low = np.where(a >= 0.0, f0, np.where(b <= 0.0, f1, cross))
    low = np.minimum(low, np.minimum(f0, f1))
    defined = (size[:, :-1] > MIN_DIST) & (size[:, 1:] > MIN_DIST)
    return np.where(defined, low, 0.5 * (f0 + f1 - reach))


def sensing_margin(
    position_noise: float,
    heading_noise: float,
    gain: float,
    look_ahead: float,
    v1_max: float,
    accel: float,
    dt: float,
) -> float:
    """Distance [m] the estimate of a neighbour's braking path may be off.

    The filter takes the others' poses from the estimate of
    :mod:`sandbox.behaviour.estimation` (the broadcast copies carried over the delay
    by the commands, through a filter of least gain ``K``), whose error has a standard
    deviation of at most ``sigma_p sqrt(K)`` per coordinate and ``sigma_theta
    sqrt(K)`` on the heading. A position error moves every point of the neighbour's
    braking path alike; a heading error ``delta`` turns the path about the centre,
    moving its points by up to ``(l + S) delta``, ``S = v1_max (v1_max / a + dt) / 2
    + v1_max dt`` the longest braking (the first period at the command's speed). So,
    :data:`SIGMAS` (3) standard deviations along the line of the closest approach::

        m_s = 3 sqrt(K) (sigma_p + (l + S) sigma_theta).

    Parameters
    ----------
    position_noise : float [m]
        ``sigma_p``, per coordinate.
    heading_noise : float [rad]
        ``sigma_theta``.
    gain : float [1]
        ``K``, the estimate's least gain, in (0, 1].
    look_ahead : float [m]
        ``l``.
    v1_max, accel : float [m/s], [m/s^2]
        The largest speed and the braking's deceleration (the fleet's largest and
        smallest).
    dt : float [s]

    Returns
    -------
    float [m]

    >>> round(sensing_margin(0.02, 0.0, 0.25, 0.1, 2.0, 5.0, 0.01), 6)
    0.03
    """
    travel = 0.5 * v1_max * (v1_max / accel + dt) + v1_max * dt
    spread = position_noise + (look_ahead + travel) * heading_noise
    return SIGMAS * math.sqrt(gain) * spread
