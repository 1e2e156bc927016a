"""The flatness controller of one period, eqs. (5)-(6) with their limits, at once.

The :class:`Controller`'s step gives what the loop asks of the controller every
period: from the vehicles' state and their targets, ``chi`` for the next period and
the commands ``(v1, v2)``, the composition of
:func:`~sandbox.model.flatness.extension_rate`,
:func:`~sandbox.model.flatness.advance_extension` (with
:func:`~sandbox.model.flatness.limit_turn`), :func:`~sandbox.model.flatness.flat_inputs`
and the clip of ``v2`` to ``v2_max``. Those numpy functions are the definition; about
50 numpy calls a period, whose fixed cost (half a microsecond each) is most of a small
fleet's controller.

Where the compiled path ``controller`` is on (:mod:`sandbox.accel`; ``_kernels.c``),
the same composition runs as one C loop over the vehicles, with the C library's
``atan2``, ``hypot``, ``sin`` and ``cos``: within rtol 1e-12 of the numpy functions
(``tests/test_compiled_paths.py``), which stay the reference
(:meth:`Controller.step_numpy`) and run where the path is off.
"""

from __future__ import annotations

import numpy as np

from sandbox import accel
from sandbox.model.dynamics import CLIP
from sandbox.model.flatness import (
    CHI_REST,
    Gains,
    advance_extension,
    extension_rate,
    flat_inputs,
    limit_turn,
    parking,
    travel_direction,
)


def _rows(value: float | np.ndarray) -> np.ndarray:
    """A gain or limit as the C loops read it: (1,) for a scalar, else (n,)."""
    return np.ascontiguousarray(np.atleast_1d(np.asarray(value, dtype=float)))


def c_float64(a: np.ndarray) -> np.ndarray:
    """``a`` as a C-contiguous float64 array for a C loop: itself where it is one.

    ``np.ascontiguousarray(a, dtype=float)``, without its call where there is nothing
    to convert (the C loops' callers pass mostly such arrays, every period).
    """
    if a.dtype == np.float64 and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(a, dtype=float)


class Controller:
    """The controller of a fleet: its gains and limits, and one period's step.

    Parameters
    ----------
    gains : Gains
        Scalars or arrays of shape (n,).
    dt : float [s]
    v1_max, accel_max, v2_max : float or ndarray (n,)
        ``inf`` where unlimited.
    turn_max : float or ndarray (n,) or None
        The anti-windup's turn-rate limit (``v2_max``), or None without one.
    """

    def __init__(
        self,
        gains: Gains,
        dt: float,
        v1_max: float | np.ndarray,
        accel_max: float | np.ndarray,
        v2_max: float | np.ndarray,
        turn_max: float | np.ndarray | None,
    ) -> None:
        self.gains, self.dt = gains, dt
        self.v1_max, self.accel_max = v1_max, accel_max
        self.v2_max, self.turn_max = v2_max, turn_max
        self._k = [_rows(getattr(gains, k)) for k in ("k1", "k2", "k3", "k4")]
        self._kp = _rows(gains.kp)
        self._accel, self._v1 = _rows(accel_max), _rows(v1_max)
        self._v2 = _rows(v2_max)
        self._turn = _rows(np.inf if turn_max is None else turn_max)
        self._turning = turn_max is not None  # the turn-rate limit
        self._c = accel.module("controller")

    def step(
        self,
        pos: np.ndarray,
        chi: np.ndarray,
        theta: np.ndarray,
        target: np.ndarray,
        v_ref: np.ndarray,
        a_ref: np.ndarray,
        travel: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``chi`` and the direction of travel of the next period, ``(v1, v2)`` now.

        Parameters
        ----------
        pos, chi : ndarray (n, 2) [m], [m/s]
        theta : ndarray (n,) [rad]
        target, v_ref, a_ref : ndarray (n, 2) [m], [m/s], [m/s^2]
            The slot to track (a NaN coordinate aims at the position's) and its
            feed-forward velocity and acceleration.
        travel : ndarray (n,), int8
            The direction of travel now
            (:func:`~sandbox.model.flatness.travel_direction`).

        Returns
        -------
        chi_next : ndarray (n, 2) [m/s]
        v1 : ndarray (n,) [m/s]
        v2 : ndarray (n,) [rad/s]
            Within ``v2_max``.
        travel_next : ndarray (n,), int8
        """
        if self._c is not None:
            return self._step_c(pos, chi, theta, target, v_ref, a_ref, travel)
        return self.step_numpy(pos, chi, theta, target, v_ref, a_ref, travel)

    def step_numpy(
        self,
        pos: np.ndarray,
        chi: np.ndarray,
        theta: np.ndarray,
        target: np.ndarray,
        v_ref: np.ndarray,
        a_ref: np.ndarray,
        travel: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` by the numpy functions (the reference)."""
        if np.count_nonzero(np.isnan(target)):
            aim = np.where(np.isnan(target), pos, target)
        else:
            aim = target
        chi_dot = extension_rate(pos, chi, aim, v_ref, a_ref, self.gains)
        chi_next, chi_dot = advance_extension(
            chi, chi_dot, self.dt, self.v1_max, self.accel_max
        )
        parks = parking(pos, aim, v_ref)
        travel_next = travel_direction(chi, chi_next, theta, travel, parks)
        turn = None
        if self.turn_max is not None:  # the turn-rate limit of the anti-windup
            chi_next, turn = limit_turn(
                chi_next, theta, self.turn_max * self.dt, travel_next
            )
            chi_dot = (chi_next - chi) / self.dt
            # Where the limit holds the vehicle at rest (it turns first), the
            # direction stays what it was: it has not set off.
            rest = np.hypot(chi_next[:, 0], chi_next[:, 1]) < CHI_REST
            travel_next = np.where(rest, travel, travel_next).astype(np.int8)
        v1, v2 = flat_inputs(theta, chi, chi_dot, self.gains.kp, turn, travel)
        return chi_next, v1, CLIP(v2, -self.v2_max, self.v2_max), travel_next

    def _step_c(self, pos, chi, theta, target, v_ref, a_ref, travel):
        try:
            return self._step_arrays(pos, chi, theta, target, v_ref, a_ref, travel)
        except (BufferError, TypeError, ValueError):  # not C arrays: made so
            arrays = map(c_float64, (pos, chi, theta, target, v_ref, a_ref))
            travel = np.ascontiguousarray(travel, dtype=np.int8)
            return self._step_arrays(*arrays, travel)

    def _step_arrays(self, pos, chi, theta, target, v_ref, a_ref, travel):
        """The C call on C-contiguous float64 arrays (else an error, no write)."""
        n = len(theta)
        k1, k2, k3, k4 = self._k
        chi_next, v1, v2 = np.empty((n, 2)), np.empty(n), np.empty(n)
        travel_next = np.empty(n, dtype=np.int8)
        self._c.controller_step(
            pos=pos, chi=chi, theta=theta, target=target, v_ref=v_ref, a_ref=a_ref,
            k1=k1, k2=k2, k3=k3, k4=k4, accel_max=self._accel, v1_max=self._v1,
            kp=self._kp, turn_max=self._turn, v2_max=self._v2, chi_next=chi_next,
            v1=v1, v2=v2, travel=travel, travel_next=travel_next, dt=self.dt,
            turning=self._turning,
        )  # fmt: skip
        return chi_next, v1, v2, travel_next


def motor_model(
    pose: np.ndarray,
    vel: np.ndarray,
    rate: np.ndarray,
    travel: np.ndarray,
    commands: np.ndarray,
    motor_accel: np.ndarray,
    turn_accel: np.ndarray,
    h: float,
    substeps: int,
) -> tuple[np.ndarray, np.ndarray] | None:
    """One period of the residual detector's motor model in C, or None.

    ``pose`` (n, 3) and ``travel`` (n,) advance in place; returns the new ``vel``
    (n, 2) and ``rate`` (n,) (new arrays, as the numpy model makes). None where the
    C loop cannot run (the compiled path ``controller`` off, or an array that is not
    C-contiguous float64): the caller runs the numpy model.
    """
    c = accel.module("controller")
    if c is None:
        return None
    n = len(pose)
    if not all(
        a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable
        for a in (pose, travel)
    ) or not (
        pose.shape == (n, 3)
        and np.shape(vel) == np.shape(commands) == (n, 2)
        and np.shape(rate) == np.shape(travel) == np.shape(motor_accel) == (n,)
        and np.shape(turn_accel) == (n,)
    ):
        return None
    vel, rate = np.array(vel, dtype=float), np.array(rate, dtype=float)
    c.motor_model(
        pose, vel, rate, c_float64(commands), c_float64(motor_accel),
        c_float64(turn_accel), float(h), int(substeps), travel,
    )  # fmt: skip
    return vel, rate
