"""The divergence check of the simulation loop: a state that no physics can mean.

A run whose state turns non-finite, or runs beyond :data:`DIVERGED_POSITION` or
:data:`DIVERGED_SPEED`, ends with status ``diverged`` (see
:meth:`sandbox.loop.simulation.Simulation._sense`, which checks all worlds at once
and then each world alone). Its fast path, whether a fleet is clearly healthy, is one
C call where the optional extension ``sandbox.loop._period`` is built.
"""

from __future__ import annotations

import numpy as np

from sandbox import accel
from sandbox.loop.state import Fleet

#: A state beyond these bounds is reported as ``diverged`` [m], [m/s].
DIVERGED_POSITION = 1e6
DIVERGED_SPEED = 1e3


class RowsView:
    """Some rows of the stacked fleet (one world's), for :func:`diverged`."""

    def __init__(self, fleet: Fleet, rows: slice) -> None:
        self.pos, self.theta = fleet.pos[rows], fleet.theta[rows]
        self.vel, self.chi = fleet.vel[rows], fleet.chi[rows]


def _largest(a: np.ndarray) -> float:
    """``np.max(a)`` (NaN if any is NaN), without the wrapper's checks."""
    return np.maximum.reduce(a, axis=None) if a.size else -np.inf


def healthy(fleet: Fleet | RowsView) -> bool:
    """Whether the fleet is clearly healthy: the fast path of :func:`diverged`.

    Every position within :data:`DIVERGED_POSITION`, every heading finite, every
    speed and extension within :data:`DIVERGED_SPEED` (a little less); a NaN fails
    every comparison. One C call where it can read the arrays, else one reduction
    per array.
    """
    vel, chi = fleet.vel, fleet.chi
    speed2 = (0.999 * DIVERGED_SPEED) ** 2
    period = accel.module("period")
    if period is not None:
        try:
            return period.healthy(
                fleet.pos, fleet.theta, vel, chi, DIVERGED_POSITION, speed2
            )
        except (BufferError, TypeError, ValueError):  # not float64 C arrays
            pass
    return bool(
        _largest(np.abs(fleet.pos)) <= DIVERGED_POSITION
        and _largest(np.abs(fleet.theta)) < np.inf
        and _largest(vel[:, 0] * vel[:, 0] + vel[:, 1] * vel[:, 1]) <= speed2
        and _largest(chi[:, 0] * chi[:, 0] + chi[:, 1] * chi[:, 1]) <= speed2
    )


def diverged(fleet: Fleet | RowsView) -> tuple[int, str] | None:
    """First vehicle whose state is non-finite or beyond the bounds, with the reason."""
    if healthy(fleet):
        return None
    finite = (
        np.isfinite(fleet.pos).all(axis=1)
        & np.isfinite(fleet.theta)
        & np.isfinite(fleet.chi).all(axis=1)
    )
    if not finite.all():
        return int(np.flatnonzero(~finite)[0]), "non-finite state"
    far = np.abs(fleet.pos).max(axis=1) > DIVERGED_POSITION
    fast = np.hypot(fleet.vel[:, 0], fleet.vel[:, 1]) > DIVERGED_SPEED
    bad = far | fast | (np.hypot(fleet.chi[:, 0], fleet.chi[:, 1]) > DIVERGED_SPEED)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        return i, "position beyond 1e6 m" if far[i] else "speed beyond 1e3 m/s"
    return None
