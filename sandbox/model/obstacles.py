"""Static obstacles: the shape record and the built-in obstacle types.

An obstacle type is a plug-in (:func:`sandbox.plugins.register_obstacle`) that turns
its YAML values into an :class:`ObstacleSpec`, one of four shapes the physics and the
distance queries know: ``circle``, ``box``, ``polygon`` (convex) and ``wall`` (a
segment with a thickness). The built-in types are those four shapes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from sandbox.plugins.registration import ObstacleContext, Param, register_obstacle

#: The shapes an obstacle type may return.
SHAPES = ("circle", "box", "polygon", "wall")


@dataclass(frozen=True)
class ObstacleSpec:
    """A static obstacle; which fields matter depends on ``type`` (a shape)."""

    type: str
    name: str
    center: tuple[float, float] | None = None
    radius: float | None = None
    size: tuple[float, float] | None = None
    angle: float = 0.0
    points: tuple[tuple[float, float], ...] | None = None
    start: tuple[float, float] | None = None
    end: tuple[float, float] | None = None
    thickness: float = 0.1

    def outline(self) -> list[list[float]]:
        """Polygon outline of a ``box``, ``polygon`` or ``wall`` [m] (for drawing)."""
        if self.type == "box":
            w, h = self.size[0] / 2, self.size[1] / 2
            c, s = math.cos(self.angle), math.sin(self.angle)
            corners = [(-w, -h), (w, -h), (w, h), (-w, h)]
            return [
                [self.center[0] + c * x - s * y, self.center[1] + s * x + c * y]
                for x, y in corners
            ]
        if self.type == "polygon":
            return [list(p) for p in self.points]
        if self.type == "wall":
            (x0, y0), (x1, y1) = self.start, self.end
            length = math.hypot(x1 - x0, y1 - y0) or 1.0
            nx, ny = -(y1 - y0) / length, (x1 - x0) / length
            t = self.thickness / 2
            return [
                [x0 + nx * t, y0 + ny * t],
                [x1 + nx * t, y1 + ny * t],
                [x1 - nx * t, y1 - ny * t],
                [x0 - nx * t, y0 - ny * t],
            ]
        raise ValueError(f"a {self.type} obstacle has no polygon outline")

    def document(self) -> dict[str, Any]:
        """The YAML mapping of this shape (``sandbox.scenario.Scenario.to_dict``)."""
        keys = {
            "circle": ("center", "radius"),
            "box": ("center", "size", "angle"),
            "polygon": ("points",),
            "wall": ("start", "end", "thickness"),
        }[self.type]
        doc: dict[str, Any] = {"type": self.type, "name": self.name}
        for k in keys:
            value = getattr(self, k)
            if isinstance(value, tuple):  # plain floats, also from a plug-in's numpy
                value = np.asarray(value, dtype=float).tolist()
            elif value is not None:
                value = float(value)
            doc[{"start": "from", "end": "to"}.get(k, k)] = value
        return doc


def is_convex(points: tuple[tuple[float, float], ...]) -> bool:
    """Whether the outline is a simple convex polygon of non-zero area.

    Every turn must go the same way, and the turns must add up to one full turn: a
    pentagram or a square listed twice turns the same way at every corner but winds
    twice around its inside (it is not simple, and pymunk would use its hull).
    Repeated consecutive points are ignored.
    """
    p = np.asarray(points, dtype=float)
    keep = np.any(np.abs(p - np.roll(p, 1, axis=0)) > 1e-12, axis=1)
    p = p[keep]
    if len(p) < 3:
        return False
    d1 = np.roll(p, -1, axis=0) - p
    d2 = np.roll(d1, -1, axis=0)
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    dot = d1[:, 0] * d2[:, 0] + d1[:, 1] * d2[:, 1]
    area = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    turning = float(np.sum(np.arctan2(cross, dot)))  # [rad], +-2 pi when simple
    return (
        abs(area) > 1e-12
        and (bool(np.all(cross >= -1e-12)) or bool(np.all(cross <= 1e-12)))
        and abs(abs(turning) - 2 * math.pi) < 1e-6
    )


_CENTER = Param("point", doc="Centre", unit="m")


@register_obstacle(
    "circle",
    {
        "center": _CENTER,
        "radius": Param("length", unit="m", doc="Radius", minimum=0, exclusive=True),
    },
)
def circle(ctx: ObstacleContext) -> ObstacleSpec:
    """A disc of ``radius`` about ``center``."""
    return ObstacleSpec(
        "circle", ctx.name, center=ctx.params["center"], radius=ctx.params["radius"]
    )


def _check_box(values: dict[str, Any], section: dict[str, Any]) -> list[tuple]:
    size = values.get("size")
    if size is not None and min(size) <= 0:
        return [
            (
                "size",
                "both sides must be greater than 0",
                f"{list(size)}",
                "two lengths > 0 [m]",
            )
        ]
    return []


@register_obstacle(
    "box",
    {
        "center": _CENTER,
        "size": Param("point", unit="m", doc="[width, height], both > 0"),
        "angle": Param("number", 0.0, unit="rad", doc="Rotation"),
    },
    check=_check_box,
)
def box(ctx: ObstacleContext) -> ObstacleSpec:
    """A rectangle of ``size`` about ``center``, turned by ``angle``."""
    p = ctx.params
    return ObstacleSpec(
        "box", ctx.name, center=p["center"], size=p["size"], angle=p["angle"]
    )


def _check_polygon(values: dict[str, Any], section: dict[str, Any]) -> list[tuple]:
    points = values.get("points")
    if points is not None and not is_convex(points):
        return [
            (
                "points",
                "not a simple convex polygon with non-zero area",
                f"{len(points)} points",
                "a convex outline that goes round once (split a concave "
                "obstacle into several polygons)",
            )
        ]
    return []


@register_obstacle(
    "polygon",
    {
        "points": Param(
            "points",
            min_items=3,
            unit="m",
            doc="At least 3 corners of a convex polygon",
        )
    },
    check=_check_polygon,
)
def polygon(ctx: ObstacleContext) -> ObstacleSpec:
    """A convex polygon through ``points``."""
    return ObstacleSpec("polygon", ctx.name, points=ctx.params["points"])


def _check_wall(values: dict[str, Any], section: dict[str, Any]) -> list[tuple]:
    start, end = values.get("from"), values.get("to")
    if start is not None and start == end:
        return [
            (
                "to",
                "a wall needs a length",
                f"from = to = {list(start)}",
                "two different end points",
            )
        ]
    return []


@register_obstacle(
    "wall",
    {
        "from": Param("point", unit="m", doc="One end of the wall"),
        "to": Param("point", unit="m", doc="The other end (different from 'from')"),
        "thickness": Param(
            "length", 0.1, unit="m", doc="Thickness", minimum=0, exclusive=True
        ),
    },
    check=_check_wall,
)
def wall(ctx: ObstacleContext) -> ObstacleSpec:
    """A straight wall from ``from`` to ``to`` of ``thickness``."""
    p = ctx.params
    return ObstacleSpec(
        "wall", ctx.name, start=p["from"], end=p["to"], thickness=p["thickness"]
    )
