"""The braking-distance barrier and the sensing margin: pure functions of arrays.

Used by the safety filter (``safety: {filter: cbf, barrier: braking}``,
:mod:`sandbox.behaviour.safety.cbf`) and by the loader's checks of a scenario (an
unsafe start, a margin the broadcast needs); see ``docs/concepts/safety.md``.

A point that can brake at ``A`` [m/s^2] and is ``s`` [m] short of contact, closing at
``c`` [m/s], can stop in time when ``c <= sqrt(2 A s)`` (the barrier of Wang, Ames and
Egerstedt, ``h = sqrt(2 A s) - c``). In a sampled loop whose speed changes by at most
``A dt`` per period of ``dt`` [s] the largest safe closing speed is the root of
``F^2 + A dt F = 2 A s``::

    F(s) = sqrt((A dt / 2)^2 + 2 A s) - A dt / 2,

which tends to ``sqrt(2 A s)`` as ``dt -> 0``. It is exact for motion along the line
of centres: from ``c = F(s)`` one period later the gap is ``s' = s - c dt`` and
``F(s') = c - A dt`` (``F(s')^2 + A dt F(s') = 2 A s - 2 A c dt = (c - A dt)^2 + A dt
(c - A dt)``), so braking at ``A`` keeps ``c <= F(s)`` until the point stops, short of
contact.
"""

from __future__ import annotations

import numpy as np

#: Standard deviations of the position and heading noise the margin covers [1].
SIGMAS = 3.0


#: Shortest distance treated as a direction [m].
MIN_DIST = 1e-9
#: Smallest speed a division by a speed is guarded with [m/s].
MIN_SPEED = 1e-9


def braking_speed(s: np.ndarray, accel: np.ndarray, dt: float) -> np.ndarray:
    """Largest closing speed [m/s] from which a gap ``s`` can be braked away.

    Parameters
    ----------
    s : ndarray [m]
        The gap left before contact (negative: already inside, gives 0).
    accel : ndarray [m/s^2]
        The braking ``A`` of the pair (``a_i + a_j``; ``a_i`` toward a vehicle that
        does not brake, an obstacle or a wall).
    dt : float [s]
        The control period.

    Returns
    -------
    ndarray [m/s]
        ``F(s) = sqrt((A dt / 2)^2 + 2 A s) - A dt / 2`` (0 for ``s <= 0``).

    >>> float(braking_speed(np.array(1.0), np.array(2.0), 0.0))
    2.0
    >>> round(float(braking_speed(np.array(1.0), np.array(2.0), 0.1)), 6)
    1.902498
    """
    half = 0.5 * accel * dt
    gap = np.maximum(s, 0.0)
    return np.sqrt(half * half + 2.0 * accel * gap) - half


def sensing_margin(
    position_noise: float,
    heading_noise: float,
    delay: float,
    speed: float,
    look_ahead: float,
) -> float:
    """Distance [m] the broadcast pose of a neighbour's look-ahead point may be off.

    ``SIGMAS`` (3) standard deviations of the position noise along the line of
    centres, the look-ahead point's swing ``l`` times 3 standard deviations of the
    heading noise, and the distance the neighbour covers at its top speed during the
    delay::

        m_s = 3 sigma_p + 3 l sigma_theta + s_max tau.

    Parameters
    ----------
    position_noise : float [m]
        ``sigma_p``, per coordinate.
    heading_noise : float [rad]
        ``sigma_theta``.
    delay : float [s]
        ``tau``.
    speed : float [m/s]
        ``s_max``, the largest speed of a look-ahead point.
    look_ahead : float [m]
        ``l``.

    Returns
    -------
    float [m]

    >>> round(sensing_margin(0.01, 0.0, 0.02, 2.0, 0.1), 6)
    0.07
    """
    return SIGMAS * position_noise + SIGMAS * look_ahead * heading_noise + speed * delay
