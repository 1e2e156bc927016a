"""The metrics accumulated inside the loop, for K worlds at once (K = 1: one run).

:class:`LoopTally` accumulates, for K worlds of ``n`` vehicles each stepped together by
:class:`~sandbox.loop.simulation.Simulation`, the numbers that do not depend on
``record_every``: control effort (the total variation of each vehicle's commands,
``effort_v1 = sum |v1(k) - v1(k-1)|`` [m/s] and ``effort_v2 = sum |v2(k) - v2(k-1)|``
[rad/s], i.e. the integrals of ``|v1'|`` and ``|v2'|``), the largest applied ``|v1|``
(the tunnelling check), the closest approach of two vehicles, and the motor check:
for every vehicle free of contact at both ends of a period, the body's velocity read
at the end against the velocity commanded for the period (the unicycle of eq. (1)); a
period whose error exceeds ``MOTOR_REL_TOL`` of the commanded speed and
``MOTOR_ABS_TOL`` counts as saturated. Above
:data:`~sandbox.run.metrics.ALL_PAIRS_MAX` vehicles the closest approach comes from a
:class:`~sandbox.run.metrics.ClosestApproach` (a Verlet list) per world. A period only
copies what these need (commands, pair distances, velocities, contact flags) into
buffers of :data:`CHUNK` periods; :meth:`LoopTally.flush` then accounts for the
buffered periods at once, in arrays over periods and vehicles (in one C call where
``sandbox.loop._period`` is built): the same elementwise operations, the sums taken
period after period in the order of the loop, and minima, maxima and counts (exact
whatever the order). Reductions over a world's vehicles run
column by column (:func:`row_reduce`), the same values as numpy's reductions over a
short axis at a fraction of their cost.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from sandbox import accel
from sandbox.run.metrics import (
    ALL_PAIRS_MAX,
    MOTOR_ABS_TOL,
    MOTOR_REL_TOL,
    ClosestApproach,
)

#: Periods buffered before :meth:`LoopTally.flush` accounts for them.
CHUNK = 64


class LoopTally:
    """The loop metrics of K worlds of ``n`` vehicles (see the module docstring)."""

    def __init__(self, K: int, n: int, h: float) -> None:
        self.K, self.n, self.h = K, n, h
        #: Per world, above ALL_PAIRS_MAX vehicles: the closest approach's Verlet list.
        self._closest = (
            [ClosestApproach() for _ in range(K)] if n > ALL_PAIRS_MAX else None
        )
        N = K * n
        pairs = 0 if self._closest else n * (n - 1) // 2
        self._m = 0  # periods buffered
        self._buf_d2 = np.empty((CHUNK, K, pairs))
        self._buf_v = np.empty((CHUNK, 2, N))
        self._buf_vel = np.empty((CHUNK, N, 2))
        self._buf_cmd = np.empty((CHUNK, N, 2))
        self._buf_free = np.empty((CHUNK, N), dtype=bool)
        self.effort_v1 = np.zeros(K * n)
        self.effort_v2 = np.zeros(K * n)
        self.peak_v1 = np.zeros(K * n)
        self.best = np.full(K, np.inf)
        self.max_speed_error = np.zeros(K)
        self.max_velocity_error = np.zeros(K)
        self.free_periods = np.zeros(K, dtype=np.int64)
        self.saturated_periods = np.zeros(K, dtype=np.int64)
        self._prev: np.ndarray | None = None  # (2, N): the last v1, v2
        self._commanded: np.ndarray | None = None
        self._was_free: np.ndarray | None = None
        # Every pair of a world, where every pair is checked (a large fleet: none).
        empty = np.zeros(0, dtype=np.intp)
        self._i, self._j = (empty, empty) if pairs == 0 else np.triu_indices(n, 1)
        #: The commanded velocities ``(v_x1, v_x2)`` of the period last accounted
        #: for, and its step index (the batch writes them to the physics).
        self.commanded: np.ndarray | None = None
        self.commanded_at = -1

    def update(
        self,
        fleet: Any,
        k: int,
        finite: bool,
        distances: Callable[[np.ndarray], np.ndarray | None],
        contact: np.ndarray | None,
        worlds: np.ndarray | None,
    ) -> None:
        """Account for period ``k`` of all worlds (or only ``worlds``).

        ``fleet`` gives the state at ``t_k`` and the commands from it, ``finite``
        whether every position is finite, ``distances(pos)`` the pair distances the
        neighbour search computed on these very positions (None: none), ``contact``
        the rows in an open contact episode (None: unknown, no motor check). With
        every world and every position finite the period is buffered (see the module
        docstring); else the buffer is accounted for and the period at once.
        """
        b = _State(fleet, k, finite, distances)
        if contact is None:  # no contact flags: no vehicle is checked
            contact = np.ones(self.K * self.n, dtype=bool)
        if self._closest is not None:
            self._closest_now(b, worlds)
        if worlds is None and b.finite:
            self._buffer(b, contact)
            return
        self.flush()
        self._update_now(b, contact, worlds)

    def _closest_now(self, b: Any, worlds: np.ndarray | None) -> None:
        """The closest approach of large fleets, world by world, at once."""
        n = self.n
        for w in range(self.K) if worlds is None else worlds:
            self._closest[w].update(b.pos[w * n : (w + 1) * n])

    def _buffer(self, b: Any, contact: np.ndarray) -> None:
        """Copy what period ``b.k`` accounts for into the buffers."""
        K, n, m = self.K, self.n, self._m
        period = accel.module("period")
        if period is not None:
            try:
                self._buffer_c(period, b, contact)
                return
            except (BufferError, TypeError, ValueError):  # not C arrays: numpy
                pass
        if n >= 2 and self._closest is None:
            d2 = b.distances(b.pos)
            if d2 is None:
                pos3 = b.pos.reshape(K, n, 2)
                d = pos3[:, self._i] - pos3[:, self._j]
                d2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
            self._buf_d2[m] = d2.reshape(K, -1)
        self._buf_v[m, 0] = b.v1
        self._buf_v[m, 1] = b.v2
        self._buf_vel[m] = b.vel
        np.logical_not(contact, out=self._buf_free[m])
        heading = b.theta + 0.5 * b.v2 * self.h
        commanded = self._buf_cmd[m]  # valid until the slot is written again
        commanded[:, 0] = b.v1 * np.cos(heading)
        commanded[:, 1] = b.v1 * np.sin(heading)
        self.commanded, self.commanded_at = commanded, b.k
        self._m = m + 1
        if self._m == CHUNK:
            self.flush()

    def _buffer_c(self, period: Any, b: Any, contact: np.ndarray) -> None:
        """:meth:`_buffer` in one C call (the same numbers)."""
        m = self._m
        i = j = d2 = None
        if self.n >= 2 and self._closest is None:
            d2 = b.distances(b.pos)  # the neighbour search's, copied by the call
            if d2 is None:
                i, j = self._i, self._j
        commanded = self._buf_cmd[m]  # valid until the slot is written again
        period.buffer_period(
            pos=b.pos,
            i=i,
            j=j,
            v1=b.v1,
            v2=b.v2,
            vel=b.vel,
            contact=contact,
            theta=b.theta,
            h=self.h,
            d2=self._buf_d2[m],
            v=self._buf_v[m],
            vel_out=self._buf_vel[m],
            free=self._buf_free[m],
            cmd=commanded,
            d2_known=d2,
        )
        self.commanded, self.commanded_at = commanded, b.k
        self._m = m + 1
        if self._m == CHUNK:
            self.flush()

    def flush(self) -> None:
        """Account for the buffered periods, as period after period would."""
        m, K, n = self._m, self.K, self.n
        if not m:
            return
        self._m = 0
        period = accel.module("period")
        if period is not None and self._flush_c(period, m):
            return
        if n >= 2 and self._closest is None:
            d2 = self._buf_d2[:m].reshape(m * K, -1)
            best = np.sqrt(row_reduce(np.minimum, d2)).reshape(m, K)
            self.best = np.minimum(self.best, np.minimum.reduce(best, axis=0))
        v = self._buf_v[:m]
        first = 0
        if self._prev is None:
            self._prev = v[0].copy()
            first = 1
        prev = np.concatenate((self._prev[None], v[:-1]))
        step = np.abs(v - prev)
        if first < m:  # period after period, as the loop adds them: an accumulation
            total = np.empty((m - first + 1, 2, step.shape[2]))
            total[0, 0], total[0, 1] = self.effort_v1, self.effort_v2
            total[1:] = step[first:]
            np.add.accumulate(total, axis=0, out=total)
            self.effort_v1[:], self.effort_v2[:] = total[-1, 0], total[-1, 1]
        self._prev = v[m - 1].copy()
        # the largest |v1| (fmax: NaN left out, in any order)
        np.fmax(self.peak_v1, np.fmax.reduce(np.abs(v[:, 0]), axis=0), out=self.peak_v1)
        free, vel, cmd_now = self._buf_free[:m], self._buf_vel[:m], self._buf_cmd[:m]
        if self._commanded is not None:
            cmd = np.concatenate((self._commanded[None], cmd_now[:-1]))
            was_free = np.concatenate((self._was_free[None], free[:-1]))
            self._account_motors(free & was_free, vel, cmd, m)
        elif m > 1:
            self._account_motors(free[1:] & free[:-1], vel[1:], cmd_now[:-1], m - 1)
        self._commanded = cmd_now[m - 1].copy()
        self._was_free = free[m - 1].copy()

    def _flush_c(self, period: Any, m: int) -> bool:
        """:meth:`flush` of ``m`` periods in one C call (the same numbers).

        False where the call refuses the arrays (nothing is changed then).
        """
        K, n = self.K, self.n
        has_prev, has_cmd = self._prev is not None, self._commanded is not None
        prev = self._prev if has_prev else np.empty((2, K * n))
        commanded = self._commanded if has_cmd else np.empty((K * n, 2))
        was_free = self._was_free if has_cmd else np.empty(K * n, dtype=bool)
        try:
            period.flush_periods(
                m=m,
                K=K,
                n=n,
                rel_tol=MOTOR_REL_TOL,
                abs_tol=MOTOR_ABS_TOL,
                has_prev=has_prev,
                has_cmd=has_cmd,
                d2=self._buf_d2[:m],
                v=self._buf_v[:m],
                vel=self._buf_vel[:m],
                cmd=self._buf_cmd[:m],
                free=self._buf_free[:m],
                best=self.best,
                effort_v1=self.effort_v1,
                effort_v2=self.effort_v2,
                peak_v1=self.peak_v1,
                prev=prev,
                commanded=commanded,
                was_free=was_free,
                max_velocity_error=self.max_velocity_error,
                max_speed_error=self.max_speed_error,
                free_periods=self.free_periods,
                saturated_periods=self.saturated_periods,
            )
        except (BufferError, TypeError, ValueError):
            return False
        self._prev, self._commanded, self._was_free = prev, commanded, was_free
        return True

    def _account_motors(
        self, check: np.ndarray, vel: np.ndarray, cmd: np.ndarray, m: int
    ) -> None:
        """The motor check of ``m`` periods: velocities read against commanded."""
        K, n = self.K, self.n
        check = check & np.isfinite(vel[..., 0]) & np.isfinite(vel[..., 1])
        want = np.hypot(cmd[..., 0], cmd[..., 1])
        err = np.hypot(vel[..., 0] - cmd[..., 0], vel[..., 1] - cmd[..., 1])
        speed_err = np.abs(np.hypot(vel[..., 0], vel[..., 1]) - want)
        check3 = check.reshape(m, K, n)
        worst = np.where(check3, err.reshape(m, K, n), -np.inf).max(axis=(0, 2))
        self.max_velocity_error = np.maximum(self.max_velocity_error, worst)
        worst = np.where(check3, speed_err.reshape(m, K, n), -np.inf).max(axis=(0, 2))
        self.max_speed_error = np.maximum(self.max_speed_error, worst)
        tol = np.maximum(MOTOR_REL_TOL * want, MOTOR_ABS_TOL)
        self.free_periods += check3.sum(axis=(0, 2))
        saturated = (check & (err > tol)).reshape(m, K, n)
        self.saturated_periods += saturated.sum(axis=(0, 2))

    def _update_now(
        self, b: Any, contact: np.ndarray, worlds: np.ndarray | None
    ) -> None:
        """One period accounted for at once (some worlds, or a non-finite state)."""
        K, n = self.K, self.n
        if worlds is None:
            ws = vs = slice(None)
            kw = K
        else:
            ws = worlds
            vs = (worlds[:, None] * n + np.arange(n)).ravel()
            kw = len(worlds)
        if n >= 2 and self._closest is None:
            d2 = b.distances(b.pos) if worlds is None else None
            if d2 is None:
                pos3 = b.pos.reshape(K, n, 2)[ws]
                d = pos3[:, self._i] - pos3[:, self._j]
                d2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
            else:
                d2 = d2.reshape(K, -1)
            best = np.sqrt(row_reduce(np.minimum, d2))
            if worlds is None and b.finite:
                self.best = np.minimum(self.best, best)
            else:
                pos3 = b.pos.reshape(K, n, 2)[ws]
                finite = np.isfinite(pos3).reshape(kw, -1).all(axis=1)
                self.best[ws] = np.where(
                    finite, np.minimum(self.best[ws], best), self.best[ws]
                )
        v1, v2 = b.v1[vs], b.v2[vs]
        self.peak_v1[vs] = np.fmax(self.peak_v1[vs], np.abs(v1))
        if self._prev is not None:
            self.effort_v1[vs] += np.abs(v1 - self._prev[0][vs])
            self.effort_v2[vs] += np.abs(v2 - self._prev[1][vs])
        if self._prev is None:
            self._prev = np.array((b.v1, b.v2), dtype=float)
        else:
            self._prev[0][vs] = v1
            self._prev[1][vs] = v2
        free = ~contact[vs]
        vel = b.vel[vs]
        if self._commanded is not None:
            check = free & self._was_free[vs]
            check &= np.isfinite(vel[:, 0]) & np.isfinite(vel[:, 1])
            if check.any():
                cmd, got = self._commanded[vs], vel
                want = np.hypot(cmd[:, 0], cmd[:, 1])
                err = np.hypot(got[:, 0] - cmd[:, 0], got[:, 1] - cmd[:, 1])
                speed_err = np.abs(np.hypot(got[:, 0], got[:, 1]) - want)
                check2 = check.reshape(kw, n)
                some = row_reduce(np.logical_or, check2)
                self.max_velocity_error[ws] = _raised_max(
                    self.max_velocity_error[ws], some, check2, err.reshape(kw, n)
                )
                self.max_speed_error[ws] = _raised_max(
                    self.max_speed_error[ws], some, check2, speed_err.reshape(kw, n)
                )
                tol = np.maximum(MOTOR_REL_TOL * want, MOTOR_ABS_TOL)
                self.free_periods[ws] += row_sum(check2)
                self.saturated_periods[ws] += row_sum(
                    (check & (err > tol)).reshape(kw, n)
                )
        heading = b.theta[vs] + 0.5 * v2 * self.h
        commanded = np.stack((v1 * np.cos(heading), v1 * np.sin(heading)), -1)
        if self._commanded is None and worlds is None:
            self._commanded, self._was_free = commanded, free
        else:
            if self._commanded is None:  # some worlds first (they ended at once)
                self._commanded = np.zeros((K * n, 2))
                self._was_free = np.zeros(K * n, dtype=bool)  # the others: unchecked
            self._commanded[vs] = commanded
            self._was_free[vs] = free
        if worlds is None:
            self.commanded, self.commanded_at = commanded, b.k

    def result(self, w: int) -> dict[str, Any]:
        """World ``w``'s values, JSON-ready (``Run.info["loop_metrics"]``)."""
        self.flush()
        rows = slice(w * self.n, (w + 1) * self.n)
        best = self._closest[w].best if self._closest is not None else self.best[w]
        free = int(self.free_periods[w])
        return {
            "effort_v1": [float(x) for x in self.effort_v1[rows]],
            "effort_v2": [float(x) for x in self.effort_v2[rows]],
            "peak_v1": [float(x) for x in self.peak_v1[rows]],
            "min_distance": float(best) if np.isfinite(best) else None,
            "motor": {
                "max_speed_error_free": float(self.max_speed_error[w]),
                "max_velocity_error_free": float(self.max_velocity_error[w]),
                "free_periods": free,
                "saturated_fraction": int(self.saturated_periods[w]) / free
                if free
                else 0.0,
            },
        }


#: Widest rows :func:`row_reduce` reduces column by column.
_COLUMNS = 8


def row_reduce(ufunc: np.ufunc, a: np.ndarray) -> np.ndarray:
    """``ufunc.reduce(a, axis=1)`` of a (k, m) array, column by column for small m.

    numpy's reduction over a short last axis costs a loop per row; ``m - 1`` calls
    over whole columns give the same values for the exact reductions used here
    (minimum, maximum, logical or).
    """
    m = a.shape[1]
    if m == 0 or m > _COLUMNS:
        return ufunc.reduce(a, axis=1)
    out = a[:, 0].copy()
    for c in range(1, m):
        ufunc(out, a[:, c], out=out)
    return out


def row_sum(mask: np.ndarray) -> np.ndarray:
    """``mask.sum(axis=1)`` of a (k, m) bool array, as int64."""
    m = mask.shape[1]
    if m == 0 or m > _COLUMNS:
        return mask.sum(axis=1)
    out = mask[:, 0].astype(np.int64)
    for c in range(1, m):
        out += mask[:, c]
    return out


def _raised_max(
    current: np.ndarray, some: np.ndarray, check: np.ndarray, values: np.ndarray
) -> np.ndarray:
    """Each world's running maximum raised by its checked values of this period.

    ``check`` and ``values`` are (worlds, vehicles); ``some`` says which worlds have a
    checked vehicle at all. Worlds without one keep ``current``.
    """
    worst = row_reduce(np.maximum, np.where(check, values, -np.inf))
    return np.where(some, np.maximum(current, worst), current)


class _State:
    """What the tally reads of the loop at ``t_k``."""

    def __init__(self, fleet: Any, k: int, finite: bool, distances: Callable) -> None:
        self.pos, self.theta, self.vel = fleet.pos, fleet.theta, fleet.vel
        self.v1, self.v2 = fleet.v1, fleet.v2
        self.k, self.finite = k, finite
        self.distances = distances


def no_distances(pos: np.ndarray) -> None:
    """No pair distances known (a neighbour search that keeps none)."""
    return None
