"""Reference trajectories with exact first and second time derivatives.

A reference is the path the leader (or, for the ``virtual`` law, every slot) tracks with
the flatness controller, eq. (6). Each class evaluates ``(p, dp, ddp)`` at a time ``t``
(a float or an array of times), each of shape ``(..., 2)`` in [m], [m/s], [m/s^2].

>>> ref = CircleReference(center=(0.0, 0.0), radius=2.0, speed=1.0, phase=0.0)
>>> p, dp, ddp = ref.evaluate(0.0)
>>> p.tolist(), (dp + 0.0).tolist(), (ddp + 0.0).tolist()
([2.0, 0.0], [0.0, 1.0], [-0.5, 0.0])
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from sandbox.plugins.registration import Param, register_reference

if TYPE_CHECKING:
    from scipy.interpolate import CubicSpline

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
    [rad] is the starting angle, measured from the x1 axis.
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

    ``x1 = c1 + a sin(s)``, ``x2 = c2 + (a/2) sin(2 s)`` with ``s = w t``; ``w`` [rad/s]
    is chosen so that the mean speed over a lap equals ``speed`` [m/s] (the speed itself
    varies, fastest at the crossing).

    Where it starts and which way it runs: at ``t = 0`` the reference is at ``center``
    (the crossing point), heading up and to the right (+45 degrees from the x1 axis). It
    first runs the right lobe (``x1 > c1``) clockwise, reaching ``(c1 + a, c2)`` heading
    straight down at a quarter lap, crosses the centre again at half a lap heading up
    and to the left (+135 degrees), then runs the left lobe counter-clockwise, through
    ``(c1 - a, c2)`` heading down at three quarters, and is back at the centre heading
    +45 degrees after one lap of
    ``2 pi / w`` seconds. The figure spans ``[c1 - a, c1 + a]`` along x1 and ``[c2 -
    a/2, c2 + a/2]`` along x2.
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


@dataclass(frozen=True)
class WaypointsReference:
    """A C2 curve through ``points`` (a natural cubic spline), run at ``speed`` [m/s].

    The spline is parameterized by cumulative chord length ``s`` [m] and run at ``ds/dt
    = speed``, so the speed along the path is close to ``speed`` (exactly so on straight
    segments). After the last point the reference holds still there. The spline is
    scipy's :class:`~scipy.interpolate.CubicSpline` with natural end conditions (zero
    second derivative at both ends), built in O(n) time and memory for ``n`` points.
    """

    points: tuple[tuple[float, float], ...]
    speed: float
    knots: np.ndarray = field(init=False, repr=False, compare=False)
    spline: CubicSpline = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        from scipy.interpolate import CubicSpline  # imported here: off the start path

        pts = np.asarray(self.points, dtype=float)
        s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))))
        object.__setattr__(self, "knots", s)
        object.__setattr__(self, "spline", CubicSpline(s, pts, bc_type="natural"))

    @property
    def length(self) -> float:
        """Chord length of the whole path [m]."""
        return float(self.knots[-1])

    def evaluate(self, t: float | np.ndarray) -> Triple:
        """Return ``(p, dp, ddp)`` at time(s) ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        s = np.clip(self.speed * t, 0.0, self.knots[-1])  # [m] arc parameter
        moving = (self.speed * t < self.knots[-1]) & (t >= 0.0)
        p = self.spline(s)
        v = self.speed * moving[..., None]  # [m/s] ds/dt
        return p, self.spline(s, 1) * v, self.spline(s, 2) * v * v


Reference = (
    PointReference
    | LineReference
    | CircleReference
    | LemniscateReference
    | WaypointsReference
)


# --------------------------------------------------------------- the built-in types
# Each reference type is a plug-in: the class is built once with its YAML values.
_CENTER = Param("point", (0.0, 0.0), unit="m", doc="Centre")


#: References whose ``evaluate`` is elementwise in ``t``: the loop evaluates them for
#: many step times at once (each row the bits of the scalar evaluation at ``t_k``,
#: ``tests/test_references.py``). Every built-in type is: numpy's functions and the
#: spline's piecewise polynomials are evaluated point by point.
TABULATED_REFERENCES = (
    PointReference,
    LineReference,
    CircleReference,
    LemniscateReference,
    WaypointsReference,
)


def _check_waypoints(values: dict, section: dict) -> list[tuple]:
    """Consecutive waypoints must differ (the chord parameterization needs it)."""
    pts = values.get("points") or ()
    for i, (a, b) in enumerate(zip(pts, pts[1:], strict=False)):
        if a == b:
            return [
                (
                    f"points[{i + 1}]",
                    "repeats the previous point",
                    f"points[{i}] = points[{i + 1}] = {list(a)}",
                    "distinct consecutive points",
                )
            ]
    return []


register_reference(
    "point",
    {"position": Param("point", unit="m", doc="The point to stabilize at, eq. (4)")},
)(PointReference)
register_reference(
    "line",
    {
        "start": Param("point", (0.0, 0.0), unit="m", doc="Starting point"),
        "heading": Param("number", 0.0, unit="rad", doc="Direction of travel"),
        "speed": Param(
            "number", 1.0, unit="m/s", doc="Speed along the line", minimum=0.0
        ),
    },
)(LineReference)
register_reference(
    "circle",
    {
        "center": _CENTER,
        "radius": Param("length", unit="m", doc="Radius", minimum=0.0, exclusive=True),
        "speed": Param(
            "number", 1.0, unit="m/s", doc="Speed along the circle; negative: clockwise"
        ),
        "phase": Param("number", 0.0, unit="rad", doc="Starting angle on the circle"),
    },
)(CircleReference)
register_reference(
    "lemniscate",
    {
        "center": Param(
            "point", (0.0, 0.0), unit="m", doc="Centre of the figure-eight"
        ),
        "size": Param(
            "length", unit="m", doc="Half-width", minimum=0.0, exclusive=True
        ),
        "speed": Param(
            "number",
            1.0,
            unit="m/s",
            doc="Mean speed over a lap",
            minimum=0.0,
            exclusive=True,
        ),
    },
)(LemniscateReference)
register_reference(
    "waypoints",
    {
        "points": Param(
            "points",
            min_items=2,
            unit="m",
            doc="Points joined by a C2 spline, no two consecutive equal",
        ),
        "speed": Param(
            "number",
            1.0,
            unit="m/s",
            doc="Speed along the path",
            minimum=0.0,
            exclusive=True,
        ),
    },
    check=_check_waypoints,
)(WaypointsReference)
