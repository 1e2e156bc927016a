"""The residual detector's pass of one control period, every vehicle in one C call.

:func:`~sandbox.behaviour.detection.residual` does, every period, about sixty numpy
operations on arrays of a few hundred rows at most (the motor model, the restart of
the windows, the contact gate, and every tenth period or so the due windows'
residuals, their log-likelihood ratios and the two CUSUMs): their fixed cost of half
a microsecond or more each is most of the detector's time. Where the optional
extension ``sandbox.behaviour._residual`` (``_residual.c``) is built,
:meth:`ResidualPass.run` does the same to the
:class:`~sandbox.behaviour.detection.DetectorState` as one loop over the rows: numpy's
operations element by element in its order, with the same double operations, so
every number is numpy's to the bit. What is rare stays in Python, vehicle by
vehicle, as the numpy path does it: the kind read at an alarm and while isolating
(:func:`~sandbox.behaviour.isolation.isolate`), the kind cleared with a detection,
and the ``trace`` of a study; :meth:`ResidualPass.run` returns the rows concerned
(:data:`QUIET` in a period without any, most periods). The same call stores the
period's row of the observed track history.

The loop takes ``sqrt``, ``hypot``, ``sin``, ``cos``, ``exp``, ``log`` and ``log1p``
from the C library, whose results may differ from numpy's by a unit in the last
place. At the first use :func:`kernel_agrees` compares each with numpy on a few
thousand arguments (special values included), and whole passes with
:func:`~sandbox.behaviour.detection.residual_pass` on a synthetic platoon of 36
vehicles over 64 periods (noise, lost packets, contacts, a NaN observation, alarms,
windows read while isolating, clearings; :func:`synthetic_run`); the C loop is used
only if every result has the same bits (:func:`same_numbers`;
``tests/test_detection_kernel.py`` compares whole runs). :data:`USE_KERNEL` False
forces the numpy path.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.model.kernels import _samples, c_float64

try:
    from sandbox.behaviour import _residual
except ImportError:  # pragma: no cover - built without a C compiler
    _residual = None

#: Use the C loop where it is built and agrees with numpy (False: numpy only).
USE_KERNEL = True
_agreed: bool | None = None
#: What :meth:`ResidualPass.run` returns for a period without anything to read.
QUIET: tuple = ()


def usable() -> bool:
    """Whether :meth:`ResidualPass.run` may run (built, agreeing, not switched off)."""
    return USE_KERNEL and kernel_agrees()


def kernel_agrees() -> bool:
    """Whether the C loop gives the numpy path's bits here (checked once)."""
    global _agreed
    if _agreed is None:
        _agreed = _residual is not None and _check()
    return _agreed


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
        self.n, self.dt = n, dt
        # The constants of detection.residual, as it computes them.
        window = max(1, int(round(p["window"] / dt)))
        sp = np.sqrt(2.0 * position_noise**2 + p["noise_floor"] ** 2)
        sh = np.sqrt(2.0 * heading_noise**2 + p["heading_floor"] ** 2)
        self._scalars = (
            float(dt),
            max(1, int(substeps)),
            window,
            float(sp),
            float(sh),
            float(heading_noise),
            float(p["shift"]),
            float(p["lambda"]),
            float(p["isolation"]),
        )
        self._limits = (
            c_float64(motor_accel),
            c_float64(turn_accel),
            c_float64(brake_accel),
        )
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
        read, cleared, alarms = self._out
        rows, inc = self._trace if trace is not None else (None, None)
        history = st.history
        ring = (None, None, 0)
        if history is not None:  # its row of this period is filled in C
            ring = (history.values, history.fresh, history.advance(t))
        try:
            counts = _residual.residual_period(
                st, seen, fresh, contact, commands, *self._limits, read, cleared,
                alarms, rows, inc, *ring, t, *self._scalars,
            )  # fmt: skip
        except TypeError:  # an observation not a contiguous float64 or bool array
            counts = _residual.residual_period(
                st, c_float64(seen), _bools(fresh), _bools(contact),
                c_float64(commands), *self._limits, read, cleared, alarms, rows, inc,
                *ring, t, *self._scalars,
            )  # fmt: skip
        n_read, n_cleared, n_alarms, n_used = counts
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


def same_numbers(x: np.ndarray, y: np.ndarray) -> bool:
    """Whether two float arrays hold the same numbers, bit for bit, NaN for NaN.

    A NaN's sign is not compared: numpy's own loops give either sign for the same
    operation on two NaNs, by the element's place in the array (the last elements of
    a vector loop are done otherwise), and no comparison or output tells them apart.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.shape != y.shape:
        return False
    nan = np.isnan(x)
    return bool(
        np.array_equal(nan, np.isnan(y))
        and np.array_equal(x[~nan].view(np.uint64), y[~nan].view(np.uint64))
    )


def _check() -> bool:
    """Compare the C library's functions and a whole pass with numpy (see module)."""
    with np.errstate(all="ignore"):
        return _functions_agree(*_samples()) and _passes_agree()


def _functions_agree(a: np.ndarray, b: np.ndarray) -> bool:
    from sandbox.behaviour.detection import _wrap, llr

    positive = np.abs(a)
    power = -np.abs(b) * 100.0  # exp's arguments of the llr, and beyond
    expected = {
        0: (a, b, np.hypot(a, b)),
        1: (a, b, np.sin(a)),
        2: (a, b, np.cos(a)),
        3: (positive, b, np.sqrt(positive)),
        4: (power, b, np.exp(power)),
        5: (positive, b, np.log(positive)),
        6: (-np.exp(power), b, np.log1p(-np.exp(power))),
        7: (a, b, _wrap(a)),
        9: (a, b, np.hypot.reduce(np.column_stack((a, b, a - b)), axis=1)),
    }
    for mu in (0.5, 2.0, 4.0, 7.25):  # the llr of |z| for a few shifts
        z = np.abs(a) * (1.0 + (b > 0))
        expected[8 + 100 * int(mu * 4)] = (z, np.full_like(z, mu), llr(z, mu))
    for key, (first, second, want) in expected.items():
        got = np.empty_like(first)
        _residual.elementwise(key % 100, first, second, got)
        if not same_numbers(got, want):
            return False
    return True


def _passes_agree() -> bool:
    """A synthetic platoon by both passes: the same state, trace and rows, bitwise."""
    return _same_runs(synthetic_run(True), synthetic_run(False))


def synthetic_run(kernel: bool, n: int = 36, periods: int = 64) -> tuple:
    """A synthetic platoon's detector passes, by :meth:`ResidualPass.run` or numpy.

    ``n`` unicycles follow smooth random commands, observed with noise and lost
    packets; a third of them stop and turn on the spot for a while (alarms, windows
    read while isolating, clearings after), some touch (the contact gate), one is
    seen at NaN for a while, and the substeps and the drives' limits vary.

    Returns
    -------
    state : DetectorState
        After the last period, with its history.
    trace : list
        ``(t, vehicle, l)`` of every window used.
    events : list
        Each period's rows read on, cleared and alarming (as lists).
    """
    from sandbox.behaviour import detection
    from sandbox.plugins.contexts import DetectorContext

    rng = np.random.default_rng(20261207)
    accel = np.where(rng.random(n) < 0.25, np.inf, rng.uniform(2.0, 8.0, n))
    params = {
        "lambda": 6.0,
        "window": 0.03,
        "shift": 3.0,
        "isolation": 0.05,
        "noise_floor": 0.001,
        "heading_floor": 0.001,
    }
    truth = np.column_stack((rng.normal(0.0, 3.0, (n, 2)), rng.uniform(-3, 3, n)))
    commands = np.column_stack((rng.uniform(0.2, 1.5, n), rng.normal(0.0, 0.5, n)))
    onset = np.where(np.arange(n) % 3 == 0, rng.integers(5, 20, n), periods)
    end = onset + rng.integers(8, 30, n)
    st, trace, events = None, [], []
    for k in range(periods):
        commands = commands + rng.normal(0.0, 0.05, (n, 2))
        faulty = (onset <= k) & (k < end)
        v1 = np.where(faulty, 0.0, commands[:, 0])
        v2 = np.where(faulty, 2.0, commands[:, 1])
        heading = np.column_stack((np.cos(truth[:, 2]), np.sin(truth[:, 2])))
        truth[:, :2] += 0.01 * v1[:, None] * heading
        truth[:, 2] += 0.01 * v2
        seen = truth + rng.normal(0.0, 0.002, (n, 3))
        if periods // 2 <= k < periods // 2 + 10:
            seen[n - 1] = np.nan  # diverged observations
        ctx = DetectorContext(
            t=0.01 * k,
            dt=0.01,
            pos=truth[:, :2],
            theta=truth[:, 2],
            vel=v1[:, None] * heading,
            seen=seen,
            fresh=rng.random(n) > 0.08,
            commands=commands.copy(),
            in_contact=rng.random(n) < 0.015,
            failing=faulty,
            position_noise=0.002,
            heading_noise=0.002,
            substeps=1 + k % 3,
            motor_accel=accel,
            turn_accel=4.0 * accel / 0.15,
            params=params,
            memory={"trace": trace},
            brake_accel=np.minimum(accel, 5.0),
        )
        if st is None:
            st = detection._start(ctx)
            st.history = detection.shape_history(ctx)
            continue
        if kernel:
            out = ResidualPass.of(ctx).run(
                st, ctx.t, ctx.seen, ctx.fresh, ctx.in_contact, ctx.commands, trace
            )
        else:
            st.history.append(ctx.t, ctx.seen[:, :2], ctx.fresh)
            out = detection.residual_pass(st, ctx)
        events.append([list(rows) for rows in out])
    return st, trace, events


def _same_runs(a: tuple, b: tuple) -> bool:
    """Whether two :func:`synthetic_run` results are the same, bit for bit."""
    (sa, ta, ea), (sb, tb, eb) = a, b
    if ea != eb or [x[:2] for x in ta] != [x[:2] for x in tb]:
        return False
    if not same_numbers(np.array([x[2] for x in ta]), np.array([x[2] for x in tb])):
        return False
    ha, hb = sa.history, sb.history
    if not (
        (ha.count, ha._next) == (hb.count, hb._next)
        and np.array_equal(ha.fresh, hb.fresh)
        and same_numbers(ha.times, hb.times)
        and same_numbers(ha.values, hb.values)
    ):
        return False
    for name, value in vars(sa).items():
        other = getattr(sb, name)
        if not isinstance(value, np.ndarray):
            continue
        if value.dtype != other.dtype or value.shape != other.shape:
            return False
        same = same_numbers if value.dtype == np.float64 else np.array_equal
        if not same(value, other):
            return False
    return True
