"""What the step-wise API shows and accepts: observations and per-step overrides.

:meth:`sandbox.loop.simulation.Simulation.observe` returns an :class:`Observation`
(copies of the fleet arrays at the current time);
:meth:`~sandbox.loop.simulation.Simulation.step` accepts ``commands`` and ``targets``
overrides, either as a mapping from vehicle name to a pair or as an ``(n, 2)`` array
with NaN rows for "no override", which :func:`override_rows` turns into one array and
one mask.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from sandbox.behaviour.ranges import NearObstacles, near_obstacles

#: An override as the user gives it: ``{name: (a, b)}`` or an (n, 2) array (NaN: none).
Overrides = Mapping[str, Sequence[float]] | np.ndarray | None


@dataclass(frozen=True)
class Observation:
    """The fleet at one control step, as the controller sees it before acting.

    Every array is a copy: changing it changes nothing in the simulation.

    Attributes
    ----------
    t : float [s]
        Simulated time.
    names : tuple of str, length n
        Vehicle names, in scenario order (the row order of every array).
    pose : ndarray, shape (n, 3)
        ``(x1, x2, x3)`` [m, m, rad], x3 unwrapped.
    vel : ndarray, shape (n, 2) [m/s]
        Measured velocities.
    chi : ndarray, shape (n, 2) [m/s]
        Extension states of eqs. (4)/(6).
    slot : ndarray, shape (n, 2) [m]
        Each vehicle's place by its formation law (the leader's: the reference point);
        NaN where undefined (an open-loop vehicle).
    slot_vel : ndarray, shape (n, 2) [m/s]
        The velocity the law gives with the slot, ``x_ref'`` of eq. (6): the
        reference's derivative, or the backward-difference estimate of eq. (8) (the
        leader's) or (18) (the slot's own); the built-in controller's feed-forward.
        NaN where the slot is.
    slot_acc : ndarray, shape (n, 2) [m/s^2]
        The acceleration the law gives with the slot, ``x_ref''`` of eq. (6) (eqs.
        (9), (19) where estimated).
    target : ndarray, shape (n, 2) [m]
        The point the built-in controller will track this period: the slot shifted by
        the recovery strategy (before any override given to :meth:`step`).
    mode : ndarray, shape (n,), int8
        ``run.MODE_*`` codes the built-in stack plans for this period (``formation``,
        ``avoid``, ``failed``); ``external`` appears in the recorded run for the periods
        a vehicle was overridden.
    failed : ndarray, shape (n,), bool
        Whether a failure is active on the vehicle.
    ranges : ndarray, shape (n, B) [m], or None
        The range sensor's readings (``sensors.range``): from each vehicle's centre
        along each beam, ``max_range`` where nothing is hit, NaN for a vehicle (or a
        beam) without a sensor; None when no vehicle has one.
    beam_angles : ndarray, shape (n, B) [rad], or None
        Each beam's angle about the vehicle's heading, from ``-fov/2`` (right) to
        ``+fov/2`` (left).
    platoon : tuple of str or None
        With ``platoons:``, the name of each vehicle's platoon; None: one platoon.
    near : tuple or None
        What :attr:`obstacles` is computed from when first read (the obstacle field,
        the obstacles, the positions and each vehicle's radius); set by the loop.
    """

    t: float
    names: tuple[str, ...]
    pose: np.ndarray
    vel: np.ndarray
    chi: np.ndarray
    slot: np.ndarray
    slot_vel: np.ndarray
    slot_acc: np.ndarray
    target: np.ndarray
    mode: np.ndarray
    failed: np.ndarray
    ranges: np.ndarray | None = None
    beam_angles: np.ndarray | None = None
    platoon: tuple[str, ...] | None = None
    near: Any = field(default=None, repr=False, compare=False)

    @cached_property
    def obstacles(self) -> NearObstacles | None:
        """The obstacles within each vehicle's ``max_range``, from the map.

        One row per (vehicle, obstacle): the obstacle's kind, its nearest surface
        point and the distance to it (:class:`~sandbox.behaviour.ranges.
        NearObstacles`); vehicles without a range sensor use ``recovery.R``. None for
        an observation made without the simulation's obstacles.
        """
        if self.near is None:
            return None
        return near_obstacles(*self.near)

    @property
    def n(self) -> int:
        """Number of vehicles."""
        return len(self.names)

    def index(self, name: str) -> int:
        """Row of vehicle ``name`` in every array."""
        return self.names.index(name)


def override_rows(
    values: Overrides, names: Sequence[str], what: str
) -> tuple[np.ndarray, np.ndarray] | None:
    """One ``(n, 2)`` float array and an ``(n,)`` mask of the overridden rows.

    Parameters
    ----------
    values : mapping of str to pair, or ndarray of shape (n, 2), or None
        By vehicle name, or by row with NaN rows for "no override".
    names : sequence of str
        Vehicle names, in row order.
    what : str
        ``"commands"`` or ``"targets"``, for error messages.

    Returns
    -------
    (rows, mask) or None
        None when nothing is overridden.

    Raises
    ------
    ValueError
        An unknown vehicle name (with the closest names), a value that is not a pair
        of finite numbers, a wrongly shaped array, or a row with one NaN.
    """
    if values is None:
        return None
    n = len(names)
    if isinstance(values, Mapping):
        if not values:
            return None
        rows = np.full((n, 2), np.nan)
        index = {name: i for i, name in enumerate(names)}
        for name, pair in values.items():
            if name not in index:
                close = difflib.get_close_matches(str(name), names, n=3)
                hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
                raise ValueError(
                    f"{what}: unknown vehicle {name!r} (vehicles: "
                    f"{', '.join(names)}){hint}"
                )
            try:
                a, b = (float(x) for x in pair)
            except (TypeError, ValueError):
                raise ValueError(
                    f"{what}[{name!r}]: expected 2 numbers, got {pair!r}"
                ) from None
            if not (np.isfinite(a) and np.isfinite(b)):
                raise ValueError(
                    f"{what}[{name!r}]: expected 2 finite numbers, got {pair!r}"
                )
            rows[index[name]] = a, b
    else:
        rows = np.array(values, dtype=float)
        if rows.shape != (n, 2):
            raise ValueError(
                f"{what}: expected a mapping by vehicle name or an array of shape "
                f"({n}, 2), got shape {rows.shape}"
            )
        nan = np.isnan(rows)
        half = nan[:, 0] != nan[:, 1]
        if half.any():
            i = int(np.flatnonzero(half)[0])
            raise ValueError(
                f"{what}: row {i} ({names[i]!r}) has one NaN; give both numbers "
                "or NaN in both for no override"
            )
        if np.isinf(rows).any():
            i = int(np.flatnonzero(np.isinf(rows).any(axis=1))[0])
            raise ValueError(f"{what}: row {i} ({names[i]!r}) is not finite")
    mask = ~np.isnan(rows[:, 0])
    if not mask.any():
        return None
    return rows, mask
