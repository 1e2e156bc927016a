"""Deadlocks of a recorded run: healthy vehicles trapped short of their slots.

A healthy vehicle (no failure active, a slot defined) farther than
``metrics.deadlock_distance`` (``d``, default 0.5 m) from its slot is *trapped* over a
stretch of the run when either

- it is **stopped**: its speed stays below ``metrics.deadlock_speed`` (default 1 cm/s)
  for at least ``metrics.deadlock_time`` (``T``, default 2 s); or
- it is **creeping**: it makes no headway, whatever its speed. With ``e(t)`` its
  distance to its slot and ``f`` = ``metrics.deadlock_progress`` (default 0.5; 0 turns
  this rule off), a window ``[t - T, t]`` is without headway when ``e > d`` at every
  sample of it and ``e(t) > e(t - T) - f d`` (0.5 gives 0.25 m in 2 s). A vehicle
  creeping along an obstacle, circling, or shuffling in a jam makes no headway; one
  driving to its slot at an eighth of a metre a second (with 0.5) does. The windows
  without headway that overlap make a stretch, dated from the start of its first
  window. Which stretches count is ``metrics.deadlock_creeping``: ``to_end`` (the
  default) only the one that lasts to the end of the run, the window ending at the
  last sample among them (a vehicle still making no headway when the run ends: a
  platoon held up by obstacles and catching up with its moving slots is not
  trapped, one left behind is); ``any`` every stretch.

Stalls of several vehicles that overlap in time are one deadlock (two vehicles nose to
nose, a ring of vehicles jammed at the centre of a swap). Each deadlock is written to
``metrics.json`` as ``{vehicles, t, duration}``: the names of the vehicles involved (in
scenario order), the time the first of them got trapped [s] and the time from then to
the end of the last stall [s] (up to the end of the run when a stall lasts until
then).

Speeds and distances are read from the recorded positions, so they read the physics,
not the commands: a vehicle pressing into another one at full command but not moving is
trapped.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.geometry.planar import norms

#: Defaults of the ``metrics:`` keys that define a deadlock.
DEADLOCK_SPEED = 0.01  # [m/s]
DEADLOCK_TIME = 2.0  # [s]
DEADLOCK_DISTANCE = 0.5  # [m]
DEADLOCK_PROGRESS = 0.5  # of deadlock_distance, per deadlock_time (0: rule off)
#: Which stretches without headway count: the one lasting to the end, or any.
DEADLOCK_CREEPING = "to_end"
CREEPING = ("to_end", "any")


def stuck_samples(
    t: np.ndarray,
    pos: np.ndarray,
    slot: np.ndarray,
    failed: np.ndarray,
    speed: float = DEADLOCK_SPEED,
    distance: float = DEADLOCK_DISTANCE,
    error: np.ndarray | None = None,
) -> np.ndarray:
    """Whether each vehicle is stuck at each recorded sample, shape (T, n) bool.

    The speed of sample ``k`` is ``|x(k+1) - x(k)| / (t(k+1) - t(k))`` (the last
    sample takes the speed of the interval before it).

    Parameters
    ----------
    t : ndarray (T,) [s]
    pos : ndarray (T, n, 2) [m]
    slot : ndarray (T, n, 2) [m]
        NaN where a vehicle has no slot (never stuck).
    failed : ndarray (T, n) bool
        Vehicles with an active failure (never stuck).
    speed : float [m/s]
    distance : float [m]
    error : ndarray (T, n) [m], optional
        The distances ``|pos - slot|``, where the caller has them already.
    """
    T = len(t)
    if T < 2:
        return np.zeros(pos.shape[:2], dtype=bool)
    step = norms(np.diff(pos, axis=0))
    dt = np.diff(t)[:, None]
    v = np.empty(pos.shape[:2])
    v[:-1] = step / np.where(dt > 0, dt, np.inf)
    v[-1] = v[-2]
    if error is None:
        error = norms(pos - slot)
    with np.errstate(invalid="ignore"):
        far = error > distance  # NaN (no slot) compares False
    return (v < speed) & far & ~failed


def no_headway(
    t: np.ndarray,
    pos: np.ndarray,
    slot: np.ndarray,
    failed: np.ndarray,
    duration: float = DEADLOCK_TIME,
    distance: float = DEADLOCK_DISTANCE,
    progress: float = DEADLOCK_PROGRESS,
    error: np.ndarray | None = None,
) -> list[list[tuple[float, float]]]:
    """Per vehicle, the ``(t start, t end)`` stretches where it makes no headway.

    Sample ``k`` ends a window without headway when the window ``[t_k - duration,
    t_k]`` lies within the run, the vehicle is healthy and farther than ``distance``
    from its slot at every sample of it, and its distance at ``t_k`` is more than the
    distance at the window's start minus ``progress * distance``. The stretches are the
    unions of such windows.

    Parameters
    ----------
    t, pos, slot, failed
        As for :func:`stuck_samples`.
    duration : float [s]
    distance : float [m]
    progress : float
        The headway expected over ``duration``, as a fraction of ``distance``; 0 turns
        the rule off.
    error : ndarray (T, n) [m], optional
        As for :func:`stuck_samples`.
    """
    T, n = pos.shape[:2]
    out: list[list[tuple[float, float]]] = [[] for _ in range(n)]
    if T < 2 or progress <= 0:  # 0: the headway rule is off (stopped vehicles only)
        return out
    if error is None:
        error = norms(pos - slot)
    with np.errstate(invalid="ignore"):
        far = (error > distance) & ~failed  # NaN (no slot) compares False
    start = np.searchsorted(t, t - duration - 1e-9)  # first sample of each window
    full = t - t[0] >= duration - 1e-9
    bad = np.concatenate((np.zeros((1, n), dtype=np.int64), np.cumsum(~far, axis=0)))
    # Every vehicle's windows at once: far at every sample of the window, and the
    # distance at its end more than at its start less the headway.
    always_far = bad[1:] - bad[start] == 0
    with np.errstate(invalid="ignore"):
        stalled = error > error[start] - progress * distance
    ending = full[:, None] & always_far & stalled
    for i in np.count_nonzero(ending, axis=0).nonzero()[0]:
        ends = np.flatnonzero(ending[:, i])
        out[i] = _union(t[start[ends]], t[ends])
    return out


def _union(a: np.ndarray, b: np.ndarray) -> list[tuple[float, float]]:
    """The union of the windows ``[a_k, b_k]``, ``b`` increasing, as ``(start, end)``.

    A window that starts no later than the one before it ends joins it (the stretch
    so far ends at the last window's end, ``b`` increasing); the others start a new
    stretch.

    >>> _union(np.array([0.0, 1.0, 5.0]), np.array([2.0, 3.0, 6.0]))
    [(0.0, 3.0), (5.0, 6.0)]
    """
    if not len(a):
        return []
    first = np.concatenate(([True], a[1:] > b[:-1])).nonzero()[0]
    last = np.concatenate((first[1:] - 1, [len(b) - 1]))
    return list(zip(a[first].tolist(), b[last].tolist(), strict=True))


def _stretches(stuck: np.ndarray) -> list[tuple[int, int]]:
    """``(first, last)`` sample indices of each run of True in a boolean vector."""
    edges = np.diff(np.concatenate(([0], stuck.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def find_deadlocks(
    t: np.ndarray,
    pos: np.ndarray,
    slot: np.ndarray,
    failed: np.ndarray,
    names: list[str],
    speed: float = DEADLOCK_SPEED,
    duration: float = DEADLOCK_TIME,
    distance: float = DEADLOCK_DISTANCE,
    progress: float = DEADLOCK_PROGRESS,
    creeping: str = DEADLOCK_CREEPING,
) -> list[dict[str, Any]]:
    """The deadlocks of a run, as written to ``metrics.json``.

    Parameters
    ----------
    t, pos, slot, failed
        As for :func:`stuck_samples`.
    names : list of str
        Vehicle names, in scenario order.
    speed : float [m/s]
        Speed below which a vehicle is stopped.
    duration : float [s]
        Shortest stall that counts.
    distance : float [m]
        Distance to the slot beyond which a stopped vehicle is short of it.
    progress : float
        Headway over ``duration`` below which a moving vehicle is trapped, as a
        fraction of ``distance`` (see :func:`no_headway`).
    creeping : {"to_end", "any"}
        Which stretches without headway count: only one lasting to the last sample,
        or every one.

    Returns
    -------
    list of dict
        ``{vehicles, t, duration}`` per deadlock, in order of time.

    Examples
    --------
    Two vehicles stopped 2 m from their slots from t = 1 s to the end (5 s):

    >>> t = np.arange(0.0, 5.01, 0.5)
    >>> x = np.minimum(t, 1.0)
    >>> pos = np.stack([np.stack([x, 0 * x], -1), np.stack([-x, 0 * x], -1)], 1)
    >>> slot = np.tile([[3.0, 0.0], [-3.0, 0.0]], (len(t), 1, 1))
    >>> find_deadlocks(t, pos, slot, np.zeros((len(t), 2), bool), ["a", "b"])
    [{'vehicles': ['a', 'b'], 't': 1.0, 'duration': 4.0}]
    """
    error = norms(pos - slot)
    stuck = stuck_samples(t, pos, slot, failed, speed, distance, error)
    stalls = []  # (t start, t end, vehicle)
    for i in np.count_nonzero(stuck, axis=0).nonzero()[0].tolist():
        for a, b in _stretches(stuck[:, i]):
            if t[b] - t[a] >= duration - 1e-9:
                stalls.append((float(t[a]), float(t[b]), i))
    if creeping not in CREEPING:
        raise ValueError(f"creeping: expected one of {CREEPING}, got {creeping!r}")
    end = float(t[-1]) if len(t) else 0.0
    for i, spans in enumerate(
        no_headway(t, pos, slot, failed, duration, distance, progress, error)
    ):
        if creeping == "to_end":
            spans = [(a, b) for a, b in spans if b >= end]
        stalls.extend((a, b, i) for a, b in spans)
    stalls.sort()
    groups: list[list[Any]] = []  # [start, end, set of vehicles]
    for a, b, i in stalls:
        if groups and a <= groups[-1][1]:
            groups[-1][1] = max(groups[-1][1], b)
            groups[-1][2].add(i)
        else:
            groups.append([a, b, {i}])
    return [
        {
            "vehicles": [names[i] for i in sorted(g[2])],
            "t": round(g[0], 6),
            "duration": round(g[1] - g[0], 6),
        }
        for g in groups
    ]
