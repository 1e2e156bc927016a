"""An ordering for the CBF filter's right-hand rule (``safety.priority``).

The right-hand rule (``pass_right``,
:func:`sandbox.behaviour.safety.right_hand.stall_turn`) treats every vehicle the same,
so two vehicles in a standoff that is symmetric under the half turn about its centre
(the door of ``scenarios/safety/door.yaml``: a gap one vehicle wide, passed in both
directions) turn alike and stall alike: only the rounding of the arithmetic breaks the
tie. A priority orders the two: a stalled vehicle whose near vehicles all rank below
it *holds its course* (it is not turned, and waits for the way to clear), while a
stalled vehicle outranked by a near one *yields* (it turns right, as before). The
barriers and bounds are untouched, so is safety; only where the nearest safe velocity
is sought moves, for the vehicles that yield.

Orders (``priority``):

- ``none`` (the key left out, the default): no ordering; every stalled vehicle turns
  (every existing run keeps its bytes, its written ``scenario.yaml`` included);
- ``index``: the vehicle listed first in its world outranks the ones after it. Fixed
  in time, so a standoff is never re-decided half-way (like the fixed order of
  prioritized planning), and a group listed first passes a door first;
- ``slot_distance``: the vehicle farther from its formation slot outranks the nearer
  one (the one with more way to go, which sets when the formation settles, goes
  first; the nearer one can afford to wait), distances within :data:`SLOT_TIE` of each
  other counting as a tie, broken by ``index``. A symmetric standoff is a tie, so it
  is decided by the index, never by rounding.

"Near" is within the filter's ``range``: the neighbours whose barriers can bind, and
so cut a vehicle's speed (at speed the cut starts metres before the barrier's ``D``).
Vehicles believed failed or driven open loop do not yield to anyone: every filtered
vehicle near one yields to it. A vehicle stalled by obstacles alone turns as before,
and so does a holder whose filtered velocity presses on an obstacle's condition
(:func:`holds`): holding there would wait for no one.

Ranks are compared within a pair only, and pairs never cross worlds; the index is the
row within its world, so a batched call of K worlds gives each world what it gets
alone.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.safety.braking import obstacle_normals
from sandbox.behaviour.safety.qp import TOLERANCE
from sandbox.plugins.registration import Param

if TYPE_CHECKING:
    from sandbox.behaviour.safety.state import CBFState
    from sandbox.plugins.contexts import FilterContext

#: Slot distances closer than this are a tie (decided by the index) [m]: far above
#: the rounding of symmetric states (1e-15 m), below a vehicle's length.
SLOT_TIE = 0.01

PRIORITY = Param(
    "choice",
    None,
    doc="An ordering for the right-hand rule, which breaks symmetric standoffs (a "
    "door passed both ways): a stalled vehicle outranking every near vehicle holds "
    "its course, the others yield (turn right). none: no ordering (every stalled "
    "vehicle turns); index: the vehicle listed first goes first; slot_distance: "
    "the one farther from its slot goes first, ties (within 1 cm) by index "
    "(left out: none, and the run's scenario.yaml does not list the key)",
    choices=("none", "slot_distance", "index"),
)


def outranks(
    kind: str, i: np.ndarray, j: np.ndarray, index: np.ndarray, far: np.ndarray
) -> np.ndarray:
    """Whether vehicle ``i`` outranks vehicle ``j``, for each pair.

    Parameters
    ----------
    kind : str
        ``index`` or ``slot_distance``.
    i, j : ndarray, shape (k,) int
        The rows of each pair (of one world).
    index : ndarray, shape (n,) int
        Each row's index within its world.
    far : ndarray, shape (n,) [m]
        Each row's distance to its slot (``slot_distance`` only).

    Returns
    -------
    ndarray, shape (k,) bool
        Exactly one of ``outranks(i, j)`` and ``outranks(j, i)`` holds for ``i != j``.

    >>> idx = np.arange(3)
    >>> far = np.array([1.0, 1.005, 3.0])
    >>> outranks("slot_distance", np.array([0, 1, 0]), np.array([1, 0, 2]), idx,
    ...          far).tolist()
    [True, False, False]
    """
    first = index[i] < index[j]
    if kind == "index":
        return first
    gap = far[i] - far[j]
    return np.where(np.abs(gap) <= SLOT_TIE, first, gap > 0)


def holding(
    state: CBFState, ctx: FilterContext, filtered: np.ndarray
) -> tuple[np.ndarray, int]:
    """The vehicles that may hold their course at a stall, and the obstacles' rows.

    A filtered vehicle may hold when it has a near filtered vehicle and outranks every
    near vehicle (:func:`outranks`; failed and open-loop ones outrank it); it holds
    unless an obstacle's condition presses on it (:func:`holds`).

    Parameters
    ----------
    state : CBFState
    ctx : FilterContext
        ``slot`` gives the slots (``slot_distance``).
    filtered : ndarray, shape (n,) bool
        The vehicles the filter drives.

    Returns
    -------
    hold : ndarray, shape (n,) bool
    walls : int
        How many conditions of the step are toward obstacles (they come last).
    """
    n, look = len(ctx.pos), state.look
    theta = ctx.theta if ctx.seen is None else ctx.seen[:, 2]
    centre = ctx.pos if ctx.seen is None else ctx.seen[:, :2]
    p = centre + look * np.stack((np.cos(theta), np.sin(theta)), -1)
    hold = np.zeros(n, dtype=bool)
    own = ctx.pos + look * np.stack((np.cos(ctx.theta), np.sin(ctx.theta)), -1)
    near = obstacle_normals(state, ctx, own, filtered)
    walls = 0 if near is None else len(near[0])
    i, j, _ = state.neighbours.near(p)  # within range, as the barriers' pairs
    if not len(i):
        return hold, walls
    me, other = np.concatenate((i, j)), np.concatenate((j, i))
    keep = np.flatnonzero(filtered[me])
    me, other = me[keep], other[keep]
    per_world = n // max(ctx.worlds, 1)
    index = np.arange(n) % per_world
    if state.priority == "slot_distance" and ctx.slot is not None:
        far = np.hypot(*(ctx.pos - ctx.slot).T)
        far = np.where(np.isfinite(far), far, 0.0)
    else:
        far = np.zeros(n)
    wins = outranks(state.priority, me, other, index, far) & filtered[other]
    has_peer = np.zeros(n, dtype=bool)
    has_peer[me[filtered[other]]] = True
    loses = np.zeros(n, dtype=bool)
    loses[me[~wins]] = True
    hold = has_peer & ~loses
    return hold, walls


def holds(
    hold: np.ndarray, wall: np.ndarray, mat: np.ndarray, off: np.ndarray, z: np.ndarray
) -> np.ndarray:
    """Which of a group's vehicles hold: ``hold`` and no obstacle's condition binding.

    Parameters
    ----------
    hold : ndarray, shape (k,) bool
        The vehicles that may hold (:func:`holding`).
    wall : ndarray, shape (k, c) bool
        Which of each vehicle's conditions ``mat z <= off`` are toward obstacles.
    mat : ndarray, shape (k, c, 2)
    off : ndarray, shape (k, c) [m/s]
    z : ndarray, shape (k, 2) [m/s]
        The filtered ``(v1, l v2)``.

    Returns
    -------
    ndarray, shape (k,) bool
        A vehicle held back by an obstacle (a post, a wall) turns as without an order:
        holding there would wait for no one.
    """
    pressed = np.einsum("kcd,kd->kc", mat, z) >= off - TOLERANCE
    return hold & ~np.any(wall & pressed, axis=1)
