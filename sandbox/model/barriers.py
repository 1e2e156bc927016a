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
#: Below this ``|sin(v2 dt / 2)|`` [1] a driven path is straight (a circle of radius
#: beyond ``v1 dt 1e12``).
STRAIGHT = 1e-12


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


def driven_path(
    start: np.ndarray,
    course: np.ndarray,
    speed: np.ndarray,
    turn: np.ndarray,
    dt: float,
    samples: int,
) -> np.ndarray:
    """The centres of vehicles that keep their commands, at the start of each period.

    A drive at the commands ``(v1, v2)`` runs each period straight at ``v1`` along
    the heading of the period's middle (the period of
    :mod:`sandbox.behaviour.estimation`), so its centre visits the vertices::

        c_m = c_0 + v1 dt sin(m beta / 2) / sin(beta / 2) (cos, sin)(x3 + m beta / 2),

    ``beta = v2 dt`` (``m v1 dt`` along the heading where ``beta = 0``): a regular
    polygon inscribed in a circle of radius ``|v1 dt / (2 sin(beta / 2))|``.

    Parameters
    ----------
    start : ndarray, shape (k, 2) [m]
        The centres ``c_0``.
    course : ndarray, shape (k,) [rad]
        The headings ``x3`` now.
    speed, turn : ndarray, shape (k,) [m/s], [rad/s]
        The commands ``v1``, ``v2`` kept.
    dt : float [s]
    samples : int

    Returns
    -------
    ndarray, shape (k, samples, 2) [m]

    >>> c = driven_path(np.zeros((1, 2)), np.zeros(1), np.ones(1),
    ...                 np.array([np.pi / 2]), 1.0, 4)
    >>> np.round(c[0], 6).tolist()  # a square of side 1, counterclockwise
    [[0.0, 0.0], [0.707107, 0.707107], [0.0, 1.414214], [-0.707107, 0.707107]]
    """
    beta = turn * dt
    m = np.arange(samples)[None, :]
    half = np.sin(0.5 * beta)
    straight = np.abs(half) < STRAIGHT
    ratio = np.sin(0.5 * beta[:, None] * m) / np.where(straight, 1.0, half)[:, None]
    factor = np.where(straight[:, None], m, ratio)
    angle = course[:, None] + 0.5 * beta[:, None] * m
    step = (speed * dt)[:, None] * factor
    return start[:, None] + step[..., None] * np.stack(
        (np.cos(angle), np.sin(angle)), -1
    )


def path_floor(
    q: np.ndarray,
    start: np.ndarray,
    course: np.ndarray,
    speed: np.ndarray,
    turn: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The least distance [m] from fixed points to a driven path, from now on, forever.

    The path of :func:`driven_path` from its vertex ``start`` (heading ``course``)
    on, without end. Turning (``beta = v2 dt != 0``), it goes round its polygon for
    ever, whose sides lie in the annulus of radii ``r cos(beta / 2)`` and ``r``, ``r
    = |R|``, ``R = v1 dt / (2 sin(beta / 2))``, about ``C = c + R n``, ``n = (-sin
    x3, cos x3)``; the distance to the annulus is a lower bound, short of the
    polygon's by at most its sagitta ``r (1 - cos(beta / 2))`` (``|v1 v2| dt^2 /
    8``, 2e-5 m at 2 m/s, 0.7 rad/s, 10 ms). With ``u = q - c`` and ``w = q - C``,
    stably for large ``r``::

        |w| - r = (|u|^2 - 2 R u . n) / (|w| + r),
        floor = max(|w| - r, r cos(beta / 2) - |w|, 0).

    Straight (``beta = 0``), the ray from ``c`` along ``sign(v1) (cos, sin) x3``.

    Parameters
    ----------
    q : ndarray, shape (k, 2) [m]
    start : ndarray, shape (k, 2) [m]
    course, speed, turn : ndarray, shape (k,) [rad], [m/s], [rad/s]
    dt : float [s]

    Returns
    -------
    dist : ndarray, shape (k,) [m]
    normal : ndarray, shape (k, 2) [1]
        The unit gradient of the floor in ``q`` (away from the path).

    >>> q = np.array([[0.0, 5.0], [-1.0, -1.0]])
    >>> d, n = path_floor(q, np.zeros((2, 2)), np.zeros(2), np.ones(2),
    ...                   np.array([0.5, 0.0]), 1e-3)  # a circle of radius 2; a ray
    >>> np.round(d, 6).tolist(), np.round(n, 6).tolist()
    ([1.0, 1.414214], [[0.0, 1.0], [-0.707107, -0.707107]])
    """
    beta = turn * dt
    half = np.sin(0.5 * beta)
    straight = np.abs(half) < STRAIGHT
    heading = np.stack((np.cos(course), np.sin(course)), -1)
    u = q - start
    # turning: the annulus about the polygon's centre
    big_r = speed * dt / (2.0 * np.where(straight, 1.0, half))
    n = heading[:, ::-1] * [-1.0, 1.0]
    w = u - big_r[:, None] * n
    size = np.hypot(w[:, 0], w[:, 1])
    radius = np.abs(big_r)
    out = np.einsum("kd,kd->k", u, u) - 2.0 * big_r * np.einsum("kd,kd->k", u, n)
    out /= np.maximum(size + radius, MIN_DIST)
    sag = 2.0 * radius * np.sin(0.25 * beta) ** 2
    inner = -out - sag
    ring = np.maximum(np.maximum(out, inner), 0.0)
    ring_n = w / np.maximum(size, MIN_DIST)[:, None]
    ring_n *= np.where(out >= inner, 1.0, -1.0)[:, None]
    # straight: the ray
    way = heading * np.sign(speed)[:, None]
    along = np.maximum(np.einsum("kd,kd->k", u, way), 0.0)
    off = u - along[:, None] * way
    ray = np.hypot(off[:, 0], off[:, 1])
    ray_n = off / np.maximum(ray, MIN_DIST)[:, None]
    dist = np.where(straight, ray, ring)
    return dist, np.where(straight[:, None], ray_n, ring_n)
