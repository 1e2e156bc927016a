"""JSON Schema (draft 2020-12) of the scenario format, for editors and other tools.

The schema is built from the loader's own tables in :mod:`sandbox.scenario`
(``TOP_KEYS``, ``VEHICLE_KEYS``, ``REFERENCE_KEYS``, ``OBSTACLE_KEYS``, the value lists
``REFERENCE_TYPES``, ``STRATEGIES``, ... and the registry of formation laws), so a key
the loader accepts cannot be missing from it: :func:`build_schema` raises if a key has
no entry in :data:`FIELDS` (its description, unit, default and type), and if an entry
names a key the loader does not know.

The schema checks what a single field can express: types, ranges, enums, required keys,
unknown keys (``additionalProperties: false``) and the ``"3d"`` length form. The checks
that involve several fields (``r < R``, unique names, leaders, overlapping vehicles, the
control-period bound of eq. (6), ...) are the loader's: ``sandbox validate`` remains the
reference. Optional keys also accept ``null`` (the loader then uses the default).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from sandbox.control.formation import LAWS
from sandbox.scenario import (
    _BAD_NAME,
    _LENGTH,
    DRIVE_KEYS,
    DRIVE_TYPES,
    FAILURE_KEYS,
    FAILURE_KINDS,
    FORMATION_KEYS,
    GAIN_KEYS,
    MAX_SUBSTEPS,
    MAX_VEHICLES,
    METRICS_KEYS,
    MIN_DIAMETER,
    MIN_MASS,
    OBSTACLE_KEYS,
    OBSTACLE_TYPES,
    PLATOON_KEYS,
    PLATOON_PATTERNS,
    RECOVERY_KEYS,
    REFERENCE_KEYS,
    REFERENCE_TYPES,
    STRATEGIES,
    TARGET_DERIVATIVES,
    TOP_KEYS,
    VEHICLE_KEYS,
    VEHICLE_PARAM_KEYS,
)

DRAFT = "https://json-schema.org/draft/2020-12/schema"
SCHEMA_ID = "https://sandbox.example/schemas/scenario.schema.json"

#: A length: metres, or a multiple of the default vehicle diameter (``"3d"``, ``1.5d``).
LENGTH_PATTERN = _LENGTH.pattern
#: The same, without a minus sign (lengths that must be positive).
POSITIVE_LENGTH_PATTERN = _LENGTH.pattern.replace("[-+]?", r"\+?", 1)
#: A name written into CSV rows and directory names: no commas, quotes or slashes.
NAME_PATTERN = r"^(?=.*\S)" + _BAD_NAME.pattern.replace("[", "[^", 1) + "+$"


# ---------------------------------------------------------------------- type fragments
def _number(minimum: float | None = None, exclusive: bool = False) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "number"}
    if minimum is not None:
        out["exclusiveMinimum" if exclusive else "minimum"] = minimum
    return out


def _positive() -> dict[str, Any]:
    return _number(0, exclusive=True)


def _length(positive: bool = False, minimum: float | None = None) -> dict[str, Any]:
    num = _positive() if positive else _number(minimum)
    pattern = POSITIVE_LENGTH_PATTERN if positive or minimum == 0 else LENGTH_PATTERN
    return {"anyOf": [num, {"type": "string", "pattern": pattern}]}


def _integer(minimum: int, maximum: int | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "integer", "minimum": minimum}
    if maximum is not None:
        out["maximum"] = maximum
    return out


def _point() -> dict[str, Any]:
    return {"type": "array", "items": _length(), "minItems": 2, "maxItems": 2}


def _points(minimum: int) -> dict[str, Any]:
    return {"type": "array", "items": _point(), "minItems": minimum}


def _enum(values: tuple[str, ...]) -> dict[str, Any]:
    return {"type": "string", "enum": list(values)}


def _text() -> dict[str, Any]:
    return {"type": "string", "minLength": 1, "pattern": r"\S"}


def _name() -> dict[str, Any]:
    return {"type": "string", "pattern": NAME_PATTERN}


def _boolean() -> dict[str, Any]:
    return {"type": "boolean"}


def _ref(name: str) -> dict[str, Any]:
    return {"$ref": f"#/$defs/{name}"}


def _randomize() -> dict[str, Any]:
    bound = {
        "anyOf": [
            {"type": "number"},
            {"type": "array", "items": {"type": "number"}, "minItems": 1},
        ]
    }
    pair = {"type": "array", "items": bound, "minItems": 2, "maxItems": 2}
    dist = {
        "oneOf": [
            {
                "type": "object",
                "properties": {"uniform": pair},
                "required": ["uniform"],
                "additionalProperties": False,
            },
            {
                "type": "object",
                "properties": {"normal": pair},
                "required": ["normal"],
                "additionalProperties": False,
            },
            {
                "type": "object",
                "properties": {"choice": {"type": "array", "minItems": 1}},
                "required": ["choice"],
                "additionalProperties": False,
            },
        ]
    }
    return {"type": "object", "additionalProperties": dist}


_NONE = object()


class Field:
    """Documentation and type of one key of the scenario format.

    Parameters
    ----------
    schema : callable
        Returns the key's type fragment.
    description : str
        What the key means (shown by editors).
    unit : str, optional
        Unit of the value (``"m"``, ``"s"``, ...); lengths also accept ``"3d"``.
    default : optional
        The value used when the key is left out (omit for required keys and for keys
        without a default).
    required : bool
        Whether the key must be present.
    """

    def __init__(
        self,
        schema: Callable[[], dict[str, Any]],
        description: str,
        unit: str | None = None,
        default: Any = _NONE,
        required: bool = False,
    ) -> None:
        self.schema = schema
        self.description = description
        self.unit = unit
        self.default = default
        self.required = required

    def build(self) -> dict[str, Any]:
        """The key's schema, with its description, unit and default."""
        out = dict(self.schema())
        text = self.description
        if self.unit:
            text = f"{text} [{self.unit}]"
        out["description"] = text
        if self.unit:
            out["x-unit"] = self.unit
        if self.default is not _NONE:
            out["default"] = self.default
        if not self.required:
            out = {"anyOf": [_strip(out), {"type": "null"}], **_docs(out)}
        return out


def _strip(fragment: dict[str, Any]) -> dict[str, Any]:
    return {
        k: v
        for k, v in fragment.items()
        if k not in ("description", "default", "x-unit")
    }


def _docs(fragment: dict[str, Any]) -> dict[str, Any]:
    return {
        k: v for k, v in fragment.items() if k in ("description", "default", "x-unit")
    }


_LAW_TEXT = "; ".join(
    f"{name}: {(law.__doc__ or '').strip().splitlines()[0]}"
    for name, law in LAWS.items()
)

#: Every key of every section: ``FIELDS[section][key]``. Each reference or obstacle
#: type has its own section (``reference.circle``, ``obstacles.box``).
FIELDS: dict[str, dict[str, Field]] = {
    "": {
        "name": Field(
            _name,
            "Name of the scenario; runs go to runs/<name>/ by default "
            "(default: the file name without .yaml)",
        ),
        "description": Field(
            lambda: {"type": "string"}, "Free text shown by 'sandbox list'", default=""
        ),
        "duration": Field(_positive, "Simulated time, > 0", "s", 20.0),
        "dt": Field(
            _positive,
            "Control period h, > 0; also the period of the backward "
            "differences of eqs. (8)-(9), (18)-(19). The forward-Euler update of eq. "
            "(6) needs dt < 0.2 s with the report's gains (checked by the loader)",
            "s",
            0.01,
        ),
        "substeps": Field(
            lambda: _integer(1, MAX_SUBSTEPS),
            "Physics steps per control period; keep v1 dt / substeps well "
            "below the vehicle radius",
            default=4,
        ),
        "seed": Field(
            lambda: _integer(0),
            "Seed of the platoon jitter; same scenario and seed give identical outputs",
            default=0,
        ),
        "record_every": Field(
            lambda: _integer(1),
            "Record one sample every N control "
            "periods (trajectory.csv and metrics use the samples)",
            default=1,
        ),
        "vehicle": Field(
            lambda: _ref("vehicleParams"),
            "Defaults for every vehicle (each vehicle may override them)",
        ),
        "reference": Field(
            lambda: _ref("reference"),
            "The reference trajectory tracked "
            "by the leader (or by every slot with law virtual)",
        ),
        "formation": Field(
            lambda: _ref("formation"),
            "The formation law of section 3; required with more than one vehicle",
        ),
        "vehicles": Field(
            lambda: {"type": "array", "items": _ref("vehicle")}, "The listed vehicles"
        ),
        "platoon": Field(
            lambda: _ref("platoon"),
            "Followers generated on a pattern, named <prefix>0, <prefix>1, ...",
        ),
        "recovery": Field(lambda: _ref("recovery"), "Collision avoidance, section 4"),
        "failures": Field(
            lambda: {"type": "array", "items": _ref("failure")},
            "Failures injected into vehicles",
        ),
        "obstacles": Field(
            lambda: {"type": "array", "items": _ref("obstacle")}, "Static obstacles"
        ),
        "metrics": Field(lambda: _ref("metrics"), "Parameters of metrics.json"),
        "randomize": Field(
            _randomize,
            "Random draws from the seed: field paths (the --set syntax, e.g. "
            "vehicles[1].pose) mapped to {uniform: [low, high]}, {normal: [mean, "
            "std]} (numbers or equal-length lists, elementwise) or {choice: [a, b, "
            "...]}; overlapping starts are redrawn (see sandbox/randomize.py)",
        ),
    },
    "vehicle": {
        "diameter": Field(
            lambda: _number(MIN_DIAMETER),
            "Vehicle diameter d (vehicles are discs); the unit of '3d' lengths",
            "m",
            0.5,
        ),
        "mass": Field(lambda: _number(MIN_MASS), "Vehicle mass", "kg", 10.0),
        "gains": Field(
            lambda: _ref("gains"),
            "Flatness controller gains, eqs. (4)-(6) (default: the report's)",
        ),
        "max_accel": Field(
            _positive,
            "Limit on |d chi / dt| (chi is clamped: no wind-up); default: unlimited",
            "m/s^2",
        ),
        "v1_max": Field(
            _positive, "Limit on the speed v1 = |chi|; default: unlimited", "m/s"
        ),
        "v2_max": Field(
            _positive, "Limit on the turn rate |v2|; default: unlimited", "rad/s"
        ),
        "motor_accel": Field(
            _positive,
            "A fixed strength of the physical motor (joint force = mass * "
            "motor_accel), which may be too weak to follow the commands (the run "
            "reports how often); default: a motor that follows every command while "
            "free and pushes with 200 m/s^2 in contact",
            "m/s^2",
        ),
    },
    "gains": {
        "k1": Field(
            _number, "Position gain on x1 of eq. (6), negative", "1/s^2", -100.0
        ),
        "k2": Field(_number, "Velocity gain on x1 of eq. (6), negative", "1/s", -20.0),
        "k3": Field(
            _number, "Position gain on x2 of eq. (6), negative", "1/s^2", -100.0
        ),
        "k4": Field(_number, "Velocity gain on x2 of eq. (6), negative", "1/s", -20.0),
        "kp": Field(_number, "Heading gain of eq. (5), positive", "1/s", 2.0),
    },
    "vehicles": {
        "name": Field(
            _name, "Unique among vehicles and obstacles (default: vehicle<i>)"
        ),
        "pose": Field(
            lambda: {
                "type": "array",
                "prefixItems": [_length(), _length(), _number()],
                "minItems": 3,
                "maxItems": 3,
            },
            "Initial pose [x1 [m], x2 [m], x3 heading [rad]]; vehicles start at "
            "rest and must not overlap",
            required=True,
        ),
        "offset": Field(
            _point,
            "Slot offset (delta1, delta2); its frame depends on the law",
            "m",
            [0.0, 0.0],
        ),
        "leader": Field(
            _boolean, "The vehicle the others follow (at most one)", default=False
        ),
        "color": Field(
            _text, "Colour name or #rrggbb (default: blue, red, green, ... in order)"
        ),
        "drive": Field(
            lambda: _ref("drive"), "How the vehicle is driven (default: by its law)"
        ),
    },
    "drive": {
        "type": Field(
            lambda: _enum(DRIVE_TYPES),
            "reference: driven by its law; commands: open loop by 'schedule'",
            default="reference",
        ),
        "schedule": Field(
            lambda: {
                "type": "array",
                "minItems": 1,
                "items": {
                    "type": "array",
                    "items": _number(),
                    "minItems": 3,
                    "maxItems": 3,
                },
            },
            "Rows [t [s], v1 [m/s], v2 [rad/s]] with increasing t, each held until the "
            "next "
            "(zero before the first)",
            required=True,
        ),
    },
    "reference.point": {
        "position": Field(
            _point, "The point to stabilize at, eq. (4)", "m", required=True
        ),
    },
    "reference.line": {
        "start": Field(_point, "Starting point", "m", [0.0, 0.0]),
        "heading": Field(_number, "Direction of travel", "rad", 0.0),
        "speed": Field(lambda: _number(0), "Speed along the line, >= 0", "m/s", 1.0),
    },
    "reference.circle": {
        "center": Field(_point, "Centre of the circle", "m", [0.0, 0.0]),
        "radius": Field(
            lambda: _length(positive=True), "Radius, > 0", "m", required=True
        ),
        "speed": Field(
            _number, "Speed along the circle; negative: clockwise", "m/s", 1.0
        ),
        "phase": Field(_number, "Starting angle on the circle", "rad", 0.0),
    },
    "reference.lemniscate": {
        "center": Field(_point, "Centre of the figure-eight", "m", [0.0, 0.0]),
        "size": Field(
            lambda: _length(positive=True), "Half-width, > 0", "m", required=True
        ),
        "speed": Field(_positive, "Mean speed over a lap, > 0", "m/s", 1.0),
    },
    "reference.waypoints": {
        "points": Field(
            lambda: _points(2),
            "At least 2 points [m], no two consecutive equal, joined by a C2 spline",
            required=True,
        ),
        "speed": Field(_positive, "Speed along the path, > 0", "m/s", 1.0),
    },
    "formation": {
        "law": Field(
            lambda: _enum(tuple(LAWS)), f"The formation law. {_LAW_TEXT}", required=True
        ),
        "rotate": Field(
            _boolean,
            "virtual and leader_ref only: turn the offsets with the "
            "reference's tangent, eqs. (14)-(15)",
            default=False,
        ),
    },
    "platoon": {
        "count": Field(
            lambda: _integer(1, MAX_VEHICLES),
            "Number of generated vehicles",
            required=True,
        ),
        "pattern": Field(
            lambda: _enum(PLATOON_PATTERNS),
            "grid: rows behind the leader; "
            "line: single file; wedge: a V; ring: a circle around the leader",
            default="grid",
        ),
        "spacing": Field(
            lambda: _length(positive=True),
            "Distance between neighbours, > 0",
            "m",
            "2d",
        ),
        "jitter": Field(
            lambda: _length(minimum=0),
            "Uniform random shift of each start "
            "position on each axis (seeded by 'seed'), >= 0",
            "m",
            0.0,
        ),
        "columns": Field(
            lambda: _integer(1),
            "grid only: vehicles per row (default: about sqrt(count))",
        ),
        "prefix": Field(_name, "Name prefix of the generated vehicles", default="v"),
    },
    "recovery": {
        "strategy": Field(
            lambda: _enum(STRATEGIES),
            "none; discontinuous (section 4.1); "
            "continuous (section 4.2, eq. (27)); smooth (tanh transition)",
            default="none",
        ),
        "beta": Field(
            lambda: _number(0),
            "Weight of the avoidance vectors, eq. (22), >= 0",
            default=1.0,
        ),
        "R": Field(lambda: _length(positive=True), "Safe-zone radius, > 0", "m", "3d"),
        "r": Field(
            lambda: _length(positive=True),
            "Inner radius, < R (continuous and smooth; default: R / 2)",
            "m",
        ),
        "leader_avoids": Field(
            _boolean, "Whether the leader avoids too (section 4.3.3)", default=False
        ),
        "target_derivatives": Field(
            lambda: _enum(TARGET_DERIVATIVES),
            "hold: the shifted target keeps the law's derivatives; "
            "estimate: the shift's derivatives are estimated and "
            "added",
            default="hold",
        ),
        "steepness": Field(_positive, "smooth only: tanh steepness, > 0", default=2.0),
    },
    "failures": {
        "vehicle": Field(_text, "Name of the failing vehicle", required=True),
        "at": Field(lambda: _number(0), "Onset, within the run", "s", required=True),
        "kind": Field(
            lambda: _enum(FAILURE_KINDS),
            "stuck_steering: v2 frozen; stop: v1 = "
            "v2 = 0; spin: v1 = 0, v2 = 'v2'; uncontrolled: constant 'v1', 'v2'; "
            "crash: immovable for good",
            required=True,
        ),
        "until": Field(
            lambda: _number(0),
            "End, later than 'at' (default: the end of the run; not for crash)",
            "s",
        ),
        "v1": Field(_number, "Constant speed (uncontrolled: required)", "m/s"),
        "v2": Field(
            _number,
            "Turn rate (spin: default 1; stuck_steering: default its value at onset)",
            "rad/s",
        ),
    },
    "obstacles.circle": {
        "center": Field(_point, "Centre", "m", required=True),
        "radius": Field(
            lambda: _length(positive=True), "Radius, > 0", "m", required=True
        ),
    },
    "obstacles.box": {
        "center": Field(_point, "Centre", "m", required=True),
        "size": Field(_point, "[width, height], both > 0", "m", required=True),
        "angle": Field(_number, "Rotation", "rad", 0.0),
    },
    "obstacles.polygon": {
        "points": Field(
            lambda: _points(3),
            "At least 3 corners [m] of a convex polygon",
            required=True,
        ),
    },
    "obstacles.wall": {
        "from": Field(_point, "One end of the wall", "m", required=True),
        "to": Field(
            _point, "The other end (different from 'from')", "m", required=True
        ),
        "thickness": Field(lambda: _length(positive=True), "Thickness, > 0", "m", 0.1),
    },
    "metrics": {
        "settle_tol": Field(
            _positive,
            "Formation error below which a vehicle counts as settled",
            "m",
            0.05,
        ),
        "settle_dwell": Field(
            lambda: _number(minimum=0.0),
            "How long the run must go on with the error in band after the settling "
            "time, else the settling time is null",
            "s",
            1.0,
        ),
        "contact_release": Field(
            _positive,
            "Gap between two surfaces beyond which a contact episode ends (closer "
            "returns are the same collision)",
            "m",
            0.01,
        ),
    },
}

#: The loader's key table of each section of :data:`FIELDS`.
SECTION_KEYS: dict[str, tuple[str, ...]] = {
    "": TOP_KEYS,
    "vehicle": VEHICLE_PARAM_KEYS,
    "gains": GAIN_KEYS,
    "vehicles": tuple(k for k in VEHICLE_KEYS if k not in VEHICLE_PARAM_KEYS),
    "drive": DRIVE_KEYS,
    "formation": FORMATION_KEYS,
    "platoon": PLATOON_KEYS,
    "recovery": RECOVERY_KEYS,
    "failures": FAILURE_KEYS,
    "metrics": METRICS_KEYS,
    **{f"reference.{t}": REFERENCE_KEYS[t] for t in REFERENCE_TYPES},
    **{f"obstacles.{t}": OBSTACLE_KEYS[t] for t in OBSTACLE_TYPES},
}


# ---------------------------------------------------------------------------- building
def _object(section: str, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """A closed object schema with the loader's keys of ``section``."""
    keys = SECTION_KEYS[section]
    docs = FIELDS.get(section)
    if docs is None:
        raise KeyError(f"schema: no FIELDS entry for section {section or 'top'!r}")
    missing = [k for k in keys if k not in docs]
    unknown = [k for k in docs if k not in keys]
    if missing or unknown:
        raise KeyError(
            f"schema: section {section or 'top'!r} is out of step with the "
            f"loader (undocumented keys: {missing}; unknown keys: {unknown})"
        )
    props = dict(extra or {})
    props.update({k: docs[k].build() for k in keys})
    out: dict[str, Any] = {
        "type": "object",
        "properties": props,
        "additionalProperties": False,
    }
    required = [k for k in keys if docs[k].required]
    if required:
        out["required"] = required
    return out


def _typed(group: str, types: tuple[str, ...], title: str) -> dict[str, Any]:
    """``oneOf`` the variants of a section selected by its ``type`` key."""
    variants = []
    for t in types:
        extra = {"type": {"const": t, "description": f"{title} type"}}
        if group == "obstacles":
            extra["name"] = {
                "anyOf": [_name(), {"type": "null"}],
                "description": "Names the obstacle in collision events "
                "(default: obstacle[<i>])",
            }
        variant = _object(f"{group}.{t}", extra)
        variant["required"] = ["type", *variant.get("required", [])]
        variant["title"] = f"{title}: {t}"
        variants.append(variant)
    return {
        "type": "object",
        "properties": {"type": _enum(types)},
        "required": ["type"],
        "oneOf": variants,
    }


def build_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scenario file.

    Raises
    ------
    KeyError
        If :data:`FIELDS` and the loader's key tables disagree.
    """
    length = {
        "anyOf": [{"type": "number"}, {"type": "string", "pattern": LENGTH_PATTERN}],
        "description": "A length: metres, or a multiple of the default vehicle "
        'diameter written like "3d" or 1.5d',
    }
    vehicle = _object("vehicles")
    params = _object("vehicle")
    vehicle["properties"].update(params["properties"])
    vehicle["description"] = (
        "A vehicle: its own keys, plus any key of 'vehicle' to "
        "override that default for this vehicle only"
    )
    failure = _object("failures")
    failure["allOf"] = [
        {
            "if": {
                "properties": {"kind": {"const": "uncontrolled"}},
                "required": ["kind"],
            },
            "then": {"required": ["v1"]},
        },
        {
            "if": {"properties": {"kind": {"const": "crash"}}, "required": ["kind"]},
            "then": {"not": {"required": ["until"]}},
        },
    ]
    drive = _object("drive")
    drive.pop("required")
    drive["if"] = {"properties": {"type": {"const": "commands"}}, "required": ["type"]}
    drive["then"] = {"required": ["schedule"]}
    drive["else"] = {"not": {"required": ["schedule"]}}
    top = _object("")
    return {
        "$schema": DRAFT,
        "$id": SCHEMA_ID,
        "title": "sandbox scenario",
        "description": "A scenario file of sandbox (a YAML document). Lengths in "
        "metres or "
        'as multiples of the vehicle diameter ("3d"); angles in radians; times in '
        "seconds. Checks across fields are done by 'sandbox validate'.",
        **{k: top[k] for k in ("type", "properties", "additionalProperties")},
        "$defs": {
            "length": length,
            "vehicleParams": params,
            "gains": _object("gains"),
            "vehicle": vehicle,
            "drive": drive,
            "reference": _typed("reference", REFERENCE_TYPES, "Reference"),
            "formation": _object("formation"),
            "platoon": _object("platoon"),
            "recovery": _object("recovery"),
            "failure": failure,
            "obstacle": _typed("obstacles", OBSTACLE_TYPES, "Obstacle"),
            "metrics": _object("metrics"),
        },
    }


def schema_json() -> str:
    """The schema as indented JSON text, with a trailing newline."""
    return json.dumps(build_schema(), indent=2) + "\n"
