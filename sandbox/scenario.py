"""Scenario files: YAML -> validated, frozen dataclasses.

Everything a run needs is checked here, at load time, and every problem of a document is
reported at once as a :class:`~sandbox.errors.Problem` with the YAML line of the field
(``FILE:LINE: path.to.field: what is wrong (got X; expected Y)``). The simulation never
re-checks configuration.

The format is documented key by key in ``scenarios/reference.yaml``. Lengths may be written
in metres (``0.75``) or as multiples of the default vehicle diameter (``"3d"``, ``1.5d``).
"""

from __future__ import annotations

import copy
import difflib
import math
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sandbox.control.flatness import Gains, discrete_spectral_radius
from sandbox.control.formation import LAWS
from sandbox.errors import Problem, ScenarioError
from sandbox.references import (
    CircleReference,
    LemniscateReference,
    LineReference,
    PointReference,
    Reference,
    WaypointsReference,
)

REFERENCE_TYPES = ("point", "line", "circle", "lemniscate", "waypoints")
STRATEGIES = ("none", "discontinuous", "continuous", "smooth")
TARGET_DERIVATIVES = ("hold", "estimate")
FAILURE_KINDS = ("stuck_steering", "stop", "spin", "uncontrolled", "crash")
OBSTACLE_TYPES = ("circle", "box", "polygon", "wall")
PLATOON_PATTERNS = ("grid", "line", "wedge", "ring")
DRIVE_TYPES = ("reference", "commands")
#: Default colours, in vehicle order (the report draws the leader blue, then red, green).
PALETTE = (
    "blue",
    "red",
    "green",
    "orange",
    "purple",
    "brown",
    "magenta",
    "teal",
    "olive",
    "navy",
)


# ---------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class DriveSpec:
    """How a vehicle is driven: by its law (``reference``) or by a command schedule.

    ``schedule`` rows are ``(t [s], v1 [m/s], v2 [rad/s])``, held from ``t`` until the
    next row (zero before the first row).
    """

    type: str = "reference"
    schedule: tuple[tuple[float, float, float], ...] = ()


@dataclass(frozen=True)
class VehicleSpec:
    """One vehicle: identity, initial pose, slot offset and physical/controller limits."""

    name: str
    pose: tuple[float, float, float]
    offset: tuple[float, float] = (0.0, 0.0)
    leader: bool = False
    color: str = "blue"
    diameter: float = 0.5
    mass: float = 10.0
    gains: Gains = field(default_factory=Gains)
    v1_max: float | None = None
    v2_max: float | None = None
    max_accel: float | None = None
    motor_accel: float = 200.0
    drive: DriveSpec = field(default_factory=DriveSpec)


@dataclass(frozen=True)
class ReferenceSpec:
    """The reference trajectory; which fields matter depends on ``type``."""

    type: str
    position: tuple[float, float] | None = None
    start: tuple[float, float] | None = None
    heading: float = 0.0
    speed: float = 1.0
    center: tuple[float, float] | None = None
    radius: float | None = None
    phase: float = 0.0
    size: float | None = None
    points: tuple[tuple[float, float], ...] | None = None

    def build(self) -> Reference:
        """Return the reference object that evaluates ``(p, p', p'')``."""
        if self.type == "point":
            return PointReference(self.position)
        if self.type == "line":
            return LineReference(self.start, self.heading, self.speed)
        if self.type == "circle":
            return CircleReference(self.center, self.radius, self.speed, self.phase)
        if self.type == "lemniscate":
            return LemniscateReference(self.center, self.size, self.speed)
        return WaypointsReference(self.points, self.speed)


@dataclass(frozen=True)
class FormationSpec:
    """Which formation law of section 3 the followers use."""

    law: str = "rotating"
    rotate: bool = False


@dataclass(frozen=True)
class RecoverySpec:
    """Collision-avoidance strategy of section 4 (lengths resolved to metres)."""

    strategy: str = "none"
    beta: float = 1.0
    R: float = 1.5
    r: float | None = None
    leader_avoids: bool = False
    target_derivatives: str = "hold"
    steepness: float = 2.0


@dataclass(frozen=True)
class FailureSpec:
    """A failure of one vehicle from ``at`` until ``until`` (or the end)."""

    vehicle: str
    at: float
    kind: str
    until: float | None = None
    v1: float | None = None
    v2: float | None = None


@dataclass(frozen=True)
class ObstacleSpec:
    """A static obstacle; which fields matter depends on ``type``."""

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


@dataclass(frozen=True)
class PlatoonSpec:
    """Generated followers: ``count`` vehicles placed by ``pattern``."""

    count: int
    pattern: str = "grid"
    spacing: float = 1.0
    jitter: float = 0.0
    columns: int | None = None
    prefix: str = "v"


@dataclass(frozen=True)
class MetricsSpec:
    """Parameters of the metrics (``metrics.json``)."""

    settle_tol: float = 0.05


@dataclass(frozen=True)
class Scenario:
    """A validated scenario. Build it with :func:`load_scenario` or :func:`parse_scenario`."""

    name: str
    description: str
    duration: float
    dt: float
    substeps: int
    seed: int
    record_every: int
    vehicles: tuple[VehicleSpec, ...]
    reference: ReferenceSpec | None
    formation: FormationSpec | None
    recovery: RecoverySpec
    failures: tuple[FailureSpec, ...]
    obstacles: tuple[ObstacleSpec, ...]
    platoon: PlatoonSpec | None
    metrics: MetricsSpec
    diameter: float
    source: str | None = None
    warnings: tuple[str, ...] = ()

    @property
    def leader_index(self) -> int:
        """Index of the leader vehicle, or -1."""
        for i, v in enumerate(self.vehicles):
            if v.leader:
                return i
        return -1

    def to_dict(self) -> dict[str, Any]:
        """A plain document that :func:`parse_scenario` reads back to this scenario.

        Lengths are resolved to metres; generated platoon vehicles are listed.
        """
        doc: dict[str, Any] = {
            "name": self.name,
            "description": self.description,
            "duration": self.duration,
            "dt": self.dt,
            "substeps": self.substeps,
            "seed": self.seed,
            "record_every": self.record_every,
            "vehicle": {"diameter": self.diameter},
        }
        if self.reference is not None:
            ref = _plain(self.reference)
            doc["reference"] = {"type": ref["type"]}
            doc["reference"].update({k: ref[k] for k in REFERENCE_KEYS[ref["type"]]})
        if self.formation is not None:
            doc["formation"] = {"law": self.formation.law}
            if self.formation.law in ("virtual", "leader_ref"):
                doc["formation"]["rotate"] = self.formation.rotate
        doc["vehicles"] = []
        for v in self.vehicles:
            item = _plain(v, skip_none=True)
            item["gains"] = _plain(v.gains)
            if v.drive.type == "reference":
                del item["drive"]
            doc["vehicles"].append(item)
        doc["recovery"] = _plain(self.recovery, skip_none=True)
        if self.failures:
            doc["failures"] = [_plain(f, skip_none=True) for f in self.failures]
        if self.obstacles:
            doc["obstacles"] = [_obstacle_doc(o) for o in self.obstacles]
        doc["metrics"] = _plain(self.metrics)
        return doc


def _plain(obj: Any, skip_none: bool = False) -> Any:
    if is_dataclass(obj):
        out = {}
        for f in fields(obj):
            value = getattr(obj, f.name)
            if skip_none and value is None:
                continue
            out[f.name] = _plain(value, skip_none)
        return out
    if isinstance(obj, tuple | list):
        return [_plain(v, skip_none) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _obstacle_doc(o: ObstacleSpec) -> dict[str, Any]:
    keys = {
        "circle": ("center", "radius"),
        "box": ("center", "size", "angle"),
        "polygon": ("points",),
        "wall": ("start", "end", "thickness"),
    }[o.type]
    doc: dict[str, Any] = {"type": o.type, "name": o.name}
    for k in keys:
        doc[{"start": "from", "end": "to"}.get(k, k)] = _plain(getattr(o, k))
    return doc


# ---------------------------------------------------------------------------- the reader
_REQUIRED = object()
_LENGTH = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*d\s*$")


def _line_map(node: yaml.Node | None, path: str, out: dict[str, int]) -> None:
    """Record the 1-based line of every field of a composed YAML node tree."""
    if node is None:
        return
    out.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            sub = f"{path}.{key.value}" if path else str(key.value)
            out[sub] = key.start_mark.line + 1
            _line_map(value, sub, out)
    elif isinstance(node, yaml.SequenceNode):
        for i, value in enumerate(node.value):
            _line_map(value, f"{path}[{i}]", out)


def _describe(value: Any) -> str:
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if value is None:
        return "nothing (null)"
    return repr(value)


class _Reader:
    """Typed field access that collects problems instead of raising."""

    def __init__(self, lines: dict[str, int]) -> None:
        self.lines = lines
        self.problems: list[Problem] = []
        self.warnings: list[Problem] = []
        self.diameter = 0.5

    def line(self, path: str) -> int | None:
        while path:
            if path in self.lines:
                return self.lines[path]
            path = re.sub(r"(\.[^.\[\]]*|\[\d+\])$", "", path)
        return None

    def fail(self, path: str, message: str) -> None:
        self.problems.append(Problem(path, message, self.line(path)))

    def warn(self, path: str, message: str) -> None:
        self.warnings.append(Problem(path, message, self.line(path)))

    # -- structure
    def mapping(self, value: Any, path: str) -> dict[str, Any] | None:
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            self.fail(path, f"expected a mapping of keys, got {_describe(value)}")
            return None
        return dict(value)

    def keys(self, m: dict[str, Any], allowed: tuple[str, ...], path: str) -> None:
        for key in m:
            if key in allowed:
                continue
            sub = f"{path}.{key}" if path else str(key)
            near = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            self.fail(sub, f"unknown key {key!r} (allowed: {', '.join(allowed)}){hint}")

    def get(self, m: dict[str, Any], key: str, path: str, default: Any) -> tuple[Any, str]:
        sub = f"{path}.{key}" if path else key
        if key not in m or (m[key] is None and default is not _REQUIRED):
            if default is _REQUIRED:
                self.fail(sub, "required key is missing")
            return default, sub
        return m[key], sub

    # -- scalars
    def number(
        self,
        m: dict[str, Any],
        key: str,
        path: str,
        default: Any = _REQUIRED,
        *,
        positive: bool = False,
        minimum: float | None = None,
        length: bool = False,
    ) -> Any:
        value, sub = self.get(m, key, path, default)
        if value is default:
            return None if default is _REQUIRED else default
        return self.check_number(value, sub, positive=positive, minimum=minimum, length=length)

    def check_number(
        self,
        value: Any,
        path: str,
        *,
        positive: bool = False,
        minimum: float | None = None,
        length: bool = False,
    ) -> float | None:
        expected = "a number in metres or a multiple of d like '3d'" if length else "a number"
        if length and isinstance(value, str):
            match = _LENGTH.match(value)
            if not match:
                self.fail(path, f"expected {expected} (got {value!r})")
                return None
            value = float(match.group(1)) * self.diameter
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(path, f"expected {expected} (got {_describe(value)})")
            return None
        value = float(value)
        if not math.isfinite(value):
            self.fail(path, f"expected a finite number (got {value})")
            return None
        if positive and value <= 0:
            self.fail(path, f"must be greater than 0 (got {value:g})")
            return None
        if minimum is not None and value < minimum:
            self.fail(path, f"must be at least {minimum:g} (got {value:g})")
            return None
        return value

    def integer(
        self, m: dict[str, Any], key: str, path: str, default: Any, *, minimum: int
    ) -> Any:
        value, sub = self.get(m, key, path, default)
        if value is default:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(sub, f"expected a whole number (got {_describe(value)})")
            return None
        if value < minimum:
            self.fail(sub, f"must be at least {minimum} (got {value})")
            return None
        return value

    def boolean(self, m: dict[str, Any], key: str, path: str, default: bool) -> bool:
        value, sub = self.get(m, key, path, default)
        if not isinstance(value, bool):
            self.fail(sub, f"expected true or false (got {_describe(value)})")
            return default
        return value

    def string(self, m: dict[str, Any], key: str, path: str, default: Any) -> Any:
        value, sub = self.get(m, key, path, default)
        if value is default:
            return default
        if not isinstance(value, str) or not value.strip():
            self.fail(sub, f"expected a non-empty string (got {_describe(value)})")
            return None if default is _REQUIRED else default
        return value

    def choice(
        self, m: dict[str, Any], key: str, path: str, default: Any, choices: tuple[str, ...]
    ) -> Any:
        value, sub = self.get(m, key, path, default)
        if value is default:
            return default
        if value not in choices:
            near = difflib.get_close_matches(str(value), choices, n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            self.fail(sub, f"unknown value {_describe(value)} (expected one of: "
                      f"{', '.join(choices)}){hint}")
            return None
        return value

    def vector(
        self,
        m: dict[str, Any],
        key: str,
        path: str,
        size: int,
        default: Any = _REQUIRED,
        *,
        length: bool = False,
    ) -> Any:
        value, sub = self.get(m, key, path, default)
        if value is default:
            return default
        return self.check_vector(value, sub, size, length=length)

    def check_vector(
        self, value: Any, path: str, size: int, *, length: bool = False
    ) -> tuple[float, ...] | None:
        if not isinstance(value, list | tuple) or len(value) != size:
            got = _describe(value)
            self.fail(path, f"expected a list of {size} numbers (got {got})")
            return None
        out = [self.check_number(v, f"{path}[{i}]", length=length) for i, v in enumerate(value)]
        if any(v is None for v in out):
            return None
        return tuple(out)

    def points(
        self, m: dict[str, Any], key: str, path: str, minimum: int
    ) -> tuple[tuple[float, float], ...] | None:
        value, sub = self.get(m, key, path, _REQUIRED)
        if value is _REQUIRED:
            return None
        if not isinstance(value, list) or len(value) < minimum:
            self.fail(sub, f"expected a list of at least {minimum} [x1, x2] points "
                      f"(got {_describe(value)})")
            return None
        pts = [self.check_vector(p, f"{sub}[{i}]", 2, length=True) for i, p in enumerate(value)]
        if any(p is None for p in pts):
            return None
        return tuple(pts)


# ---------------------------------------------------------------------------- sections
TOP_KEYS = (
    "name",
    "description",
    "duration",
    "dt",
    "substeps",
    "seed",
    "record_every",
    "vehicle",
    "reference",
    "formation",
    "vehicles",
    "platoon",
    "recovery",
    "failures",
    "obstacles",
    "metrics",
)
VEHICLE_PARAM_KEYS = (
    "diameter",
    "mass",
    "gains",
    "max_accel",
    "v1_max",
    "v2_max",
    "motor_accel",
)
VEHICLE_KEYS = ("name", "pose", "offset", "leader", "color", "drive", *VEHICLE_PARAM_KEYS)
GAIN_KEYS = ("k1", "k2", "k3", "k4", "kp")
REFERENCE_KEYS = {
    "point": ("position",),
    "line": ("start", "heading", "speed"),
    "circle": ("center", "radius", "speed", "phase"),
    "lemniscate": ("center", "size", "speed"),
    "waypoints": ("points", "speed"),
}
OBSTACLE_KEYS = {
    "circle": ("center", "radius"),
    "box": ("center", "size", "angle"),
    "polygon": ("points",),
    "wall": ("from", "to", "thickness"),
}
RECOVERY_KEYS = ("strategy", "beta", "R", "r", "leader_avoids", "target_derivatives",
                 "steepness")
FAILURE_KEYS = ("vehicle", "at", "kind", "until", "v1", "v2")
PLATOON_KEYS = ("count", "pattern", "spacing", "jitter", "columns", "prefix")


def _vehicle_params(rd: _Reader, m: dict[str, Any], path: str, base: dict[str, Any]) -> dict:
    """Read the physical/controller parameters shared by ``vehicle:`` and each vehicle."""
    out = dict(base)
    out["diameter"] = rd.number(m, "diameter", path, base["diameter"], positive=True)
    out["mass"] = rd.number(m, "mass", path, base["mass"], positive=True)
    for key in ("max_accel", "v1_max", "v2_max"):
        out[key] = rd.number(m, key, path, base[key], positive=True)
    out["motor_accel"] = rd.number(m, "motor_accel", path, base["motor_accel"], positive=True)
    gains_doc, gains_path = rd.get(m, "gains", path, None)
    gains = dict(base["gains"])
    if gains_doc is not None:
        g = rd.mapping(gains_doc, gains_path)
        if g is not None:
            rd.keys(g, GAIN_KEYS, gains_path)
            for key in GAIN_KEYS:
                gains[key] = rd.number(g, key, gains_path, gains[key])
    out["gains"] = gains
    return out


def _reference(rd: _Reader, doc: Any, path: str) -> ReferenceSpec | None:
    m = rd.mapping(doc, path)
    if m is None:
        return None
    kind = rd.choice(m, "type", path, _REQUIRED, REFERENCE_TYPES)
    if kind is None or kind is _REQUIRED:
        return None
    rd.keys(m, ("type", *REFERENCE_KEYS[kind]), path)
    kw: dict[str, Any] = {"type": kind}
    if kind == "point":
        kw["position"] = rd.vector(m, "position", path, 2, length=True)
    elif kind == "line":
        kw["start"] = rd.vector(m, "start", path, 2, (0.0, 0.0), length=True)
        kw["heading"] = rd.number(m, "heading", path, 0.0)
        kw["speed"] = rd.number(m, "speed", path, 1.0, minimum=0.0)
    elif kind == "circle":
        kw["center"] = rd.vector(m, "center", path, 2, (0.0, 0.0), length=True)
        kw["radius"] = rd.number(m, "radius", path, positive=True, length=True)
        kw["speed"] = rd.number(m, "speed", path, 1.0)
        kw["phase"] = rd.number(m, "phase", path, 0.0)
    elif kind == "lemniscate":
        kw["center"] = rd.vector(m, "center", path, 2, (0.0, 0.0), length=True)
        kw["size"] = rd.number(m, "size", path, positive=True, length=True)
        kw["speed"] = rd.number(m, "speed", path, 1.0, positive=True)
    else:
        kw["points"] = rd.points(m, "points", path, 2)
        kw["speed"] = rd.number(m, "speed", path, 1.0, positive=True)
        pts = kw["points"]
        if pts is not None and any(
            math.hypot(b[0] - a[0], b[1] - a[1]) == 0 for a, b in zip(pts, pts[1:], strict=False)
        ):
            rd.fail(f"{path}.points", "two consecutive points are equal (expected distinct)")
            return None
    if any(v is None for v in kw.values()):
        return None
    return ReferenceSpec(**kw)


def _drive(rd: _Reader, doc: Any, path: str) -> DriveSpec:
    m = rd.mapping(doc, path)
    if m is None:
        return DriveSpec()
    rd.keys(m, ("type", "schedule"), path)
    kind = rd.choice(m, "type", path, "reference", DRIVE_TYPES)
    if kind != "commands":
        if "schedule" in m:
            rd.fail(f"{path}.schedule", "a schedule needs type: commands")
        return DriveSpec()
    rows, sub = rd.get(m, "schedule", path, _REQUIRED)
    if rows is _REQUIRED:
        return DriveSpec()
    if not isinstance(rows, list) or not rows:
        rd.fail(sub, f"expected a list of [t, v1, v2] rows (got {_describe(rows)})")
        return DriveSpec()
    schedule = [rd.check_vector(r, f"{sub}[{i}]", 3) for i, r in enumerate(rows)]
    if any(r is None for r in schedule):
        return DriveSpec()
    times = [r[0] for r in schedule]
    if any(b <= a for a, b in zip(times, times[1:], strict=False)):
        rd.fail(sub, f"row times must increase (got {times})")
    return DriveSpec("commands", tuple(schedule))


def _vehicles(
    rd: _Reader, doc: Any, path: str, params: dict[str, Any]
) -> list[VehicleSpec]:
    if doc is None:
        return []
    if not isinstance(doc, list):
        rd.fail(path, f"expected a list of vehicles (got {_describe(doc)})")
        return []
    out = []
    for i, item in enumerate(doc):
        sub = f"{path}[{i}]"
        m = rd.mapping(item, sub)
        if m is None:
            continue
        rd.keys(m, VEHICLE_KEYS, sub)
        name = rd.string(m, "name", sub, f"vehicle{i}")
        pose = rd.vector(m, "pose", sub, 3, _REQUIRED)
        if pose is not None and pose is not _REQUIRED:
            pose = (
                rd.check_number(pose[0], f"{sub}.pose[0]", length=True),
                rd.check_number(pose[1], f"{sub}.pose[1]", length=True),
                pose[2],
            )
        offset = rd.vector(m, "offset", sub, 2, (0.0, 0.0), length=True)
        leader = rd.boolean(m, "leader", sub, False)
        color = rd.string(m, "color", sub, PALETTE[i % len(PALETTE)])
        drive = _drive(rd, m["drive"], f"{sub}.drive") if m.get("drive") else DriveSpec()
        p = _vehicle_params(rd, m, sub, params)
        if pose is None or pose is _REQUIRED or offset is None or None in pose:
            continue
        out.append(_make_vehicle(name, pose, offset, leader, color, drive, p))
    return out


def _make_vehicle(
    name: str,
    pose: tuple[float, float, float],
    offset: tuple[float, float],
    leader: bool,
    color: str,
    drive: DriveSpec,
    p: dict[str, Any],
) -> VehicleSpec:
    return VehicleSpec(
        name=name,
        pose=tuple(pose),
        offset=tuple(offset),
        leader=leader,
        color=color,
        diameter=p["diameter"],
        mass=p["mass"],
        gains=Gains(**p["gains"]),
        v1_max=p["v1_max"],
        v2_max=p["v2_max"],
        max_accel=p["max_accel"],
        motor_accel=p["motor_accel"],
        drive=drive,
    )


def _platoon(rd: _Reader, doc: Any, path: str) -> PlatoonSpec | None:
    m = rd.mapping(doc, path)
    if m is None:
        return None
    rd.keys(m, PLATOON_KEYS, path)
    count = rd.integer(m, "count", path, _REQUIRED, minimum=1)
    pattern = rd.choice(m, "pattern", path, "grid", PLATOON_PATTERNS)
    spacing = rd.number(m, "spacing", path, 2.0 * rd.diameter, positive=True, length=True)
    jitter = rd.number(m, "jitter", path, 0.0, minimum=0.0, length=True)
    columns = rd.integer(m, "columns", path, None, minimum=1)
    prefix = rd.string(m, "prefix", path, "v")
    if None in (pattern, spacing, jitter, prefix) or count in (None, _REQUIRED):
        return None
    return PlatoonSpec(count, pattern, spacing, jitter, columns, prefix)


def platoon_offsets(spec: PlatoonSpec) -> np.ndarray:
    """Leader-frame offsets of the generated vehicles, shape ``(count, 2)`` [m].

    The leader sits at the origin facing +x1; followers are placed behind it (negative
    delta1): ``grid`` rows of ``columns`` (default about sqrt(count)) centred sideways,
    ``line`` in single file, ``wedge`` a V of two arms, ``ring`` on a circle around it.
    """
    n, s = spec.count, spec.spacing
    k = np.arange(n)
    if spec.pattern == "line":
        return np.stack((-(k + 1.0) * s, np.zeros(n)), -1)
    if spec.pattern == "wedge":
        rank = k // 2 + 1.0
        side = np.where(k % 2 == 0, 1.0, -1.0)
        return np.stack((-rank * s, side * rank * s), -1)
    if spec.pattern == "ring":
        radius = max(s * n / (2 * math.pi), 2.0 * s)
        phi = 2 * math.pi * k / n
        return np.stack((radius * np.cos(phi), radius * np.sin(phi)), -1)
    cols = spec.columns or max(1, math.ceil(math.sqrt(n)))
    row, col = k // cols, k % cols
    return np.stack((-(row + 1.0) * s, (col - (cols - 1) / 2.0) * s), -1)


def _expand_platoon(
    spec: PlatoonSpec,
    listed: list[VehicleSpec],
    params: dict[str, Any],
    seed: int,
    reference: ReferenceSpec | None,
) -> list[VehicleSpec]:
    """Create the platoon's vehicles, starting on their slots (jittered by ``seed``)."""
    leader = next((v for v in listed if v.leader), None)
    if leader is not None:
        x, y, th = leader.pose
    elif reference is not None:
        p, dp, _ = reference.build().evaluate(0.0)
        x, y, th = float(p[0]), float(p[1]), math.atan2(dp[1], dp[0]) if np.any(dp) else 0.0
    else:
        x, y, th = 0.0, 0.0, 0.0
    delta = platoon_offsets(spec)
    c, s = math.cos(th), math.sin(th)
    world = np.stack((c * delta[:, 0] - s * delta[:, 1], s * delta[:, 0] + c * delta[:, 1]), -1)
    rng = np.random.default_rng(seed)
    jitter = rng.uniform(-spec.jitter, spec.jitter, size=(spec.count, 2))
    start = np.array([x, y]) + world + jitter
    out = []
    for i in range(spec.count):
        pose = (float(start[i, 0]), float(start[i, 1]), th)
        offset = (float(delta[i, 0]), float(delta[i, 1]))
        color = PALETTE[(len(listed) + i) % len(PALETTE)]
        out.append(
            _make_vehicle(f"{spec.prefix}{i}", pose, offset, False, color, DriveSpec(), params)
        )
    return out


def _recovery(rd: _Reader, doc: Any, path: str) -> RecoverySpec:
    m = rd.mapping(doc, path)
    if m is None:
        return RecoverySpec(R=3.0 * rd.diameter)
    rd.keys(m, RECOVERY_KEYS, path)
    strategy = rd.choice(m, "strategy", path, "none", STRATEGIES)
    beta = rd.number(m, "beta", path, 1.0, minimum=0.0)
    big_r = rd.number(m, "R", path, 3.0 * rd.diameter, positive=True, length=True)
    small_r = rd.number(m, "r", path, None, positive=True, length=True)
    leader_avoids = rd.boolean(m, "leader_avoids", path, False)
    derivs = rd.choice(m, "target_derivatives", path, "hold", TARGET_DERIVATIVES)
    steep = rd.number(m, "steepness", path, 2.0, positive=True)
    if big_r is not None:
        if small_r is None and strategy in ("continuous", "smooth"):
            small_r = big_r / 2.0
        if small_r is not None and small_r >= big_r:
            rd.fail(f"{path}.r", f"must be smaller than R (got r = {small_r:g} m, "
                    f"R = {big_r:g} m)")
        if big_r < rd.diameter:
            rd.warn(f"{path}.R", f"R = {big_r:g} m is smaller than the vehicle diameter "
                    f"{rd.diameter:g} m: avoidance starts only after contact")
    return RecoverySpec(
        strategy=strategy or "none",
        beta=beta if beta is not None else 1.0,
        R=big_r if big_r is not None else 3.0 * rd.diameter,
        r=small_r,
        leader_avoids=leader_avoids,
        target_derivatives=derivs or "hold",
        steepness=steep or 2.0,
    )


def _failures(rd: _Reader, doc: Any, path: str) -> list[FailureSpec]:
    if doc is None:
        return []
    if not isinstance(doc, list):
        rd.fail(path, f"expected a list of failures (got {_describe(doc)})")
        return []
    out = []
    for i, item in enumerate(doc):
        sub = f"{path}[{i}]"
        m = rd.mapping(item, sub)
        if m is None:
            continue
        rd.keys(m, FAILURE_KEYS, sub)
        vehicle = rd.string(m, "vehicle", sub, _REQUIRED)
        at = rd.number(m, "at", sub, _REQUIRED, minimum=0.0)
        kind = rd.choice(m, "kind", sub, _REQUIRED, FAILURE_KINDS)
        until = rd.number(m, "until", sub, None, minimum=0.0)
        v1 = rd.number(m, "v1", sub, None)
        v2 = rd.number(m, "v2", sub, None)
        if kind == "spin" and v2 is None:
            v2 = 1.0
        if kind == "uncontrolled" and v1 is None and "v1" not in m:
            rd.fail(f"{sub}.v1", "required for an uncontrolled failure (the constant speed)")
        if kind == "crash" and until is not None:
            rd.fail(f"{sub}.until", "a crash is permanent: remove 'until'")
        if at is not None and until is not None and until <= at:
            rd.fail(f"{sub}.until", f"must be later than at = {at:g} s (got {until:g})")
        if None in (vehicle, at, kind) or _REQUIRED in (vehicle, at, kind):
            continue
        out.append(FailureSpec(vehicle, at, kind, until, v1, v2))
    return out


def _obstacles(rd: _Reader, doc: Any, path: str) -> list[ObstacleSpec]:
    if doc is None:
        return []
    if not isinstance(doc, list):
        rd.fail(path, f"expected a list of obstacles (got {_describe(doc)})")
        return []
    out = []
    for i, item in enumerate(doc):
        sub = f"{path}[{i}]"
        m = rd.mapping(item, sub)
        if m is None:
            continue
        kind = rd.choice(m, "type", sub, _REQUIRED, OBSTACLE_TYPES)
        if kind is None or kind is _REQUIRED:
            continue
        rd.keys(m, ("type", "name", *OBSTACLE_KEYS[kind]), sub)
        kw: dict[str, Any] = {"type": kind, "name": rd.string(m, "name", sub, f"obstacle[{i}]")}
        if kind == "circle":
            kw["center"] = rd.vector(m, "center", sub, 2, length=True)
            kw["radius"] = rd.number(m, "radius", sub, positive=True, length=True)
        elif kind == "box":
            kw["center"] = rd.vector(m, "center", sub, 2, length=True)
            kw["size"] = rd.vector(m, "size", sub, 2, length=True)
            kw["angle"] = rd.number(m, "angle", sub, 0.0)
            if kw["size"] is not None and min(kw["size"]) <= 0:
                rd.fail(f"{sub}.size", f"both sides must be greater than 0 (got {kw['size']})")
                kw["size"] = None
        elif kind == "polygon":
            kw["points"] = rd.points(m, "points", sub, 3)
            if kw["points"] is not None and not _is_convex(kw["points"]):
                rd.fail(f"{sub}.points", "the polygon must be convex with non-zero area "
                        "(split a concave obstacle into several polygons)")
                kw["points"] = None
        else:
            kw["start"] = rd.vector(m, "from", sub, 2, length=True)
            kw["end"] = rd.vector(m, "to", sub, 2, length=True)
            kw["thickness"] = rd.number(m, "thickness", sub, 0.1, positive=True, length=True)
            if kw["start"] is not None and kw["start"] == kw["end"]:
                rd.fail(f"{sub}.to", "must differ from 'from' (a wall needs a length)")
                kw["end"] = None
        if any(v is None for v in kw.values()):
            continue
        out.append(ObstacleSpec(**kw))
    return out


def _is_convex(points: tuple[tuple[float, float], ...]) -> bool:
    p = np.asarray(points, dtype=float)
    d1 = np.roll(p, -1, axis=0) - p
    d2 = np.roll(d1, -1, axis=0)
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    area = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    return abs(area) > 1e-12 and (bool(np.all(cross >= -1e-12)) or bool(np.all(cross <= 1e-12)))


# ---------------------------------------------------------------------------- entry points
def parse_scenario(
    doc: Any,
    *,
    source: str | None = None,
    lines: dict[str, int] | None = None,
    overrides: list[str] | None = None,
) -> Scenario:
    """Validate a scenario document (as loaded from YAML) and return a :class:`Scenario`.

    Parameters
    ----------
    doc : mapping
        The document.
    source : str, optional
        File name used in error messages.
    lines : dict, optional
        Line of each field path (filled by :func:`load_scenario`).
    overrides : list of str, optional
        ``path=value`` assignments applied before validation (the CLI's ``--set``).

    Raises
    ------
    ScenarioError
        With one :class:`~sandbox.errors.Problem` per problem found.
    """
    rd = _Reader(lines or {})
    if doc is None:
        raise ScenarioError([Problem("", "the file is empty (expected a scenario mapping)")],
                            source)
    if not isinstance(doc, Mapping):
        raise ScenarioError(
            [Problem("", f"expected a mapping of scenario keys at the top (got {_describe(doc)})",
                     1 if lines is not None else None)],
            source,
        )
    doc = copy.deepcopy(dict(doc))
    for item in overrides or []:
        _apply_override(rd, doc, item)
    rd.keys(doc, TOP_KEYS, "")

    default_name = Path(source).stem if source else "scenario"
    name = rd.string(doc, "name", "", default_name) or default_name
    description = doc.get("description") or ""
    if not isinstance(description, str):
        rd.fail("description", f"expected a string (got {_describe(description)})")
        description = ""
    duration = rd.number(doc, "duration", "", 20.0, positive=True)
    dt = rd.number(doc, "dt", "", 0.01, positive=True)
    substeps = rd.integer(doc, "substeps", "", 4, minimum=1)
    seed = rd.integer(doc, "seed", "", 0, minimum=0)
    record_every = rd.integer(doc, "record_every", "", 1, minimum=1)

    vehicle_doc = rd.mapping(doc.get("vehicle"), "vehicle") or {}
    rd.keys(vehicle_doc, VEHICLE_PARAM_KEYS, "vehicle")
    base = {
        "diameter": 0.5,
        "mass": 10.0,
        "max_accel": None,
        "v1_max": None,
        "v2_max": None,
        "motor_accel": 200.0,
        "gains": asdict(Gains()),
    }
    params = _vehicle_params(rd, vehicle_doc, "vehicle", base)
    rd.diameter = params["diameter"] or 0.5

    reference = None
    if doc.get("reference") is not None:
        reference = _reference(rd, doc["reference"], "reference")
    formation = None
    if doc.get("formation") is not None:
        fm = rd.mapping(doc["formation"], "formation")
        if fm is not None:
            rd.keys(fm, ("law", "rotate"), "formation")
            law = rd.choice(fm, "law", "formation", _REQUIRED, tuple(LAWS))
            rotate = rd.boolean(fm, "rotate", "formation", False)
            if "rotate" in fm and law in ("fixed", "rotating", "own_estimate"):
                rd.fail("formation.rotate", f"applies only to the virtual and leader_ref laws "
                        f"(law {law} fixes the frame of its offsets)")
            if law not in (None, _REQUIRED):
                formation = FormationSpec(law, rotate)

    vehicles = _vehicles(rd, doc.get("vehicles"), "vehicles", params)
    platoon = None
    if doc.get("platoon") is not None:
        platoon = _platoon(rd, doc["platoon"], "platoon")
        if platoon is not None and seed is not None:
            vehicles += _expand_platoon(platoon, vehicles, params, seed, reference)
    recovery = _recovery(rd, doc.get("recovery"), "recovery")
    failures = _failures(rd, doc.get("failures"), "failures")
    obstacles = _obstacles(rd, doc.get("obstacles"), "obstacles")
    mdoc = rd.mapping(doc.get("metrics"), "metrics") or {}
    rd.keys(mdoc, ("settle_tol",), "metrics")
    metrics = MetricsSpec(rd.number(mdoc, "settle_tol", "metrics", 0.05, positive=True) or 0.05)

    if not rd.problems:
        _check_consistency(rd, duration, dt, vehicles, reference, formation, failures,
                           obstacles, platoon)
    if rd.problems:
        raise ScenarioError(rd.problems, source)
    return Scenario(
        name=name,
        description=description.strip(),
        duration=duration,
        dt=dt,
        substeps=substeps,
        seed=seed,
        record_every=record_every,
        vehicles=tuple(vehicles),
        reference=reference,
        formation=formation,
        recovery=recovery,
        failures=tuple(failures),
        obstacles=tuple(obstacles),
        platoon=platoon,
        metrics=metrics,
        diameter=rd.diameter,
        source=source,
        warnings=tuple(w.format(source) for w in rd.warnings),
    )


def _check_consistency(
    rd: _Reader,
    duration: float,
    dt: float,
    vehicles: list[VehicleSpec],
    reference: ReferenceSpec | None,
    formation: FormationSpec | None,
    failures: list[FailureSpec],
    obstacles: list[ObstacleSpec],
    platoon: PlatoonSpec | None,
) -> None:
    """Checks that involve several sections (run only when each section is valid)."""
    if not vehicles:
        rd.fail("vehicles", "at least one vehicle is required (a 'vehicles' list or a "
                "'platoon')")
        return
    if dt >= duration:
        rd.fail("dt", f"must be shorter than the duration {duration:g} s (got {dt:g})")
    for v in vehicles:
        g = v.gains
        for k_pos, k_vel, axis in ((g.k1, g.k2, "1"), (g.k3, g.k4, "3")):
            rho = discrete_spectral_radius(k_pos, k_vel, dt)
            if rho >= 1.0:
                rd.fail("dt", f"control period {dt:g} s is too long for the gains of "
                        f"{v.name} (k{axis}={k_pos:g}, k{int(axis) + 1}={k_vel:g}): the "
                        f"forward-Euler update of eq. (6) has spectral radius {rho:.3f} >= 1 "
                        "and diverges (expected a dt with radius < 1; 0.2 s for the "
                        "report's gains, well under 0.1 s in practice)")
                return
    names: dict[str, int] = {}
    for i, v in enumerate(vehicles):
        if v.name in names:
            rd.fail(f"vehicles[{i}].name", f"duplicate vehicle name {v.name!r} "
                    f"(also vehicles[{names[v.name]}]); expected unique names")
        names.setdefault(v.name, i)
    leaders = [i for i, v in enumerate(vehicles) if v.leader]
    if len(leaders) > 1:
        rd.fail(f"vehicles[{leaders[1]}].leader", f"two leaders ({vehicles[leaders[0]].name} "
                f"and {vehicles[leaders[1]].name}); expected at most one")
    law = formation.law if formation else None
    if formation is None and len(vehicles) > 1:
        rd.fail("formation", "required when there is more than one vehicle (expected "
                f"formation: {{law: one of {', '.join(LAWS)}}})")
    if law is not None and LAWS[law].needs_leader and len(leaders) != 1:
        rd.fail("vehicles", f"the {law} law needs exactly one vehicle with leader: true "
                f"(got {len(leaders)})")
    if platoon is not None and law is not None and LAWS[law].needs_leader and not leaders:
        rd.fail("platoon", "a platoon follows a leader: list one vehicle with leader: true")
    needs_ref = []
    for i, v in enumerate(vehicles):
        tracks = v.drive.type == "reference"
        if tracks and (len(vehicles) == 1 or v.leader or law == "virtual"):
            needs_ref.append(i)
    if (needs_ref or (law is not None and LAWS[law].needs_reference)) and reference is None:
        who = vehicles[needs_ref[0]].name if needs_ref else f"the {law} law"
        rd.fail("reference", f"required: {who} tracks the reference trajectory (or give the "
                "leader drive: {type: commands, schedule: ...})")
    n = len(vehicles)
    if n <= 2000:
        pos = np.array([v.pose[:2] for v in vehicles])
        rad = np.array([v.diameter / 2 for v in vehicles])
        i_idx, j_idx = np.triu_indices(n, 1)
        gap = np.hypot(*(pos[i_idx] - pos[j_idx]).T) - rad[i_idx] - rad[j_idx]
        for k in np.flatnonzero(gap < -1e-9)[:5]:
            a, b = i_idx[k], j_idx[k]
            rd.fail(f"vehicles[{b}].pose", f"{vehicles[b].name} starts overlapping "
                    f"{vehicles[a].name} (centres {gap[k] + rad[a] + rad[b]:.3g} m apart; "
                    f"expected at least {rad[a] + rad[b]:g} m)")
        off = np.array([v.offset for v in vehicles])
        d_off = np.hypot(*(off[i_idx] - off[j_idx]).T)
        for k in np.flatnonzero(d_off < 2 * np.maximum(rad[i_idx], rad[j_idx]) - 1e-9)[:3]:
            a, b = i_idx[k], j_idx[k]
            if law is not None and not (vehicles[a].leader or vehicles[b].leader):
                rd.warn(f"vehicles[{b}].offset", f"slots of {vehicles[a].name} and "
                        f"{vehicles[b].name} are {d_off[k]:.3g} m apart, closer than a "
                        "diameter: they cannot both reach them")
    for i, f in enumerate(failures):
        if f.vehicle not in names:
            near = difflib.get_close_matches(f.vehicle, list(names), n=1)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            rd.fail(f"failures[{i}].vehicle", f"no vehicle named {f.vehicle!r} (vehicles: "
                    f"{', '.join(list(names)[:10])}){hint}")
        if f.at >= duration:
            rd.fail(f"failures[{i}].at", f"must be within the run, before duration = "
                    f"{duration:g} s (got {f.at:g})")
    obstacle_names = [o.name for o in obstacles]
    for i, o in enumerate(obstacles):
        if o.name in names or obstacle_names.index(o.name) != i:
            rd.fail(f"obstacles[{i}].name", f"duplicate name {o.name!r} (expected names "
                    "unique among vehicles and obstacles)")


def _apply_override(rd: _Reader, doc: dict[str, Any], item: str) -> None:
    """Apply one ``path=value`` assignment (``recovery.beta=2``, ``vehicles[1].pose=[...]``)."""
    path, sep, raw = item.partition("=")
    path = path.strip()
    if not sep or not path:
        rd.fail(f"--set {item}", "expected path=value, e.g. recovery.beta=2.5")
        return
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError:
        value = raw
    tokens = re.findall(r"[^.\[\]]+|\[\d+\]", path)
    target: Any = doc
    for k, tok in enumerate(tokens):
        last = k == len(tokens) - 1
        if tok.startswith("["):
            idx = int(tok[1:-1])
            if not isinstance(target, list) or idx >= len(target):
                rd.fail(f"--set {path}", f"names no field: there is no item {tok} here")
                return
            if last:
                target[idx] = value
            else:
                target = target[idx]
            continue
        if not isinstance(target, dict):
            rd.fail(f"--set {path}", f"names no field: {tok!r} is not under a mapping")
            return
        allowed = _allowed_keys(tokens[:k], target)
        if tok not in allowed:
            near = difflib.get_close_matches(tok, allowed, n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            rd.fail(f"--set {path}", f"names no field ({tok!r} is not one of: "
                    f"{', '.join(allowed)}){hint}")
            return
        if last:
            target[tok] = value
        else:
            if target.get(tok) is None:
                target[tok] = {}
            target = target[tok]


def _allowed_keys(parents: list[str], node: dict[str, Any]) -> tuple[str, ...]:
    """Keys allowed at a position in the document (for ``--set``)."""
    names = [t for t in parents if not t.startswith("[")]
    if not names:
        return TOP_KEYS
    head = names[-1]
    if head == "gains":
        return GAIN_KEYS
    table: dict[str, tuple[str, ...]] = {
        "vehicle": VEHICLE_PARAM_KEYS,
        "vehicles": VEHICLE_KEYS,
        "recovery": RECOVERY_KEYS,
        "failures": FAILURE_KEYS,
        "platoon": PLATOON_KEYS,
        "metrics": ("settle_tol",),
        "formation": ("law", "rotate"),
        "drive": ("type", "schedule"),
        "reference": ("type", *REFERENCE_KEYS.get(node.get("type", ""), ())),
        "obstacles": ("type", "name", *OBSTACLE_KEYS.get(node.get("type", ""), ())),
    }
    return table.get(head, tuple(node))


def load_scenario(
    source: str | Path | Mapping[str, Any], overrides: list[str] | None = None
) -> Scenario:
    """Load and validate a scenario from a YAML file or a mapping.

    Parameters
    ----------
    source : path or mapping
        A ``.yaml`` file, or an already-loaded document (a dict).
    overrides : list of str, optional
        ``path=value`` assignments applied before validation.

    Raises
    ------
    ScenarioError
        The file cannot be read or parsed, or the document is invalid.
    """
    if isinstance(source, Mapping):
        return parse_scenario(source, overrides=overrides)
    path = Path(source)
    name = str(source)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError([Problem("", "no such file")], name) from None
    except IsADirectoryError:
        raise ScenarioError([Problem("", "is a directory, expected a YAML file")], name) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError([Problem("", f"cannot be read ({exc})")], name) from None
    try:
        loader = yaml.SafeLoader(text)
        try:
            node = loader.get_single_node()
            doc = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ScenarioError([Problem("", f"malformed YAML: {what}", line)], name) from None
    lines: dict[str, int] = {}
    _line_map(node, "", lines)
    return parse_scenario(doc, source=name, lines=lines, overrides=overrides)
