"""The CBF filter's right-hand rule out of stalls (``safety: {pass_right: ...}``).

Split from :mod:`sandbox.behaviour.safety.cbf`, whose docstring gives the rule: a
vehicle whose filtered look-ahead velocity keeps less than half of its nominal one
turns that nominal velocity to its right (:func:`stall_turn`) and is filtered again
toward it, the barriers and bounds unchanged (:func:`pass_right`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.safety.braking import columns
from sandbox.behaviour.safety.priority import holds
from sandbox.behaviour.safety.qp import solve
from sandbox.model.barriers import MIN_SPEED
from sandbox.model.dynamics import CLIP

if TYPE_CHECKING:
    from sandbox.behaviour.safety.state import CBFState

#: The right-hand rule (``pass_right``): a vehicle is stalled when its filtered
#: look-ahead speed keeps less than STALL_START of its nominal speed, fully at
#: STALL_FULL [1]; the turn fades in proportion below a nominal speed STALL_SPEED
#: [m/s].
STALL_START = 0.5
STALL_FULL = 0.1
STALL_SPEED = 0.2


def stall_turn(z0: np.ndarray, z: np.ndarray, angle: float) -> np.ndarray:
    """The right-hand rule's turn [rad] of each nominal velocity, from the cut.

    A vehicle is stalled by the filter when the filtered velocity of its look-ahead
    point keeps less than :data:`STALL_START` of the nominal speed: the turn ramps
    smoothly (a smoothstep) from 0 there to ``angle`` at :data:`STALL_FULL`, and in
    proportion to the nominal speed below :data:`STALL_SPEED` (a vehicle at its slot,
    whose nominal speed vanishes, is never turned).

    Parameters
    ----------
    z0, z : ndarray, shape (k, 2) [m/s]
        Nominal and filtered ``(v1, l v2)``.
    angle : float [rad]
        The largest turn (``pass_right``).

    Returns
    -------
    ndarray, shape (k,) [rad]

    >>> z0 = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.1, 0.0]])
    >>> z = np.array([[0.6, 0.0], [0.3, 0.0], [0.0, 0.0], [0.0, 0.0]])
    >>> np.round(stall_turn(z0, z, np.pi / 2), 4).tolist()
    [0.0, 0.7854, 1.5708, 0.7854]
    """
    nominal = np.hypot(z0[:, 0], z0[:, 1])
    kept = np.hypot(z[:, 0], z[:, 1])
    cut = 1.0 - kept / np.maximum(nominal, MIN_SPEED)
    x = CLIP((cut - (1.0 - STALL_START)) / (STALL_START - STALL_FULL), 0.0, 1.0)
    ramp = x * x * (3.0 - 2.0 * x)
    return angle * ramp * np.minimum(nominal / STALL_SPEED, 1.0)


def pass_right(
    state: CBFState,
    z0: np.ndarray,
    z: np.ndarray,
    slack: np.ndarray,
    mat: np.ndarray,
    off: np.ndarray,
    soft: np.ndarray,
    hold: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Filter again, toward the nominal velocities turned right where stalled.

    The barriers and bounds are the same (``mat``, ``off``, ``soft``), so is safety;
    only the point the nearest safe velocity is sought to moves. ``hold``: the
    vehicles whose priority outranks every near vehicle's, and which rows are of
    obstacles; those not pressed on an obstacle's condition are not turned.
    """
    turn = stall_turn(z0, z, state.pass_right)
    if hold is not None:
        turn[holds(hold[0], hold[1], mat, off, z)] = 0.0
    rows = (turn > 0).nonzero()[0]
    if len(rows) == 0:
        return z, slack
    c, s = np.cos(turn[rows]), np.sin(turn[rows])
    zr = z0[rows]
    # clockwise by the turn: (v1, l v2) rotated toward (0, -|z0|), the right
    nominal = columns(c * zr[:, 0] + s * zr[:, 1], c * zr[:, 1] - s * zr[:, 0])
    z, slack = z.copy(), slack.copy()
    z[rows], slack[rows] = solve(nominal, mat[rows], off[rows], soft[rows])
    return z, slack
