"""The sections of the format, declared once, and the reader of declared keys.

Each key is a :class:`~sandbox.plugins.Param` in one table (``TOP``, ``METRICS``, the
own keys of the sections that select a plug-in, and, in :mod:`.vehicles`, those of the
vehicles); a plug-in's keys are declared by its registration. :func:`read_param` reads a
key from its declaration, :func:`read_plugin_section` a section that selects a plug-in
by name (reference, formation, recovery, failures, obstacles). The JSON
Schema (:mod:`sandbox.scenario.schema`) and the documentation checks derive from
these tables.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from sandbox import plugins
from sandbox.model.flatness import (
    Gains,
    max_control_period,
)
from sandbox.model.obstacles import SHAPES, ObstacleSpec
from sandbox.plugins.registration import (
    KINDS,
    ObstacleContext,
    Param,
    reserve_section_keys,
)
from sandbox.scenario.expectations import EXPECT_SCHEMA
from sandbox.scenario.reader import (
    LENGTH,
    MAX_RECORD_EVERY,
    MAX_SEED,
    MAX_SUBSTEPS,
    REQUIRED,
    Reader,
    describe,
    number_kind,
)
from sandbox.scenario.specs import (
    DetectionSpec,
    FailureSpec,
    FormationSpec,
    RecoverySpec,
    ReferenceSpec,
    SafetySpec,
)


# Every key of the format is declared once, here or in the plug-in that uses it: the
# reader below, the JSON Schema (scenario/schema.py) and the documentation checks of
# scenarios/reference.yaml (tests/test_reference_doc.py) derive from these tables.
def section_param(name: str) -> dict[str, Any]:
    """The ``Param`` keywords of a key that holds the section ``name``."""
    return {"type": "custom", "default": None, "schema": {"$ref": f"#/$defs/{name}"}}


def list_param(name: str) -> dict[str, Any]:
    """The ``Param`` keywords of a key that holds a list of ``name`` sections."""
    return {
        "type": "custom",
        "default": None,
        "schema": {"type": "array", "items": {"$ref": f"#/$defs/{name}"}},
    }


_BOUND = {
    "anyOf": [
        {"type": "number"},
        {"type": "array", "items": {"type": "number"}, "minItems": 1},
    ]
}

_PAIR = {"type": "array", "items": _BOUND, "minItems": 2, "maxItems": 2}

#: The schema of ``randomize:`` (read by :mod:`sandbox.scenario.randomize`).
_RANDOMIZE_SCHEMA = {
    "type": "object",
    "additionalProperties": {
        "oneOf": [
            {
                "type": "object",
                "properties": {key: value},
                "required": [key],
                "additionalProperties": False,
            }
            for key, value in (
                ("uniform", _PAIR),
                ("normal", _PAIR),
                ("choice", {"type": "array", "minItems": 1}),
            )
        ]
    },
}


def _nullable_keys(schema: dict[str, Any]) -> dict[str, Any]:
    """The schema with every key, at every depth, also accepting null (the default)."""
    docs = ("description", "default")

    def nullable(sub: Any) -> Any:
        if not isinstance(sub, dict):
            return sub
        sub = _nullable_keys(sub)
        if any(a.get("type") == "null" for a in sub.get("anyOf", [])):
            return sub
        core = {k: v for k, v in sub.items() if k not in docs}
        return {
            "anyOf": [core, {"type": "null"}],
            **{k: sub[k] for k in docs if k in sub},
        }

    out = dict(schema)
    if "properties" in out:
        out["properties"] = {k: nullable(v) for k, v in out["properties"].items()}
    if isinstance(out.get("additionalProperties"), dict):
        out["additionalProperties"] = nullable(out["additionalProperties"])
    if "anyOf" in out:
        out["anyOf"] = [
            _nullable_keys(a) if isinstance(a, dict) else a for a in out["anyOf"]
        ]
    return out


#: The control-period bound of eq. (6) with the report's gains [s].
REPORT_DT_BOUND = max_control_period(Gains().k1, Gains().k2)

TOP: dict[str, Param] = {
    "name": Param(
        "name",
        None,
        doc="Name of the scenario; runs go to runs/<name>/ by default (default: the "
        "file name without .yaml)",
    ),
    "description": Param("text", "", doc="Free text shown by 'sandbox list'"),
    "duration": Param(
        "number", 20.0, "s", "Simulated time", minimum=0.0, exclusive=True
    ),
    "dt": Param(
        "number",
        0.01,
        "s",
        "Control period h; also the period of the backward differences of eqs. "
        "(8)-(9), (18)-(19). The forward-Euler update of eq. (6) needs dt < "
        f"{REPORT_DT_BOUND:g} s with the report's gains (checked by the loader)",
        minimum=0.0,
        exclusive=True,
    ),
    "substeps": Param(
        "integer",
        4,
        doc="Physics steps per control period; keep v1 dt / substeps well below the "
        "vehicle radius",
        minimum=1,
        maximum=MAX_SUBSTEPS,
    ),
    "seed": Param(
        "integer",
        0,
        doc="Seed of the platoon jitter; same scenario and seed give identical outputs",
        minimum=0,
        maximum=MAX_SEED,
    ),
    "record_every": Param(
        "integer",
        1,
        doc="Record one sample every N control periods (trajectory.csv and metrics "
        "use the samples)",
        minimum=1,
        maximum=MAX_RECORD_EVERY,
    ),
    "plugins": Param(
        "custom",
        None,
        doc="Plug-in files (relative to this file) or modules to import first",
        schema={"type": "array", "items": {"type": "string", "minLength": 1}},
    ),
    "vehicle": Param(
        **section_param("vehicleParams"),
        doc="Defaults for every vehicle (each vehicle may override them)",
    ),
    "reference": Param(
        **section_param("reference"),
        doc="The reference trajectory tracked by the leader (or by every slot with "
        "law virtual)",
    ),
    "formation": Param(
        **section_param("formation"),
        doc="The formation law; required with more than one vehicle",
    ),
    "vehicles": Param(**list_param("vehicle"), doc="The listed vehicles"),
    "platoon": Param(
        **section_param("platoon"),
        doc="Followers generated on a pattern, named <prefix>0, <prefix>1, ...",
    ),
    "recovery": Param(
        **section_param("recovery"), doc="Collision avoidance, section 4"
    ),
    "failures": Param(**list_param("failure"), doc="Failures injected into vehicles"),
    "obstacles": Param(**list_param("obstacle"), doc="Static obstacles"),
    "metrics": Param(**section_param("metrics"), doc="Parameters of metrics.json"),
    "sensing": Param(
        **section_param("sensing"),
        doc="What the vehicles see of each other: a noisy, delayed, lossy broadcast "
        "of the poses (see sandbox/behaviour/sensing.py; all 0: the truth)",
    ),
    "detection": Param(
        **section_param("detection"),
        doc="How the platoon learns of failures: oracle (the truth, at once) or "
        "residual (observed motion against the broadcast commands, a CUSUM; see "
        "sandbox/behaviour/detection.py)",
    ),
    "safety": Param(
        **section_param("safety"),
        doc="A safety filter on the commands, after the controller and before the "
        "failures (see sandbox/behaviour/safety/; filter none: no filter)",
    ),
    "sensors": Param(
        **section_param("sensors"),
        doc="The sensors of every vehicle (a vehicle's own 'sensors' is merged over "
        "them): range, a planar LiDAR (see sandbox/behaviour/ranges.py)",
    ),
    "reconfigure": Param(
        **section_param("reconfigure"),
        doc="Who tracks which slot once a vehicle is believed failed (see "
        "sandbox/behaviour/reconfigure.py; default: everyone keeps their slot)",
    ),
    "on_leader_failure": Param(
        "choice",
        "keep",
        doc="When the leader is believed failed: keep (the followers keep following "
        "it), virtual (the formation follows the reference itself, section 3.4) or "
        "elect (the healthy vehicle nearest the leader's slot leads)",
        choices=("keep", "virtual", "elect"),
    ),
    # Several platoons in one world (the keys of an entry: scenario/platoons.py).
    "platoons": Param(
        **list_param("platoonEntry"),
        doc="Several platoons in one world, each with its own name, vehicles, "
        "reference, formation and recovery; the top-level sections are their "
        "defaults (see scenarios/traffic/)",
    ),
    "events": Param(
        **list_param("event"),
        doc="Merges and splits of platoons, at a time or when one platoon comes "
        "within a distance of another (with platoons:; see sandbox/scenario/events.py)",
    ),
    "randomize": Param(
        "custom",
        None,
        doc="Random draws from the seed: field paths (the --set syntax, e.g. "
        "vehicles[1].pose) mapped to {uniform: [low, high]}, {normal: [mean, std]} "
        "(numbers or equal-length lists, elementwise) or {choice: [a, b, ...]}; "
        "overlapping starts are redrawn (see sandbox/scenario/randomize.py)",
        schema=_RANDOMIZE_SCHEMA,
    ),
    "expect": Param(
        "custom",
        None,
        doc="What the run must show, checked by 'sandbox check' and the pytest plugin "
        "(see sandbox/scenario/expectations.py; bounds are inclusive; quantities are "
        "those of metrics.json)",
        schema=_nullable_keys(EXPECT_SCHEMA),
    ),
}

METRICS: dict[str, Param] = {
    "settle_tol": Param(
        "number",
        0.05,
        "m",
        "Formation error below which a vehicle counts as settled",
        minimum=0.0,
        exclusive=True,
    ),
    "settle_dwell": Param(
        "number",
        1.0,
        "s",
        "How long the run must go on with the error in band after the settling "
        "time, else the settling time is null",
        minimum=0.0,
    ),
    "settle_speed": Param(
        "number",
        0.02,
        "m/s",
        "Largest drift relative to the slot over the last settle_dwell of the run for "
        "a settled vehicle (one crossing its slot slowly has not settled)",
        minimum=0.0,
        exclusive=True,
    ),
    "contact_release": Param(
        "number",
        0.01,
        "m",
        "Gap between two surfaces beyond which a contact episode ends (closer "
        "returns are the same collision)",
        minimum=0.0,
        exclusive=True,
    ),
    "deadlock_speed": Param(
        "number",
        0.01,
        "m/s",
        "Speed below which a healthy vehicle short of its slot counts as stopped "
        "(deadlocks in metrics.json)",
        minimum=0.0,
        exclusive=True,
    ),
    "deadlock_time": Param(
        "number",
        2.0,
        "s",
        "How long vehicles must stay stopped short of their slots to be a deadlock",
        minimum=0.0,
        exclusive=True,
    ),
    "deadlock_distance": Param(
        "number",
        0.5,
        "m",
        "Distance to the slot beyond which a stopped vehicle is short of it (a "
        "deadlock, not a vehicle settling)",
        minimum=0.0,
    ),
    "deadlock_progress": Param(
        "number",
        0.5,
        "",
        "Headway toward its slot, as a fraction of deadlock_distance per "
        "deadlock_time, below which a moving vehicle farther than deadlock_distance "
        "is trapped (a deadlock); 0: only stopped vehicles are",
        minimum=0.0,
    ),
    "deadlock_creeping": Param(
        "choice",
        "to_end",
        doc="Which stretches without headway (deadlock_progress) are deadlocks: "
        "to_end: only one that lasts to the end of the run (a vehicle held up for a "
        "while, e.g. behind its moving slot, is not trapped); any: every one",
        choices=("to_end", "any"),
    ),
}

SENSING: dict[str, Param] = {
    "position_noise": Param(
        "number",
        0.0,
        "m",
        "Standard deviation of the noise on each broadcast position coordinate",
        minimum=0.0,
    ),
    "heading_noise": Param(
        "number",
        0.0,
        "rad",
        "Standard deviation of the noise on each broadcast heading",
        minimum=0.0,
    ),
    "delay": Param(
        "number",
        0.0,
        "s",
        "Latency of the broadcast, a whole number of control periods dt",
        minimum=0.0,
    ),
    "loss": Param(
        "number",
        0.0,
        doc="Probability that a vehicle's packet of a period is lost (the last "
        "received copy is held), below 1",
        minimum=0.0,
    ),
}

RECONFIGURE: dict[str, Param] = {
    "assign": Param(
        "choice",
        "none",
        doc="none: every vehicle keeps its slot; hungarian: at each change of the "
        "believed failures the healthy vehicles are reassigned to slots by minimum "
        "total squared distance",
        choices=("none", "hungarian"),
    ),
    "close_gap": Param(
        "boolean",
        False,
        doc="With hungarian: the slots are the formation's first ones, one per "
        "healthy vehicle (a column closes up); false: a failed vehicle's slot stays "
        "empty",
    ),
}

#: The own keys of the sections that select a plug-in (the plug-in's parameters are
#: declared by its registration).
FORMATION: dict[str, Param] = {
    "law": Param("custom", doc="The formation law (registered name)"),
}

RECOVERY: dict[str, Param] = {
    "strategy": Param("custom", "none", doc="The recovery strategy (registered name)"),
    "R": Param(
        "length",
        "3d",
        "m",
        "Safe-zone radius: obstacles within R are avoided",
        minimum=0.0,
        exclusive=True,
    ),
    "leader_avoids": Param(
        "boolean", False, doc="Whether the leader avoids too (section 4.3.3)"
    ),
    "target_derivatives": Param(
        "choice",
        "hold",
        doc="hold: the shifted target keeps the law's derivatives; estimate: the "
        "shift's derivatives are estimated and added",
        choices=("hold", "estimate"),
    ),
    "obstacles": Param(
        "choice",
        "map",
        doc="Where the strategy and the safety filter find the static obstacles: map "
        "(the scenario's obstacles) or sensed (each vehicle's range-sensor hits, the "
        "nearest of each obstacle it sees; needs sensors.range)",
        choices=("map", "sensed"),
    ),
}

DETECTION: dict[str, Param] = {
    "method": Param("custom", "oracle", doc="The failure detector (registered name)"),
}

FAILURE: dict[str, Param] = {
    "vehicle": Param("string", doc="Name of the failing vehicle"),
    "at": Param("number", unit="s", doc="Onset, within the run", minimum=0.0),
    "kind": Param("custom", doc="The failure kind (registered name)"),
    "until": Param(
        "number",
        None,
        "s",
        "End, later than 'at' (default: the end of the run)",
        minimum=0.0,
    ),
}

REFERENCE: dict[str, Param] = {
    "type": Param("custom", doc="The reference type (registered name)"),
}

OBSTACLE: dict[str, Param] = {
    "type": Param("custom", doc="The obstacle type (registered name)"),
    "name": Param(
        "name",
        None,
        doc="Names the obstacle in collision events (default: obstacle[<i>])",
    ),
}

SAFETY: dict[str, Param] = {
    "filter": Param(
        "custom", "none", doc="The safety filter (registered name; none: no filter)"
    ),
}

#: The sections by kind of plug-in they select.
PLUGIN_SECTIONS: dict[str, dict[str, Param]] = {
    "law": FORMATION,
    "strategy": RECOVERY,
    "failure": FAILURE,
    "reference": REFERENCE,
    "obstacle": OBSTACLE,
    "detector": DETECTION,
    "filter": SAFETY,
}

for _kind, _own in PLUGIN_SECTIONS.items():
    reserve_section_keys(_kind, tuple(_own))

TOP_KEYS = tuple(TOP)

METRICS_KEYS = tuple(METRICS)

SENSING_KEYS = tuple(SENSING)

RECONFIGURE_KEYS = tuple(RECONFIGURE)


def _length_default(rd: Reader, value: Any) -> Any:
    """A default written ``"3d"`` resolved to metres with the default diameter."""
    if isinstance(value, str):
        match = LENGTH.match(value)
        if match:
            return float(match.group(1)) * rd.diameter
    return value


#: ``read_param``'s default: the declared one.
DECLARED: Any = type("Declared", (), {"__repr__": lambda self: "DECLARED"})()


def read_param(
    rd: Reader,
    m: dict[Any, Any],
    key: str,
    path: str,
    p: Param,
    default: Any = DECLARED,
) -> tuple[Any, bool]:
    """Read one declared key: ``(value, ok)``; problems are recorded in ``rd``.

    A missing optional key gives its default (lengths like ``"3d"`` in metres); a
    missing required key, or a value of the wrong type or out of bounds, gives
    ``(None, False)``. ``default`` replaces the declared one (a vehicle's keys left
    out take the shared ``vehicle:`` values).
    """
    before = len(rd.problems)
    if default is DECLARED:
        default = p.default
    required = default is REQUIRED
    if p.type == "length":
        default = _length_default(rd, default)
    t = p.type
    if t in ("number", "length"):
        positive = p.exclusive and p.minimum == 0
        minimum = None if positive else p.minimum
        value = rd.number(
            m,
            key,
            path,
            default,
            positive=positive,
            minimum=minimum,
            length=t == "length",
        )
        if value is not None and len(rd.problems) == before:
            sub = f"{path}.{key}" if path else key
            kind = number_kind(positive, minimum, t == "length")
            if p.exclusive and not positive and value <= p.minimum:
                rd.fail(sub, f"must be greater than {p.minimum:g}", f"{value:g}", kind)
            elif p.maximum is not None and value > p.maximum:
                rd.fail(sub, f"must be at most {p.maximum:g}", f"{value:g}", kind)
    elif t == "integer":
        lo = int(p.minimum) if p.minimum is not None else -(2**63)
        hi = int(p.maximum) if p.maximum is not None else MAX_SEED
        value = rd.integer(m, key, path, default, minimum=lo, maximum=hi)
        if value is REQUIRED:
            value = None
    elif t == "boolean":
        value = rd.boolean(m, key, path, False if default is REQUIRED else default)
    elif t == "string":
        value = rd.string(m, key, path, default)
    elif t == "name":
        value = rd.name(m, key, path, default)
    elif t == "text":
        value = m.get(key)
        value = default if value is None else value
        if not isinstance(value, str):
            rd.fail(
                f"{path}.{key}" if path else key,
                "not a string",
                describe(value),
                "a text",
            )
    elif t == "choice":
        value = rd.choice(m, key, path, default, p.choices, f"{key} value")
    elif t == "point":
        value = rd.vector(m, key, path, 2, default, length=True)
    elif t == "points":
        if key not in m or m[key] is None:
            if required:
                value = rd.points(m, key, path, p.min_items)
            else:
                value = default
        else:
            value = rd.points(m, key, path, p.min_items)
    else:
        raise ValueError(f"{path}.{key}: a {t} key is read by its section's code")
    if value is REQUIRED:
        value = None
    return value, len(rd.problems) == before


def read_params(
    rd: Reader, m: dict[Any, Any], path: str, params: dict[str, Param]
) -> tuple[dict[str, Any], bool]:
    """Read every declared key of a mapping (not ``custom`` ones): ``(values, ok)``."""
    values, ok = {}, True
    for key, p in params.items():
        if p.type == "custom":
            continue
        values[key], good = read_param(rd, m, key, path, p)
        ok = ok and good
    return values, ok


def _and(names: list[str]) -> str:
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _plural(title: str) -> str:
    """``recovery strategies``, ``failure detectors``."""
    return f"{title[:-1]}ies" if title.endswith("y") else f"{title}s"


def read_plugin_section(
    rd: Reader,
    m: dict[Any, Any],
    path: str,
    kind: str,
) -> tuple[plugins.Plugin | None, dict[str, Any], dict[str, Any], bool]:
    """Read a section that selects a plug-in of ``kind`` by name.

    Returns ``(plugin, own, values, ok)``: the selected plug-in (None if the name is
    missing or unknown), the section's own keys, the plug-in's parameters (checked
    by its ``check``), and whether all were valid. Keys are checked against the
    section's own keys and the plug-in's parameters; a key another plug-in of the
    kind declares is an error naming them, or ignored for a lenient kind.
    """
    info = KINDS[kind]
    own = PLUGIN_SECTIONS[kind]
    registered = plugins.names(kind)
    default = own[info.selector].default
    selected = m.get(info.selector)
    if rd.unloaded and isinstance(selected, str) and selected not in registered:
        rd.unchecked.append((path, f"{info.selector} {selected}"))
        return None, {}, {}, False
    name = rd.choice(m, info.selector, path, default, registered, info.title)
    own_values, ok = read_params(rd, m, path, own)
    everyone = plugins.all_params(kind)
    if name is None or name is REQUIRED:
        rd.keys(m, (*own, *everyone), path)
        return None, own_values, {}, False
    plugin = plugins.get(kind, name)
    allowed = (*own, *plugin.params)
    for key in m:
        if isinstance(key, str) and key in allowed:
            continue
        if isinstance(key, str) and key in everyone:
            if not info.lenient:
                users = everyone[key]
                rd.fail(
                    f"{path}.{key}",
                    f"applies only to the {_and(users)} "
                    f"{_plural(info.title) if len(users) > 1 else info.title}",
                    f"{key} with {info.selector} {name}",
                    f"no '{key}' ({info.title} {name} does not take it)",
                )
            else:  # ignored by this plug-in, but still a valid value of the key
                declared = plugins.get(kind, everyone[key][0]).params[key]
                if not declared.required:
                    read_param(rd, m, key, path, declared)
                users = everyone[key]
                if f"{path}.{info.selector}" in rd.varied:
                    continue  # the file's key, for the plug-in the file chose
                rd.warn(
                    f"{path}.{key}",
                    f"does nothing here: it applies only to the {_and(users)} "
                    f"{_plural(info.title) if len(users) > 1 else info.title}, not "
                    f"to {info.selector} {name}",
                )
            continue
        rd.keys({key: None}, allowed, path)
    values, good = read_params(rd, m, path, plugin.params)
    ok = ok and good
    if good and plugin.check is not None:
        section = {**own_values, info.selector: name}
        for key, what, got, expected in plugin.check(values, section) or ():
            rd.fail(f"{path}.{key}", what, got, expected)
            ok = False
    return plugin, own_values, values, ok


def read_reference(rd: Reader, doc: Any, path: str) -> ReferenceSpec | None:
    """The ``reference:`` section, or None if it has problems (recorded)."""
    m = rd.mapping(doc, path)
    if m is None:
        return None
    plugin, _, values, ok = read_plugin_section(rd, m, path, "reference")
    if plugin is None or not ok:
        return None
    return ReferenceSpec(plugin.name, values)


def read_formation(rd: Reader, doc: Any, path: str) -> FormationSpec | None:
    """The ``formation:`` section, or None if it has problems (recorded)."""
    m = rd.mapping(doc, path)
    if m is None:
        return None
    plugin, _, values, ok = read_plugin_section(rd, m, path, "law")
    if plugin is None or not ok:
        return None
    return FormationSpec(plugin.name, values)


def read_recovery(rd: Reader, doc: Any, path: str) -> RecoverySpec:
    """The ``recovery:`` section (no strategy when left out or invalid)."""
    m = rd.mapping(doc, path)
    fallback = RecoverySpec(R=3.0 * rd.diameter)
    if m is None:
        return fallback
    plugin, own, values, _ = read_plugin_section(rd, m, path, "strategy")
    big_r = own.get("R")
    if big_r is not None and big_r < rd.diameter:
        rd.warn(
            f"{path}.R",
            f"R = {big_r:g} m is smaller than the vehicle diameter "
            f"{rd.diameter:g} m: avoidance starts only after contact",
        )
    if plugin is None:
        return fallback
    return RecoverySpec(
        strategy=plugin.name,
        R=big_r if big_r is not None else fallback.R,
        leader_avoids=bool(own.get("leader_avoids")),
        target_derivatives=own.get("target_derivatives") or "hold",
        params=values,
        obstacles=own.get("obstacles") or "map",
    )


def read_detection(rd: Reader, doc: Any, path: str) -> DetectionSpec:
    """The ``detection:`` section (the oracle when left out or invalid)."""
    m = rd.mapping(doc, path)
    if m is None:
        return DetectionSpec()
    plugin, _, values, ok = read_plugin_section(rd, m, path, "detector")
    if plugin is None or not ok:
        return DetectionSpec()
    return DetectionSpec(method=plugin.name, params=values)


def read_failures(rd: Reader, doc: Any, path: str) -> list[tuple[str, FailureSpec]]:
    """The valid entries of ``failures:`` as ``(path, spec)``."""
    out = []
    for _, sub, m in rd.items(doc, path, "failures"):
        plugin, own, values, ok = read_plugin_section(rd, m, sub, "failure")
        vehicle, at, until = own.get("vehicle"), own.get("at"), own.get("until")
        if plugin is not None and plugin.options.get("permanent") and until is not None:
            rd.fail(
                f"{sub}.until",
                f"a {plugin.name} is permanent",
                f"until = {until:g} s",
                "no 'until' (use kind: stop for a temporary halt)",
            )
            ok = False
        if at is not None and until is not None and until <= at:
            rd.fail(
                f"{sub}.until",
                "must be later than 'at'",
                f"until = {until:g} s, at = {at:g} s",
                "until > at",
            )
            ok = False
        rd.timed.append(
            (
                sub,
                vehicle if isinstance(vehicle, str) else None,
                at if isinstance(at, float) else None,
            )
        )
        if plugin is None or vehicle is None or at is None:
            continue
        if ok:
            out.append((sub, FailureSpec(vehicle, at, plugin.name, until, values)))
    return out


def read_obstacles(rd: Reader, doc: Any, path: str) -> list[tuple[str, ObstacleSpec]]:
    """The valid entries of ``obstacles:`` as ``(path, spec)``."""
    out = []
    for i, sub, m in rd.items(doc, path, "obstacles"):
        plugin, own, values, ok = read_plugin_section(rd, m, sub, "obstacle")
        if plugin is None or not ok:
            continue
        name = own.get("name") or f"obstacle[{i}]"
        try:
            spec = plugin.obj(ObstacleContext(name, values))
        except Exception as exc:  # a plug-in's error is the user's problem, reported
            rd.fail(
                sub,
                f"obstacle type {plugin.name} failed",
                f"{type(exc).__name__}: {exc}",
                f"values {plugin.name} accepts ({plugin.origin})",
            )
            continue
        if not isinstance(spec, ObstacleSpec) or spec.type not in SHAPES:
            rd.fail(
                sub,
                f"obstacle type {plugin.name} returned no shape",
                describe(spec),
                f"an ObstacleSpec of type {', '.join(SHAPES)}",
            )
            continue
        if spec.name != name:
            spec = dataclasses.replace(spec, name=name)
        out.append((sub, spec))
    return out


def read_safety(rd: Reader, doc: Any, path: str) -> SafetySpec:
    """The ``safety:`` section: the filter and its values (default: none)."""
    m = rd.mapping(doc, path)
    if m is None:
        return SafetySpec()
    plugin, _, values, ok = read_plugin_section(rd, m, path, "filter")
    if plugin is None or not ok or plugin.name == "none":
        return SafetySpec()
    return SafetySpec(plugin.name, values)
