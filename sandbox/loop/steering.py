"""The cars of the loop: their controller rows, their steering, their record.

A fleet may hold cars (``model: bicycle``, :mod:`sandbox.model.bicycle`) among its
unicycles, in any world of a batch. The loop leaves the unicycles' rows as they are
and adds, where some row is a car (both :meth:`CarDrive.build` and
:meth:`SteeringRecord.build` give None otherwise):

1. in the act stage (:class:`~sandbox.loop.acting.Acting`, which holds the
   :class:`CarDrive`), after the controller (:meth:`CarDrive.control`): the cars'
   rows computed again by :func:`~sandbox.model.bicycle.car_controller_step`, with
   the car's anti-windup in place of the unicycle's turn limit;
2. there too, after the safety filter, the schedules and the overrides, and again
   after the failures for the rows they hit (:meth:`CarDrive.steer`): the asked
   turn rate made a steering angle within the car's limits, and the turn rate the
   car executes, ``v1 tan(delta) / L``; every command a car executes (a filter's, a
   user's, a failure's) is one it can. The steering angles of the period are
   returned with the commands and become the fleet's ``steer``;
3. the steering angle of each sample (:class:`SteeringRecord`, written by the loop
   beside its record), given to each world's :class:`~sandbox.run.record.Run` as
   ``steer`` where the world has a car (NaN on its unicycles' rows).

Every step is elementwise over rows: a world's cars have the numbers they have alone.
"""

from __future__ import annotations

import numpy as np

from sandbox.loop.state import Fleet
from sandbox.model.bicycle import CarLimits, car_controller_step, steer_commands
from sandbox.model.flatness import Gains


class CarDrive:
    """The car rows of a loop's fleet: their gains and limits, fixed at build.

    Parameters
    ----------
    fleet : Fleet
        The stacked fleet (rows world after world) with at least one car.
    dt : float [s]
        The control period.
    """

    def __init__(self, fleet: Fleet, dt: float) -> None:
        #: The car rows of the loop's arrays.
        self.rows = rows = np.flatnonzero(fleet.bicycle)
        self.dt = dt
        self.gains = Gains(
            **{k: getattr(fleet.gains, k)[rows] for k in ("k1", "k2", "k3", "k4", "kp")}
        )
        self.limits = CarLimits(
            fleet.wheelbase[rows],
            fleet.max_steer[rows],
            fleet.max_steer_rate[rows],
            fleet.v1_max[rows],
            fleet.accel_max[rows],
            fleet.v2_max[rows],
        )
        #: Whether every row is a car (then no row is copied out).
        self.every = len(rows) == len(fleet.bicycle)

    @classmethod
    def build(cls, fleet: Fleet, dt: float) -> CarDrive | None:
        """The loop's cars, or None where every row is a unicycle."""
        if not np.count_nonzero(fleet.bicycle):
            return None
        return cls(fleet, dt)

    def control(
        self,
        fleet: Fleet,
        target: np.ndarray,
        v_ref: np.ndarray,
        a_ref: np.ndarray,
        chi_next: np.ndarray,
        v1: np.ndarray,
        v2: np.ndarray,
    ) -> None:
        """The cars' rows of the controller's outputs, computed again, in place.

        :func:`~sandbox.model.bicycle.car_controller_step` on the car rows of the
        period's state and targets; ``chi_next``, ``v1`` and ``v2`` (the
        controller's outputs of this period, shape (N, ...)) take its results on
        those rows.
        """
        r = slice(None) if self.every else self.rows
        nxt, u1, u2 = car_controller_step(
            fleet.pos[r],
            fleet.chi[r],
            fleet.theta[r],
            target[r],
            v_ref[r],
            a_ref[r],
            self.gains,
            self.dt,
            self.limits,
        )
        chi_next[r], v1[r], v2[r] = nxt, u1, u2

    def steer(
        self,
        v1: np.ndarray,
        v2: np.ndarray,
        held: np.ndarray,
        steer: np.ndarray | None = None,
        only: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The turn rates the cars execute and their steering angles, all rows.

        :func:`~sandbox.model.bicycle.steer_commands` on the car rows from the
        angles ``held`` of the last period; the unicycles' rows keep their ``v2``.

        Parameters
        ----------
        v1, v2 : ndarray, shape (N,) [m/s], [rad/s]
            The commands as they stand.
        held : ndarray, shape (N,) [rad]
            The steering angles of the last period (``Fleet.steer``).
        steer : ndarray, shape (N,) [rad], optional
            The angles an earlier call of this period gave; with ``only``, the rows
            outside ``only`` keep them.
        only : ndarray, shape (N,), bool, optional
            Steer these rows again (those a failure changed), the others as given.

        Returns
        -------
        v2 : ndarray, shape (N,) [rad/s]
            A new array (``v2`` itself where ``only`` picks no car).
        steer : ndarray, shape (N,) [rad]
            A new array (``steer`` itself where ``only`` picks no car).
        """
        r = self.rows
        limits = self.limits
        if only is not None:
            pick = np.flatnonzero(only[r])
            if not len(pick):
                return v2, (held.copy() if steer is None else steer)
            r, limits = r[pick], limits.rows(pick)
        u2, angle = steer_commands(v1[r], v2[r], held[r], limits, self.dt)
        v2 = v2.copy()
        out = held.copy() if steer is None else steer.copy()
        v2[r], out[r] = u2, angle
        return v2, out


class SteeringRecord:
    """The cars' steering angle at each recorded sample of K worlds of ``n`` rows.

    Kept in memory beside the loop's record (:class:`~sandbox.loop.recording.
    LoopRecord`), at the same sample indices; NaN on the unicycles' rows.

    Parameters
    ----------
    bicycle : ndarray, shape (K n,), bool
        The car rows.
    capacity, K, n : int
        Samples of the record, worlds, vehicles of each.
    """

    def __init__(self, bicycle: np.ndarray, capacity: int, K: int, n: int) -> None:
        self.n = n
        self._unicycle = ~bicycle
        #: Which worlds hold a car (only their runs get ``steer``).
        self.worlds = bicycle.reshape(K, n).any(axis=1)
        self._angles = np.full((capacity, K * n), np.nan)

    @classmethod
    def build(
        cls, fleet: Fleet, capacity: int, K: int, n: int
    ) -> SteeringRecord | None:
        """The record of the loop's cars, or None where every row is a unicycle."""
        if not np.count_nonzero(fleet.bicycle):
            return None
        return cls(fleet.bicycle, capacity, K, n)

    def append(self, index: int, steer: np.ndarray, world: int | None = None) -> None:
        """Sample ``index`` of every world's rows (or of world ``world``'s alone).

        ``steer`` is the fleet's, shape (K n,) [rad]; a sample beyond the capacity
        is not kept (as the loop's record keeps none).
        """
        if index >= len(self._angles):
            return
        angles = np.where(self._unicycle, np.nan, steer)
        if world is None:
            self._angles[index] = angles
        else:
            rows = slice(world * self.n, (world + 1) * self.n)
            self._angles[index, rows] = angles[rows]

    def arrays(self, world: int, count: int) -> dict[str, np.ndarray]:
        """World ``world``'s ``steer`` (count, n) [rad], or nothing without a car."""
        if not self.worlds[world]:
            return {}
        rows = slice(world * self.n, (world + 1) * self.n)
        return {"steer": np.ascontiguousarray(self._angles[:count, rows])}
