"""Unicycle kinematics, eq. (1) of the report, and the angle helper (pure, vectorized).

The physics engine moves the vehicles; this module is the model the controller assumes,
used to build the engine's velocity commands and in tests as the open-loop reference.
"""

from __future__ import annotations

import numpy as np

try:  # numpy >= 2
    from numpy._core.umath import clip as _clip_ufunc
except ImportError:  # pragma: no cover - numpy 1.26
    from numpy.core.umath import clip as _clip_ufunc

#: ``np.clip``'s own ufunc, called without the wrapper's checks: the same numbers
#: (``CLIP(x, lo, hi)``, scalars or arrays as bounds) at a quarter of the cost.
CLIP = _clip_ufunc


def wrap_angle(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles to ``[-pi, pi)`` [rad].

    >>> float(wrap_angle(3 * np.pi / 2))
    -1.5707963267948966
    >>> float(wrap_angle(np.pi))
    -3.141592653589793
    >>> float(wrap_angle(np.nextafter(-np.pi, -np.inf)))
    -3.141592653589793
    """
    wrapped = (np.asarray(angle, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
    # Rounding maps angles a hair below -pi (nextafter(-pi, -inf)) to +pi: fold back.
    high = wrapped >= np.pi
    if np.ndim(high) and not np.count_nonzero(high):
        return wrapped
    return np.where(high, -np.pi, wrapped)


def unicycle_rates(theta: np.ndarray, v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
    """Right-hand side of eq. (1): ``(x1', x2', x3')``, shape ``(n, 3)``.

    Parameters
    ----------
    theta : ndarray, shape (n,) [rad]
        Headings x3.
    v1 : ndarray, shape (n,) [m/s]
        Forward speeds.
    v2 : ndarray, shape (n,) [rad/s]
        Turn rates.
    """
    theta, v1, v2 = np.broadcast_arrays(theta, v1, v2)
    return np.stack((v1 * np.cos(theta), v1 * np.sin(theta), v2), axis=-1)  # eq. (1)


def unicycle_step(
    pose: np.ndarray, v1: np.ndarray, v2: np.ndarray, dt: float
) -> np.ndarray:
    """Advance poses ``(n, 3)`` by ``dt`` [s] under constant commands, exactly.

    Integrates eq. (1) in closed form (arcs of radius ``v1 / v2``; straight lines when
    ``v2 = 0``).

    >>> unicycle_step(np.zeros((1, 3)), np.ones(1), np.zeros(1), 1.0).tolist()
    [[1.0, 0.0, 0.0]]
    """
    pose = np.asarray(pose, dtype=float)
    x, y, th = pose[..., 0], pose[..., 1], pose[..., 2]
    dth = v2 * dt
    small = np.abs(dth) < 1e-9
    # Chord of the arc: length v1*dt*sinc(dth/2) along th + dth/2.
    chord = v1 * dt * np.where(small, 1.0 - dth**2 / 24.0, np.sinc(dth / (2 * np.pi)))
    mid = th + 0.5 * dth
    return np.stack(
        (x + chord * np.cos(mid), y + chord * np.sin(mid), th + dth), axis=-1
    )
