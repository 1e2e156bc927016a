"""A unicycle as a holonomic disc: its velocity, commands, and tracking error.

ORCA plans for discs that take any velocity at once. Alonso-Mora, Breitenmoser,
Rufli, Beardsley and Siegwart ("Optimal reciprocal collision avoidance for multiple
non-holonomic robots", DARS 2010; the same construction in their 2013 Springer
chapter) let a unicycle of eq. (1) of the report follow a *holonomic* velocity ``u``
with a bounded error and give ORCA a disc enlarged by that bound ``E``:

- to follow ``u = V (cos(x3 + phi), sin(x3 + phi))`` the vehicle turns at the constant
  rate ``v2 = phi / T_phi`` until it heads along ``u`` (after ``T_phi``), at the
  constant speed that keeps it nearest to the straight path ``x + u t`` at
  ``T_phi``::

      v1 = V (phi / 2) / tan(phi / 2),     v2 = phi / T_phi,
      T_phi = max(T, |phi| / v2_max),

  (the unicycle's arc ends at ``(v1 T_phi / phi) (sin phi, 1 - cos phi)`` in its own
  frame; ``v1`` above minimises its distance to ``V T_phi (cos phi, sin phi)``);
- the distance to the straight path is then largest at ``T_phi`` and stays constant
  after it::

      epsilon(u) = V T_phi |sin(phi / 2)|,

  so the vehicle stays within ``E`` of the holonomic disc's centre as long as
  ``V <= E / (T_phi |sin(phi / 2)|)``: the *admissible* holonomic velocities, a set
  that reaches ``v1_max`` straight ahead and ``sqrt(2) E / T`` sideways
  (:func:`drive_lines`: a polygon inscribed in it, as hard lines of the program).

The unicycle drives forward only (``v1 >= 0``): the speed above vanishes at
``phi = pi``.
"""

from __future__ import annotations

import numpy as np

from sandbox.behaviour.safety.orca_program import TINY, normalized
from sandbox.model.dynamics import wrap_angle

#: The admissible set's polygon: its corners at this many headings about the vehicle's
#: own (every 30 degrees from straight ahead).
CORNERS = 12


def speed_factor(phi: np.ndarray) -> np.ndarray:
    """``(phi / 2) / tan(phi / 2)``: the unicycle's speed over the holonomic one.

    1 straight ahead, ``pi / 4`` at a right angle, 0 straight behind.

    >>> speed_factor(np.array([0.0, np.pi / 2])).round(6).tolist()
    [1.0, 0.785398]
    """
    half = 0.5 * np.asarray(phi, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = half / np.tan(half)
    return np.where(np.abs(half) < 1e-8, 1.0, np.maximum(factor, 0.0))


def align_time(phi: np.ndarray, align: float, turn_max: np.ndarray) -> np.ndarray:
    """``T_phi = max(T, |phi| / v2_max)`` [s]: the time to head along ``u``."""
    with np.errstate(divide="ignore"):
        slowest = np.abs(phi) / turn_max
    return np.maximum(align, slowest)


def admissible_speed(
    phi: np.ndarray, error: float, align: float, turn_max: np.ndarray
) -> np.ndarray:
    """The largest holonomic speed [m/s] followed within ``error`` at the angle phi.

    ``E / (T_phi |sin(phi / 2)|)`` (inf straight ahead).

    >>> float(admissible_speed(np.array(np.pi), 0.1, 0.5, np.array(np.inf)))
    0.2
    """
    sine = np.abs(np.sin(0.5 * np.asarray(phi, dtype=float)))
    with np.errstate(divide="ignore"):
        return error / (align_time(phi, align, turn_max) * sine)


def holonomic_velocity(
    v1: np.ndarray,
    v2: np.ndarray,
    theta: np.ndarray,
    align: float,
    v_max: np.ndarray,
) -> np.ndarray:
    """The holonomic velocity a command ``(v1, v2)`` follows, within ``v_max``.

    The inverse of :func:`unicycle_commands` for a turn rate within ``v2_max``:
    ``phi = v2 T`` (within ``[-pi, pi]``), ``V = v1 / ((phi / 2) / tan(phi / 2))``,
    the speed kept within ``v_max`` (a command that turns a half turn in ``T`` or
    more follows a velocity behind the vehicle, at ``v_max``).

    Parameters
    ----------
    v1, v2 : ndarray, shape (n,) [m/s], [rad/s]
    theta : ndarray, shape (n,) [rad]
    align : float [s]
        ``T``.
    v_max : ndarray, shape (n,) [m/s]

    Returns
    -------
    ndarray, shape (n, 2) [m/s]
    """
    phi = np.clip(v2 * align, -np.pi, np.pi)
    factor = speed_factor(phi)
    speed = np.where(
        np.abs(v1) >= factor * v_max, np.sign(v1) * v_max, v1 / np.maximum(factor, TINY)
    )
    out = np.empty((len(theta), 2))
    out[:, 0] = speed * np.cos(theta + phi)
    out[:, 1] = speed * np.sin(theta + phi)
    return out


def unicycle_commands(
    u: np.ndarray, theta: np.ndarray, align: float, turn_max: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The commands ``(v1, v2)`` that follow the holonomic velocity ``u``.

    ``v1 = V (phi / 2) / tan(phi / 2)``, ``v2 = phi / T_phi`` with ``phi`` the angle
    of ``u`` from the heading (in ``[-pi, pi)``); a velocity of zero stops the vehicle
    and holds its heading.

    Parameters
    ----------
    u : ndarray, shape (n, 2) [m/s]
    theta : ndarray, shape (n,) [rad]
    align : float [s]
        ``T``.
    turn_max : ndarray, shape (n,) [rad/s]
        ``v2_max`` (inf: unlimited).

    Returns
    -------
    v1 : ndarray, shape (n,) [m/s]
    v2 : ndarray, shape (n,) [rad/s]

    Examples
    --------
    A velocity of 1 m/s to the left of a vehicle heading along x1, T = 0.5 s: turn
    at pi/2 / 0.5 = pi rad/s, at pi/4 m/s.

    >>> v1, v2 = unicycle_commands(np.array([[0.0, 1.0]]), np.array([0.0]), 0.5,
    ...                            np.array([np.inf]))
    >>> round(float(v1[0]), 6), round(float(v2[0]), 6)
    (0.785398, 3.141593)
    """
    speed = np.sqrt(u[:, 0] * u[:, 0] + u[:, 1] * u[:, 1])
    moving = speed > TINY
    phi = wrap_angle(np.arctan2(u[:, 1], u[:, 0]) - theta)
    phi = np.where(moving, phi, 0.0)
    v1 = speed * speed_factor(phi)
    v2 = phi / align_time(phi, align, turn_max)
    return v1, v2


def drive_lines(
    theta: np.ndarray,
    v_max: np.ndarray,
    error: float,
    align: float,
    turn_max: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The polygon of admissible holonomic velocities, as lines (hard, the drive's).

    Its corners lie on the boundary of the admissible set at :data:`CORNERS` angles
    ``phi`` about the heading, at the speed ``min(v_max, E / (T_phi |sin(phi / 2)|))``,
    counter-clockwise; each edge's line has the polygon on its left. The edges are
    chords of the set, so the polygon lies within it.

    Parameters
    ----------
    theta : ndarray, shape (n,) [rad]
    v_max : ndarray, shape (n,) [m/s]
    error : float [m]
        ``E``.
    align : float [s]
        ``T``.
    turn_max : ndarray, shape (n,) [rad/s]

    Returns
    -------
    point, direction : ndarray, shape (n, CORNERS, 2)
        Each edge's first corner [m/s] and unit direction [1].
    """
    phi = -np.pi + (2.0 * np.pi / CORNERS) * np.arange(1, CORNERS + 1)  # to +pi
    speed = np.minimum(
        v_max[:, None],
        admissible_speed(phi[None, :], error, align, turn_max[:, None]),
    )
    angle = theta[:, None] + phi[None, :]
    corner = np.empty((len(theta), CORNERS, 2))
    corner[..., 0] = speed * np.cos(angle)
    corner[..., 1] = speed * np.sin(angle)
    following = np.roll(corner, -1, axis=1)
    return corner, normalized(following - corner)
