"""Reference trajectories with exact first and second time derivatives.

A reference is the path the leader (or, for the ``virtual`` law, every slot) tracks
with the
flatness controller, eq. (6). Each class evaluates ``(p, dp, ddp)`` at a time ``t`` (a
float
or an array of times), each of shape ``(..., 2)`` in [m], [m/s], [m/s^2].

>>> ref = CircleReference(center=(0.0, 0.0), radius=2.0, speed=1.0, phase=0.0)
>>> p, dp, ddp = ref.evaluate(0.0)
>>> p.tolist(), (dp + 0.0).tolist(), (ddp + 0.0).tolist()
([2.0, 0.0], [0.0, 1.0], [-0.5, 0.0])
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

Triple = tuple[np.ndarray, np.ndarray, np.ndarray]


def _stack(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.stack(np.broadcast_arrays(x, y), axis=-1).astype(float)


@dataclass(frozen=True)
class PointReference:
    """A fixed point: stabilization, eq. (4) (all derivatives are zero)."""

    position: tuple[float, float]

    def evaluate(self, t: float | np.ndarray) -> Triple:
        """Return ``(p, dp, ddp)`` at time(s) ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        zero = np.zeros_like(t)
        p = _stack(zero + self.position[0], zero + self.position[1])
        return p, np.zeros_like(p), np.zeros_like(p)


@dataclass(frozen=True)
class LineReference:
    """A straight line from ``start`` along ``heading`` [rad] at ``speed`` [m/s]."""

    start: tuple[float, float]
    heading: float
    speed: float

    def evaluate(self, t: float | np.ndarray) -> Triple:
        """Return ``(p, dp, ddp)`` at time(s) ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        c, s = math.cos(self.heading), math.sin(self.heading)
        p = _stack(
            self.start[0] + self.speed * c * t, self.start[1] + self.speed * s * t
        )
        dp = _stack(self.speed * c + 0 * t, self.speed * s + 0 * t)
        return p, dp, np.zeros_like(p)


@dataclass(frozen=True)
class CircleReference:
    """A circle of ``radius`` [m] about ``center``, run at ``speed`` [m/s].

    The sign of ``speed`` gives the direction (positive: counter-clockwise); ``phase``
    [rad]
    is the starting angle, measured from the x1 axis.
    """

    center: tuple[float, float]
    radius: float
    speed: float
    phase: float = 0.0

    def evaluate(self, t: float | np.ndarray) -> Triple:
        """Return ``(p, dp, ddp)`` at time(s) ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        w = self.speed / self.radius  # angular rate [rad/s]
        phi = self.phase + w * t
        c, s = np.cos(phi), np.sin(phi)
        r = self.radius
        p = _stack(self.center[0] + r * c, self.center[1] + r * s)
        dp = _stack(-r * w * s, r * w * c)
        ddp = _stack(-r * w * w * c, -r * w * w * s)
        return p, dp, ddp


@dataclass(frozen=True)
class LemniscateReference:
    """A figure-eight (lemniscate of Gerono), half-width ``size`` [m], at ``center``.

    ``x1 = c1 + a sin(s)``, ``x2 = c2 + (a/2) sin(2 s)`` with ``s = w t``; ``w`` is
    chosen
    so that the mean speed over a lap equals ``speed`` [m/s] (the speed itself varies).
    """

    center: tuple[float, float]
    size: float
    speed: float
    rate: float = field(init=False)

    def __post_init__(self) -> None:
        s = np.linspace(0.0, 2.0 * math.pi, 4001)
        a = self.size
        ds = np.hypot(a * np.cos(s), a * np.cos(2.0 * s))
        perimeter = float(np.sum(0.5 * (ds[1:] + ds[:-1]) * np.diff(s)))
        object.__setattr__(self, "rate", 2.0 * math.pi * self.speed / perimeter)

    def evaluate(self, t: float | np.ndarray) -> Triple:
        """Return ``(p, dp, ddp)`` at time(s) ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        a, w = self.size, self.rate
        s = w * t
        p = _stack(
            self.center[0] + a * np.sin(s), self.center[1] + 0.5 * a * np.sin(2 * s)
        )
        dp = _stack(a * w * np.cos(s), a * w * np.cos(2 * s))
        ddp = _stack(-a * w * w * np.sin(s), -2.0 * a * w * w * np.sin(2 * s))
        return p, dp, ddp


def _natural_spline_second_derivatives(s: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Second derivatives at the knots of the natural cubic spline through (s, y)."""
    n = len(s)
    m = np.zeros((n,) + y.shape[1:])
    if n < 3:
        return m
    h = np.diff(s)
    a = np.zeros((n, n))
    rhs = np.zeros((n,) + y.shape[1:])
    a[0, 0] = a[-1, -1] = 1.0
    for i in range(1, n - 1):
        a[i, i - 1] = h[i - 1]
        a[i, i] = 2.0 * (h[i - 1] + h[i])
        a[i, i + 1] = h[i]
        rhs[i] = 6.0 * ((y[i + 1] - y[i]) / h[i] - (y[i] - y[i - 1]) / h[i - 1])
    return np.linalg.solve(a, rhs)


@dataclass(frozen=True)
class WaypointsReference:
    """A C2 curve through ``points`` (a natural cubic spline), run at ``speed`` [m/s].

    The spline is parameterized by cumulative chord length ``s`` and run at
    ``ds/dt = speed``, so the speed along the path is close to ``speed`` (exactly so on
    straight segments). After the last point the reference holds still there.
    """

    points: tuple[tuple[float, float], ...]
    speed: float
    knots: np.ndarray = field(init=False, repr=False, compare=False)
    curvature: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=float)
        s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))))
        object.__setattr__(self, "knots", s)
        object.__setattr__(
            self, "curvature", _natural_spline_second_derivatives(s, pts)
        )

    @property
    def length(self) -> float:
        """Chord length of the whole path [m]."""
        return float(self.knots[-1])

    def evaluate(self, t: float | np.ndarray) -> Triple:
        """Return ``(p, dp, ddp)`` at time(s) ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        pts = np.asarray(self.points, dtype=float)
        s_all, m = self.knots, self.curvature
        s = np.clip(self.speed * t, 0.0, s_all[-1])
        moving = (self.speed * t < s_all[-1]) & (t >= 0.0)
        i = np.clip(np.searchsorted(s_all, s, side="right") - 1, 0, len(s_all) - 2)
        h = (s_all[i + 1] - s_all[i])[..., None]
        a = (s_all[i + 1] - s)[..., None]
        b = (s - s_all[i])[..., None]
        y0, y1, m0, m1 = pts[i], pts[i + 1], m[i], m[i + 1]
        p = (
            m0 * a**3 / (6 * h)
            + m1 * b**3 / (6 * h)
            + (y0 / h - m0 * h / 6) * a
            + (y1 / h - m1 * h / 6) * b
        )
        dpds = -m0 * a**2 / (2 * h) + m1 * b**2 / (2 * h) - y0 / h + m0 * h / 6 + y1 / h
        dpds = dpds - m1 * h / 6
        d2pds2 = m0 * a / h + m1 * b / h
        v = self.speed * moving[..., None]
        return p, dpds * v, d2pds2 * v * v


Reference = (
    PointReference
    | LineReference
    | CircleReference
    | LemniscateReference
    | WaypointsReference
)
