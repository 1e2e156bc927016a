"""The ``sensors:`` sections: the fleet's at the top level, a vehicle's own.

Declared here (``SENSORS``, ``RANGE``) beside the code that reads them. A vehicle's
``sensors:`` is merged over the fleet's key by key: ``vehicles[2].sensors.range.fov``
alone changes that vehicle's field of view and keeps the fleet's other values (or the
defaults, without a fleet-wide sensor). The sensor itself is
:mod:`sandbox.behaviour.ranges`.
"""

from __future__ import annotations

import math
from typing import Any

from sandbox.plugins.registration import Param
from sandbox.scenario.reader import Reader
from sandbox.scenario.sections import DECLARED, read_param, section_param
from sandbox.scenario.specs import RangeSpec, SensorsSpec

#: The most beams of one range sensor (a scan is one pymunk query per beam at worst).
MAX_BEAMS = 1024
#: The narrowest field of view [rad] (about 0.06 degrees; one beam has no width).
MIN_FOV = 1e-3

SENSORS: dict[str, Param] = {
    "range": Param(
        **section_param("range"),
        doc="A planar range sensor (LiDAR): beams from the vehicle's centre over a "
        "field of view about the heading, cast against obstacles, walls and the other "
        "vehicles (see sandbox/behaviour/ranges.py)",
    ),
}

RANGE: dict[str, Param] = {
    "beams": Param(
        "integer",
        32,
        doc="Number of beams, ordered from -fov/2 (right) to +fov/2 (left)",
        minimum=1,
        maximum=MAX_BEAMS,
    ),
    "fov": Param(
        "number",
        2.0 * math.pi,
        "rad",
        "Field of view, centred on the heading; a full turn (2 pi) spaces the beams "
        "2 pi / beams apart from -pi, a narrower one puts beams on both edges",
        minimum=MIN_FOV,
        maximum=2.0 * math.pi,
    ),
    "max_range": Param(
        "length",
        "10d",
        "m",
        "Reach of every beam from the vehicle's centre; a beam that hits nothing "
        "reads max_range",
        minimum=0.0,
        exclusive=True,
    ),
    "noise": Param(
        "number",
        0.0,
        "m",
        "Standard deviation of the Gaussian noise on each range (seeded by 'seed', "
        "a stream of its own; readings stay within [0, max_range])",
        minimum=0.0,
    ),
    "rate": Param(
        "number",
        None,
        "Hz",
        "Scans per second, each held until the next (default: one every control "
        "period dt)",
        minimum=0.0,
        exclusive=True,
    ),
    "memory": Param(
        "number",
        0.0,
        "s",
        "With recovery.obstacles: sensed, how long an obstacle no longer seen (hidden "
        "behind another, between two beams) is kept at the point last seen (0: the "
        "current scan only)",
        minimum=0.0,
    ),
}

SENSORS_KEYS = tuple(SENSORS)

RANGE_KEYS = tuple(RANGE)


def read_sensors(
    rd: Reader, doc: Any, path: str, base: SensorsSpec | None = None
) -> SensorsSpec | None:
    """A ``sensors:`` mapping, merged over ``base``; None if it has problems.

    ``base`` is the fleet's section for a vehicle's own (None: the top level, whose
    keys left out take their defaults).
    """
    before = len(rd.problems)
    m = rd.mapping(doc, path)
    if m is None:
        return None if len(rd.problems) > before else (base or SensorsSpec())
    rd.keys(m, SENSORS_KEYS, path)
    inherited = base.range if base is not None else None
    found = inherited
    if m.get("range") is not None:
        found = _read_range(rd, m["range"], f"{path}.range", inherited)
    if len(rd.problems) > before:
        return None
    return SensorsSpec(range=found)


def _read_range(
    rd: Reader, doc: Any, path: str, base: RangeSpec | None
) -> RangeSpec | None:
    """The ``range:`` mapping, its keys left out from ``base`` (or the defaults)."""
    m = rd.mapping(doc, path)
    if m is None:
        return None
    rd.keys(m, RANGE_KEYS, path)
    values, ok = {}, True
    for key, p in RANGE.items():
        default = getattr(base, key) if base is not None else DECLARED
        values[key], good = read_param(rd, m, key, path, p, default)
        ok = ok and good
    if not ok:
        return None
    return RangeSpec(**values)
