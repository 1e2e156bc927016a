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
