"""JSON Schema (draft 2020-12) of the scenario format, for editors and other tools.

Nothing here is declared twice: the schema is generated from the declarations the
loader reads with, the section tables of :mod:`sandbox.scenario` (``TOP``,
``VEHICLE_PARAMS``, ``GAINS``, ``VEHICLE``, ``DRIVE``, ``PLATOON``, ``METRICS`` and
the own keys of the sections that select a plug-in) and the parameters each
registered plug-in declares (:mod:`sandbox.plugins`). A plug-in loaded before the
schema is built (``sandbox schema --plugin FILE``) is part of it.

The schema checks what a single field can express: types, ranges, enums, required keys,
unknown keys (``additionalProperties: false``) and the ``"3d"`` length form. The checks
that involve several fields (``r < R``, unique names, leaders, overlapping vehicles, the
control-period bound of eq. (6), ...) are the loader's: ``sandbox validate`` remains the
reference. Optional keys also accept ``null`` (the loader then uses the default).
"""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

from sandbox import plugins
from sandbox.plugins.registration import KINDS, Param
from sandbox.scenario import (
    BAD_NAME,
    DRIVE,
    GAINS,
    LENGTH,
    METRICS,
    PLATOON,
    PLATOONS,
    PLUGIN_SECTIONS,
    RANGE,
    RECONFIGURE,
    SENSING,
    SENSORS,
    TOP,
    VEHICLE,
    VEHICLE_PARAMS,
)
from sandbox.scenario.events import EVENT

DRAFT = "https://json-schema.org/draft/2020-12/schema"
SCHEMA_ID = "https://sandbox.example/schemas/scenario.schema.json"

#: A length: metres, or a multiple of the default vehicle diameter (``"3d"``, ``1.5d``).
LENGTH_PATTERN = LENGTH.pattern
#: The same, without a minus sign (lengths that must be positive).
POSITIVE_LENGTH_PATTERN = LENGTH.pattern.replace("[-+]?", r"\+?", 1)
#: A name written into CSV rows and directory names: no commas, quotes or slashes.
NAME_PATTERN = r"^(?=.*\S)" + BAD_NAME.pattern.replace("[", "[^", 1) + "+$"
_DOCS = ("description", "default", "x-unit")


def sections() -> dict[str, dict[str, Param]]:
    """Every section of the format and its declared keys, plug-ins included.

    Sections that select a plug-in have their own keys under their name
    (``recovery``) and each plug-in's under ``SECTION.NAME`` (``recovery.smooth``,
    ``reference.circle``).
    """
    out: dict[str, dict[str, Param]] = {
        "": TOP,
        "vehicle": VEHICLE_PARAMS,
        "gains": GAINS,
        "vehicles": VEHICLE,
        "drive": DRIVE,
        "platoon": PLATOON,
        "platoons": PLATOONS,
        "events": EVENT,
        "metrics": METRICS,
        "sensing": SENSING,
        "reconfigure": RECONFIGURE,
        "sensors": SENSORS,
        "range": RANGE,
    }
    for kind, own in PLUGIN_SECTIONS.items():
        section = KINDS[kind].section
        out[section] = own
        for name, plugin in plugins.registry(kind).items():
            out[f"{section}.{name}"] = plugin.params
    return out


# ---------------------------------------------------------------------- type fragments
def _number(p: Param) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "number"}
    if p.minimum is not None:
        out["exclusiveMinimum" if p.exclusive else "minimum"] = p.minimum
    if p.maximum is not None:
        out["maximum"] = p.maximum
    return out


def _length(p: Param) -> dict[str, Any]:
    nonnegative = p.minimum is not None and p.minimum >= 0
    pattern = POSITIVE_LENGTH_PATTERN if nonnegative else LENGTH_PATTERN
    return {"anyOf": [_number(p), {"type": "string", "pattern": pattern}]}


def _point() -> dict[str, Any]:
    return {
        "type": "array",
        "items": {"$ref": "#/$defs/length"},
        "minItems": 2,
        "maxItems": 2,
    }


def _name() -> dict[str, Any]:
    return {"type": "string", "pattern": NAME_PATTERN}


def _plain(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def fragment(p: Param) -> dict[str, Any]:
    """The type of a declared key, without its documentation."""
    t = p.type
    if t == "custom":
        return dict(p.schema or {})
    if t == "number":
        return _number(p)
    if t == "length":
        return _length(p)
    if t == "integer":
        out: dict[str, Any] = {"type": "integer"}
        if p.minimum is not None:
            out["minimum"] = int(p.minimum)
        if p.maximum is not None:
            out["maximum"] = int(p.maximum)
        return out
    if t == "boolean":
        return {"type": "boolean"}
    if t == "string":
        return {"type": "string", "minLength": 1, "pattern": r"\S"}
    if t == "name":
        return _name()
    if t == "text":
        return {"type": "string"}
    if t == "choice":
        return {"type": "string", "enum": list(p.choices)}
    if t == "point":
        return _point()
    if t == "points":
        return {"type": "array", "items": _point(), "minItems": p.min_items}
    raise ValueError(f"no schema for a {t} key")


def describe(p: Param) -> str:
    """The key's one-line documentation: doc, bounds, unit."""
    text = p.doc.rstrip(".")
    bounds = p.bounds_text()
    if bounds and bounds not in text:
        text = f"{text}, {bounds}"
    if p.unit:
        text = f"{text} [{p.unit}]"
    return text


def build_key(p: Param) -> dict[str, Any]:
    """The key's schema, with its description, unit and default."""
    out = fragment(p)
    out["description"] = describe(p)
    if p.unit:
        out["x-unit"] = p.unit
    if not p.required and p.default is not None:
        out["default"] = _plain(p.default)
    if not p.required:
        core = {k: v for k, v in out.items() if k not in _DOCS}
        out = {
            "anyOf": [core, {"type": "null"}],
            **{k: out[k] for k in _DOCS if k in out},
        }
    return out


def _object(params: dict[str, Param], extra: dict[str, Any] | None = None) -> dict:
    """A closed object schema of declared keys."""
    props = dict(extra or {})
    props.update({k: build_key(p) for k, p in params.items()})
    out: dict[str, Any] = {
        "type": "object",
        "properties": props,
        "additionalProperties": False,
    }
    required = [k for k, p in params.items() if p.required]
    if required:
        out["required"] = required
    return out


def _selector(kind: str) -> dict[str, Any]:
    info = KINDS[kind]
    own = PLUGIN_SECTIONS[kind][info.selector]
    registered = plugins.registry(kind)
    text = "; ".join(f"{n}: {p.doc}" if p.doc else n for n, p in registered.items())
    out: dict[str, Any] = {
        "type": "string",
        "enum": list(registered),
        "description": f"The {info.title}. {text}",
    }
    if not own.required:
        # An optional selector also accepts null, as the loader does (the default).
        out = {
            "anyOf": [{"type": "string", "enum": list(registered)}, {"type": "null"}],
            "description": out["description"],
            "default": own.default,
        }
    return out


def _plugin_section(kind: str) -> dict[str, Any]:
    """The schema of a section that selects a plug-in of ``kind``.

    A strict kind is ``oneOf`` its plug-ins, each a closed object of the section's
    keys and its own parameters; a lenient kind accepts every plug-in's parameters,
    and requires those the selected one requires.
    """
    info = KINDS[kind]
    own = {k: p for k, p in PLUGIN_SECTIONS[kind].items() if k != info.selector}
    registered = plugins.registry(kind)
    selector = _selector(kind)
    if info.lenient:
        union: dict[str, Param] = dict(own)
        for plugin in registered.values():
            for key, p in plugin.params.items():
                # required only for its plug-in (the rules below)
                union.setdefault(key, replace(p, default=None) if p.required else p)
        out = _object(union, {info.selector: selector})
        out["properties"] = {
            info.selector: selector,
            **{k: v for k, v in out["properties"].items() if k != info.selector},
        }
        rules = []
        for name, plugin in registered.items():
            when = {
                "properties": {info.selector: {"const": name}},
                "required": [info.selector],
            }
            need = [k for k, p in plugin.params.items() if p.required]
            if need:
                rules.append({"if": when, "then": {"required": need}})
            if plugin.options.get("permanent"):
                rules.append({"if": when, "then": {"not": {"required": ["until"]}}})
        if rules:
            out["allOf"] = rules
        if PLUGIN_SECTIONS[kind][info.selector].required:
            out["required"] = [info.selector, *out.get("required", [])]
        return out
    variants = []
    for name, plugin in registered.items():
        variant = _object(
            {**own, **plugin.params},
            {info.selector: {"const": name, "description": f"{info.title}: {name}"}},
        )
        variant["required"] = [info.selector, *variant.get("required", [])]
        variant["title"] = f"{info.title}: {name}"
        if plugin.doc:
            variant["description"] = plugin.doc
        variants.append(variant)
    return {
        "type": "object",
        "properties": {info.selector: selector},
        "required": [info.selector],
        "oneOf": variants,
    }


def build_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scenario file."""
    length = {
        "anyOf": [{"type": "number"}, {"type": "string", "pattern": LENGTH_PATTERN}],
        "description": "A length: metres, or a multiple of the default vehicle "
        'diameter written like "3d" or 1.5d',
    }
    vehicle = _object(VEHICLE)
    params = _object(VEHICLE_PARAMS)
    vehicle["properties"].update(params["properties"])
    vehicle["description"] = (
        "A vehicle: its own keys, plus any key of 'vehicle' to "
        "override that default for this vehicle only"
    )
    drive = _object(DRIVE)
    drive.pop("required", None)
    drive["if"] = {"properties": {"type": {"const": "commands"}}, "required": ["type"]}
    drive["then"] = {"required": ["schedule"]}
    drive["else"] = {"not": {"required": ["schedule"]}}
    top = _object(TOP)
    return {
        "$schema": DRAFT,
        "$id": SCHEMA_ID,
        "title": "sandbox scenario",
        "description": "A scenario file of sandbox (a YAML document). Lengths in "
        'metres or as multiples of the vehicle diameter ("3d"); angles in radians; '
        "times in seconds. Checks across fields are done by 'sandbox validate'.",
        **{k: top[k] for k in ("type", "properties", "additionalProperties")},
        "$defs": {
            "length": length,
            "vehicleParams": params,
            "gains": _object(GAINS),
            "vehicle": vehicle,
            "drive": drive,
            "reference": _plugin_section("reference"),
            "formation": _plugin_section("law"),
            "platoon": _object(PLATOON),
            "platoonEntry": _object(PLATOONS),
            "event": _object(EVENT),
            "recovery": _plugin_section("strategy"),
            "failure": _plugin_section("failure"),
            "obstacle": _plugin_section("obstacle"),
            "metrics": _object(METRICS),
            "sensing": _object(SENSING),
            "detection": _plugin_section("detector"),
            "safety": _plugin_section("filter"),
            "reconfigure": _object(RECONFIGURE),
            "sensors": _object(SENSORS),
            "range": _object(RANGE),
        },
    }


def schema_json() -> str:
    """The schema as indented JSON text, with a trailing newline."""
    return json.dumps(build_schema(), indent=2) + "\n"
