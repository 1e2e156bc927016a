"""The vehicle sections: shared defaults, gains, listed vehicles, drives, platoons.

Declared here (``VEHICLE_PARAMS``, ``GAINS``, ``VEHICLE``, ``DRIVE``, ``PLATOON``)
beside the code that reads them, including the generation of a platoon's vehicles on
the slots their formation law gives at t = 0.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from sandbox import plugins
from sandbox.model.flatness import (
    Gains,
)
from sandbox.plugins.registration import (
    Param,
)
from sandbox.scenario.reader import (
    MAX_VEHICLES,
    MIN_DIAMETER,
    MIN_MASS,
    REQUIRED,
    Reader,
    describe,
)
from sandbox.scenario.sections import read_param, read_params, section_param
from sandbox.scenario.sensors import read_sensors
from sandbox.scenario.specs import (
    DRIVE_TYPES,
    PALETTE,
    PLATOON_PATTERNS,
    DriveSpec,
    FormationSpec,
    PlatoonSpec,
    ReferenceSpec,
    SensorsSpec,
    VehicleSpec,
)

#: The least acceleration limit [m/s^2]: a stop from 1 m/s then takes 17 minutes (the
#: braking barrier plans every vehicle's stop period by period).
MIN_ACCEL = 1e-3

VEHICLE_PARAMS: dict[str, Param] = {
    "diameter": Param(
        "number",
        0.5,
        "m",
        "Vehicle diameter d (vehicles are discs); the unit of '3d' lengths",
        minimum=MIN_DIAMETER,
    ),
    "mass": Param("number", 10.0, "kg", "Vehicle mass", minimum=MIN_MASS),
    "gains": Param(
        **section_param("gains"),
        doc="Flatness controller gains, eqs. (4)-(6) (default: the report's)",
    ),
    "max_accel": Param(
        "number",
        None,
        "m/s^2",
        "Limit on |d chi / dt| (chi is clamped: no wind-up); default: unlimited",
        minimum=MIN_ACCEL,
    ),
    "v1_max": Param(
        "number",
        None,
        "m/s",
        "Limit on the speed v1 = |chi|; default: unlimited",
        minimum=0.0,
        exclusive=True,
    ),
    "v2_max": Param(
        "number",
        None,
        "rad/s",
        "Limit on the turn rate |v2|; default: unlimited",
        minimum=0.0,
        exclusive=True,
    ),
    "motor_accel": Param(
        "number",
        None,
        "m/s^2",
        "A fixed strength of the physical motor (joint force = mass * motor_accel), "
        "which may be too weak to follow the commands (the run reports how often); "
        "default: a motor that follows every command while free and pushes with 200 "
        "m/s^2 in contact",
        minimum=MIN_ACCEL,
    ),
}

GAINS: dict[str, Param] = {
    "k1": Param("number", Gains().k1, "1/s^2", "Position gain on x1 of eq. (6)"),
    "k2": Param("number", Gains().k2, "1/s", "Velocity gain on x1 of eq. (6)"),
    "k3": Param("number", Gains().k3, "1/s^2", "Position gain on x2 of eq. (6)"),
    "k4": Param("number", Gains().k4, "1/s", "Velocity gain on x2 of eq. (6)"),
    "kp": Param("number", Gains().kp, "1/s", "Heading gain of eq. (5)"),
}

VEHICLE: dict[str, Param] = {
    "name": Param(
        "name", None, doc="Unique among vehicles and obstacles (default: vehicle<i>)"
    ),
    "pose": Param(
        "custom",
        doc="Initial pose [x1 [m], x2 [m], x3 heading [rad]]; vehicles start at rest "
        "and must not overlap",
        schema={
            "type": "array",
            "prefixItems": [
                {"$ref": "#/$defs/length"},
                {"$ref": "#/$defs/length"},
                {"type": "number"},
            ],
            "minItems": 3,
            "maxItems": 3,
        },
    ),
    "offset": Param(
        "point",
        (0.0, 0.0),
        "m",
        "Slot offset (delta1, delta2); its frame depends on the law",
    ),
    "leader": Param(
        "boolean", False, doc="The vehicle the others follow (at most one)"
    ),
    "color": Param(
        "string",
        None,
        doc="A CSS colour name or #rrggbb (default: blue, red, green, ... in order)",
    ),
    "drive": Param(
        **section_param("drive"), doc="How the vehicle is driven (default: by its law)"
    ),
    "sensors": Param(
        **section_param("sensors"),
        doc="This vehicle's sensors, merged key by key over the fleet's top-level "
        "'sensors' (default: the fleet's)",
    ),
}

DRIVE: dict[str, Param] = {
    "type": Param(
        "choice",
        "reference",
        doc="reference: driven by its law; commands: open loop by 'schedule'",
        choices=DRIVE_TYPES,
    ),
    "schedule": Param(
        "custom",
        None,
        doc="Rows [t [s], v1 [m/s], v2 [rad/s]] with increasing t, each held until the "
        "next (zero before the first); required with type commands",
        schema={
            "type": "array",
            "minItems": 1,
            "items": {
                "type": "array",
                "items": {"type": "number"},
                "minItems": 3,
                "maxItems": 3,
            },
        },
    ),
}

PLATOON: dict[str, Param] = {
    "count": Param(
        "integer",
        doc="Number of generated vehicles",
        minimum=1,
        maximum=MAX_VEHICLES,
    ),
    "pattern": Param(
        "choice",
        "grid",
        doc="grid: rows behind the leader; line: single file; wedge: a V; ring: a "
        "circle around the leader",
        choices=PLATOON_PATTERNS,
    ),
    "spacing": Param(
        "length",
        "2d",
        "m",
        "Distance between neighbours",
        minimum=0.0,
        exclusive=True,
    ),
    "jitter": Param(
        "length",
        0.0,
        "m",
        "Uniform random shift of each start position on each axis (seeded by 'seed')",
        minimum=0.0,
    ),
    "columns": Param(
        "integer",
        None,
        doc="grid only: vehicles per row (default: about sqrt(count))",
        minimum=1,
        maximum=MAX_VEHICLES,
    ),
    "prefix": Param("name", "v", doc="Name prefix of the generated vehicles"),
}

VEHICLE_PARAM_KEYS = tuple(VEHICLE_PARAMS)

VEHICLE_KEYS = (*VEHICLE, *VEHICLE_PARAMS)

GAIN_KEYS = tuple(GAINS)

PLATOON_KEYS = tuple(PLATOON)

DRIVE_KEYS = tuple(DRIVE)


def read_vehicle_params(
    rd: Reader, m: dict[Any, Any], path: str, base: dict[str, Any]
) -> dict:
    """Read the physical/controller parameters of ``vehicle:`` or of one vehicle.

    ``base`` holds the values used for keys left out (the shared ``vehicle:`` ones
    for a listed vehicle).
    """
    out = dict(base)
    for key, p in VEHICLE_PARAMS.items():
        if p.type != "custom":
            out[key], _ = read_param(rd, m, key, path, p, base[key])
    gains_doc, gains_path = rd.get(m, "gains", path, None)
    gains = dict(base["gains"])
    if gains_doc is not None:
        g = rd.mapping(gains_doc, gains_path)
        if g is not None:
            rd.keys(g, GAIN_KEYS, gains_path)
            for key, p in GAINS.items():
                gains[key], _ = read_param(rd, g, key, gains_path, p, gains[key])
    out["gains"] = gains
    return out


def vehicle_defaults() -> dict[str, Any]:
    """The declared defaults of ``vehicle:``, gains included."""
    base = {k: p.default for k, p in VEHICLE_PARAMS.items() if p.type != "custom"}
    base["gains"] = {k: p.default for k, p in GAINS.items()}
    return base


def _drive(rd: Reader, doc: Any, path: str) -> DriveSpec | None:
    """The drive of one vehicle, or None if it has problems (they are recorded)."""
    before = len(rd.problems)
    drive = _read_drive(rd, doc, path)
    return drive if len(rd.problems) == before else None


def _read_drive(rd: Reader, doc: Any, path: str) -> DriveSpec:
    m = rd.mapping(doc, path)
    if m is None:
        return DriveSpec()
    rd.keys(m, DRIVE_KEYS, path)
    kind = rd.choice(m, "type", path, "reference", DRIVE_TYPES, "drive type")
    if kind != "commands":
        if "schedule" in m and kind is not None:
            rd.fail(
                f"{path}.schedule",
                "a schedule needs type: commands",
                f"type {kind}",
                "type: commands, or no schedule",
            )
        return DriveSpec()
    kind_rows = "a list of [t, v1, v2] rows ([s], [m/s], [rad/s])"
    rows, sub = rd.get(m, "schedule", path, REQUIRED, kind_rows)
    if rows is REQUIRED:
        return DriveSpec()
    if not isinstance(rows, list) or not rows:
        rd.fail(
            sub,
            "not a list of rows" if not isinstance(rows, list) else "no rows",
            describe(rows),
            kind_rows,
        )
        return DriveSpec()
    schedule = [rd.check_vector(r, f"{sub}[{i}]", 3) for i, r in enumerate(rows)]
    if any(r is None for r in schedule):
        return DriveSpec()
    times = [r[0] for r in schedule]
    for i, (a, b) in enumerate(zip(times, times[1:], strict=False)):
        if b <= a:
            rd.fail(
                f"{sub}[{i + 1}]",
                "row times must increase",
                f"t = {b:g} s after t = {a:g} s",
                "strictly increasing times",
            )
            return DriveSpec()
    return DriveSpec("commands", tuple(schedule))


def read_vehicles(
    rd: Reader,
    doc: Any,
    path: str,
    params: dict[str, Any],
    fleet_sensors: SensorsSpec | None = None,
) -> list[tuple[str, VehicleSpec]]:
    """The listed vehicles as ``(path, spec)``; every name also goes to ``rd.declared``.

    A vehicle's own ``sensors`` are merged over ``fleet_sensors`` (the top level's).

    A vehicle with an invalid field is left out of the list, but its name and leader
    flag are still declared so that checks across sections (failures naming it, the
    number of leaders) do not report follow-on problems.
    """
    if doc is None:
        return []
    if not isinstance(doc, list):
        rd.fail(path, "not a list", describe(doc), "a list of vehicles")
        return []
    if len(doc) > MAX_VEHICLES:
        rd.fail(path, "too many vehicles", f"{len(doc)}", f"at most {MAX_VEHICLES}")
        return []
    out = []
    for i, item in enumerate(doc):
        sub = f"{path}[{i}]"
        m = rd.mapping(item, sub)
        if m is None:
            rd.declared.append((sub, f"vehicle{i}", False))
            continue
        rd.keys(m, VEHICLE_KEYS, sub)
        name = rd.name(m, "name", sub, f"vehicle{i}")
        leader = rd.boolean(m, "leader", sub, False)
        rd.declared.append(
            (sub, name if isinstance(name, str) else f"vehicle{i}", leader)
        )
        kind = "a list [x1, x2, x3]: two lengths [m] and a heading [rad]"
        raw, pose_path = rd.get(m, "pose", sub, REQUIRED, kind)
        pose: Any = None
        if raw is not REQUIRED:
            if not isinstance(raw, list | tuple) or len(raw) != 3:
                what = (
                    "wrong number of items"
                    if isinstance(raw, list | tuple)
                    else "not a list"
                )
                rd.fail(pose_path, what, describe(raw), kind)
            else:
                pose = (
                    rd.check_number(raw[0], f"{pose_path}[0]", length=True),
                    rd.check_number(raw[1], f"{pose_path}[1]", length=True),
                    rd.check_number(raw[2], f"{pose_path}[2]"),
                )
        offset = rd.vector(m, "offset", sub, 2, (0.0, 0.0), length=True)
        color = rd.color(m, "color", sub, PALETTE[i % len(PALETTE)])
        drive: DriveSpec | None = DriveSpec()
        if m.get("drive") is not None:
            drive = _drive(rd, m["drive"], f"{sub}.drive")
        p = read_vehicle_params(rd, m, sub, params)
        sensors = None
        if m.get("sensors") is not None:
            sensors = read_sensors(rd, m["sensors"], f"{sub}.sensors", fleet_sensors)
            if sensors is None:
                continue
        if pose is None or offset is None or None in pose or drive is None:
            continue
        if None in (p["diameter"], p["mass"]):
            continue
        if any(v is None for v in p["gains"].values()):
            continue
        made = _make_vehicle(name, pose, offset, leader, color, drive, p)
        if sensors is not None:
            made = dataclasses.replace(made, sensors=sensors)
        out.append((sub, made))
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


def read_platoon(rd: Reader, doc: Any, path: str) -> PlatoonSpec | None:
    """The ``platoon:`` section, or None if it has problems (recorded)."""
    m = rd.mapping(doc, path)
    if m is None:
        return None
    rd.keys(m, PLATOON_KEYS, path)
    values, ok = read_params(rd, m, path, PLATOON)
    return PlatoonSpec(**values) if ok else None


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


def platoon_frame(
    formation: FormationSpec | None,
    leader: VehicleSpec | None,
    reference: ReferenceSpec | None,
) -> tuple[float, float, float, float]:
    """Where a platoon's slots are at t = 0, as its formation law defines them.

    Returns ``(x, y, angle, heading)``: the point the offsets are added to [m], the
    angle they are turned by [rad], and the heading the vehicles start with [rad], by
    the ``frame`` the law registered with (:func:`sandbox.plugins.register_law`):

    - ``fixed``: the leader, offsets in the world frame (eq. (7));
    - ``rotating``, ``own_estimate``: the leader, offsets in its frame (eqs. (10),
      (20));
    - ``virtual``: the reference's start, offsets in the world frame or, with
      ``rotate``, turned by the reference's tangent (eqs. (13)-(15));
    - ``leader_ref``: the leader, offsets like ``virtual`` (eq. (16)).

    Without a leader the reference's start stands in for it (then the origin).
    Vehicles face the leader's heading, or the reference's tangent under ``virtual``.
    """
    ref = reference.build().evaluate(0.0) if reference is not None else None
    tangent = 0.0
    if ref is not None:
        tangent = math.atan2(float(ref[1][1]), float(ref[1][0]))  # eq. (15)
    if leader is not None:
        x, y, heading = (float(c) for c in leader.pose)
    elif ref is not None:
        x, y, heading = float(ref[0][0]), float(ref[0][1]), tangent
    else:
        x, y, heading = 0.0, 0.0, 0.0
    frame = "leader"
    if formation is not None:
        frame = plugins.get("law", formation.law).options["frame"]
    rotate = formation is not None and formation.rotate
    if frame == "reference" and ref is not None:
        x, y, heading = float(ref[0][0]), float(ref[0][1]), tangent
        return x, y, tangent if rotate else 0.0, heading
    if frame == "world":
        return x, y, 0.0, heading
    if frame == "leader_reference":
        return x, y, tangent if rotate and ref is not None else 0.0, heading
    return x, y, heading, heading


def expand_platoon(
    spec: PlatoonSpec,
    listed: list[VehicleSpec],
    params: dict[str, Any],
    seed: int,
    reference: ReferenceSpec | None,
    formation: FormationSpec | None = None,
) -> list[VehicleSpec]:
    """Create the platoon's vehicles, starting on their slots (jittered by ``seed``).

    The slots are those the formation law gives at t = 0 (see :func:`platoon_frame`),
    so that an unjittered platoon starts in formation. The jitter is uniform in
    ``[-jitter, jitter]`` on each axis, drawn from ``numpy.random.default_rng(seed)``.
    """
    leader = next((v for v in listed if v.leader), None)
    x, y, angle, heading = platoon_frame(formation, leader, reference)
    delta = platoon_offsets(spec)
    c, s = math.cos(angle), math.sin(angle)
    world = np.stack(
        (c * delta[:, 0] - s * delta[:, 1], s * delta[:, 0] + c * delta[:, 1]), -1
    )  # eqs. (11), (14)
    rng = np.random.default_rng(seed)
    jitter = rng.uniform(-spec.jitter, spec.jitter, size=(spec.count, 2))
    start = (np.array([x, y]) + world + jitter).tolist()
    offsets = delta.tolist()
    out = []
    for i in range(spec.count):
        pose = (start[i][0], start[i][1], heading)
        color = PALETTE[(len(listed) + i) % len(PALETTE)]
        out.append(
            _make_vehicle(
                f"{spec.prefix}{i}",
                pose,
                tuple(offsets[i]),
                False,
                color,
                DriveSpec(),
                params,
            )
        )
    return out
