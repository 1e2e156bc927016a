"""The residual detector's pass of one control period, every vehicle in one C call.

:func:`~sandbox.behaviour.detection.residual` does, every period, about sixty numpy
operations on arrays of a few hundred rows at most (the motor model, the restart of
the windows, the contact gate, and every tenth period or so the due windows'
residuals, their log-likelihood ratios and the two CUSUMs): their fixed cost of half
a microsecond or more each is most of the detector's time. Where the compiled path
``residual`` is on (:mod:`sandbox.accel`; ``_residual.c``), :meth:`ResidualPass.run`
does the same to the :class:`~sandbox.behaviour.residual_state.DetectorState` as one
loop over the rows, with the C library's ``exp``, ``log`` and ``log1p``: within rtol
1e-9 of :func:`~sandbox.behaviour.detection.residual_pass`, the reference
(``tests/test_compiled_paths.py``). What is rare stays in Python, vehicle by
vehicle, as the numpy path does it: the kind read at an alarm and while isolating
(:func:`~sandbox.behaviour.isolation.isolate`), the kind cleared with a detection,
and the ``trace`` of a study; :meth:`ResidualPass.run` returns the rows concerned
(:data:`QUIET` in a period without any, most periods). The same call stores the
period's row of the observed track history.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox import accel
from sandbox.behaviour.residual_state import RECENT_SPEED_WINDOW
from sandbox.model.kernels import c_float64

#: What :meth:`ResidualPass.run` returns for a period without anything to read.
QUIET: tuple = ()


def usable() -> bool:
    """Whether :meth:`ResidualPass.run` may run (the compiled path ``residual``)."""
    return accel.module("residual") is not None


def _bools(a: np.ndarray | None) -> np.ndarray | None:
    """``a`` as a C-contiguous bool array for the C loop (None stays None)."""
    if a is None or (a.dtype == np.bool_ and a.flags.c_contiguous):
        return a
    return np.ascontiguousarray(a, dtype=bool)


class ResidualPass:
    """One residual detector's constants, and its pass of a period in C.

    Parameters
    ----------
    n : int
        Rows (vehicles of every world).
    dt : float [s]
        The control period.
    substeps : int
        Physics substeps per period.
    params : dict
        The detector's values (``RESIDUAL_PARAMS``).
    position_noise, heading_noise : float [m], [rad]
        The broadcast noise of ``sensing:``.
    motor_accel, turn_accel, brake_accel : ndarray (n,) [m/s^2], [rad/s^2], [m/s^2]
        The drives' limits (see :class:`~sandbox.plugins.contexts.DetectorContext`).
    """

    def __init__(
        self,
        n: int,
        dt: float,
        substeps: int,
        params: dict[str, Any],
        position_noise: float,
        heading_noise: float,
        motor_accel: np.ndarray,
        turn_accel: np.ndarray,
        brake_accel: np.ndarray,
    ) -> None:
        p = params
        self._c = accel.module("residual")
        self.n, self.dt = n, dt
        # The constants of detection.residual, as it computes them.
        window = max(1, int(round(p["window"] / dt)))
        sp = np.sqrt(2.0 * position_noise**2 + p["noise_floor"] ** 2)
        sh = np.sqrt(2.0 * heading_noise**2 + p["heading_floor"] ** 2)
        self.substeps, self.window = max(1, int(substeps)), window
        self.sp, self.sh, self.heading_noise = (
            float(sp),
            float(sh),
            float(heading_noise),
        )
        self.mu, self.lam = float(p["shift"]), float(p["lambda"])
        self.isolation = float(p["isolation"])
        self.settle = RECENT_SPEED_WINDOW
        self.motor_accel = c_float64(motor_accel)
        self.turn_accel = c_float64(turn_accel)
        self.brake_accel = c_float64(brake_accel)
        self._out = tuple(np.empty(n, dtype=np.intp) for _ in range(3))
        self._trace = (np.empty(n, dtype=np.intp), np.empty(n))

    @classmethod
    def of(cls, ctx: Any) -> ResidualPass:
        """The pass of a :class:`~sandbox.plugins.contexts.DetectorContext`."""
        brakes = ctx.motor_accel if ctx.brake_accel is None else ctx.brake_accel
        return cls(
            len(ctx.pos),
            ctx.dt,
            ctx.substeps,
            ctx.params,
            ctx.position_noise,
            ctx.heading_noise,
            ctx.motor_accel,
            ctx.turn_accel,
            brakes,
        )

    def run(
        self,
        st: Any,
        t: float,
        seen: np.ndarray,
        fresh: np.ndarray | None,
        contact: np.ndarray | None,
        commands: np.ndarray,
        trace: list | None = None,
    ) -> tuple:
        """One period of the detector ``st``, its history's row included.

        Parameters
        ----------
        st : DetectorState
            Advanced in place, as :func:`~sandbox.behaviour.detection.residual`
            advances it before it reads kinds (its history's append and
            :func:`~sandbox.behaviour.detection.residual_pass`).
        t : float [s]
        seen : ndarray (n, 3) [m, m, rad]
            The observed poses.
        fresh, contact : ndarray (n,) bool or None
            The fresh observations (None: all) and the vehicles in contact (None:
            none).
        commands : ndarray (n, 2) [m/s, rad/s]
            The commands of the period ending at ``seen``.
        trace : list or None
            Where ``(t, vehicle, l)`` of every window used is appended.

        Returns
        -------
        tuple
            :data:`QUIET` when no kind is to be read, else ``(read, cleared,
            alarms)``: the rows (ndarray of intp, increasing) read on while
            isolating, cleared, and alarming this period.
        """
        rows, inc = self._trace if trace is not None else (None, None)
        history = st.history
        ring = (None, None, 0)
        if history is not None:  # its row of this period is filled in C
            ring = (history.values, history.fresh, history.advance(t))
        observed = (seen, fresh, contact, commands)
        try:
            counts = self._call(st, t, observed, ring, rows, inc)
        except TypeError:  # an observation not a contiguous float64 or bool array
            observed = (c_float64(seen), _bools(fresh), _bools(contact))
            counts = self._call(
                st, t, (*observed, c_float64(commands)), ring, rows, inc
            )
        n_read, n_cleared, n_alarms, n_used = counts
        read, cleared, alarms = self._out
        if trace is not None and n_used:  # (t, vehicle, l) of every window used
            trace.extend(
                (t, int(i), float(x))
                for i, x in zip(rows[:n_used], inc[:n_used], strict=True)
            )
        if not (n_read or n_cleared or n_alarms):
            return QUIET
        return (
            read[:n_read].copy(),
            cleared[:n_cleared].copy(),
            alarms[:n_alarms].copy(),
        )

    def _call(
        self,
        st: Any,
        t: float,
        observed: tuple,
        ring: tuple,
        rows: np.ndarray | None,
        inc: np.ndarray | None,
    ) -> tuple[int, int, int, int]:
        """The C loop's period: how many rows are read, cleared, alarming, used.

        ``observed``: ``seen``, ``fresh``, ``contact`` and the commands; ``ring``:
        the track history's rings and this period's row of them (None, None, 0:
        none); ``rows``, ``inc``: where the trace is written (None: no trace).
        """
        seen, fresh, contact, commands = observed
        read, cleared, alarms = self._out
        return self._c.residual_period(
            state=st,
            seen=seen,
            fresh=fresh,
            contact=contact,
            commands=commands,
            motor_accel=self.motor_accel,
            turn_accel=self.turn_accel,
            brake=self.brake_accel,
            read=read,
            cleared=cleared,
            alarms=alarms,
            trace_rows=rows,
            trace_inc=inc,
            ring_values=ring[0],
            ring_fresh=ring[1],
            slot=ring[2],
            t=t,
            h=self.dt,
            substeps=self.substeps,
            window=self.window,
            sp=self.sp,
            sh=self.sh,
            heading_noise=self.heading_noise,
            mu=self.mu,
            lam=self.lam,
            isolation=self.isolation,
            settle=self.settle,
        )
