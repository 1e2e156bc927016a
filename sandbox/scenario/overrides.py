"""``--set`` overrides: ``path=value`` assignments applied to a scenario document.

Each names a field by a dotted path (``recovery.beta``, ``vehicles[1].pose``), checked
against the keys allowed where it points (a plug-in's own keys once it is loaded); a
problem of an overridden field is pointed at its ``--set``.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

from sandbox import plugins
from sandbox.errors import Problem
from sandbox.plugins.registration import KINDS, Param
from sandbox.scenario.events import EVENT
from sandbox.scenario.expectations import allowed_keys as expect_keys
from sandbox.scenario.platoons import PLATOONS
from sandbox.scenario.reader import Reader, describe, hint
from sandbox.scenario.sections import (
    METRICS,
    PLUGIN_SECTIONS,
    RECONFIGURE,
    SENSING,
    TOP,
)
from sandbox.scenario.sensors import RANGE, SENSORS
from sandbox.scenario.vehicles import DRIVE, GAINS, PLATOON, VEHICLE, VEHICLE_PARAMS
from sandbox.scenario.yamlfile import YAMLLoader


def mark_overrides(
    problems: list[Problem], overridden: list[tuple[str, str]]
) -> list[Problem]:
    """Point problems in fields set on the command line at their ``--set``.

    The last ``--set`` that wrote the field (or a mapping holding it) is the one that
    gave it its value.
    """
    out = []
    for p in problems:
        for where, item in reversed(overridden):
            if p.path == where or p.path.startswith((f"{where}.", f"{where}[")):
                p = Problem(p.path, f"{p.message} [from --set {item}]", None)
                break
        out.append(p)
    return out


def apply_override(rd: Reader, doc: dict[Any, Any], item: str) -> str | None:
    """Apply one ``path=value`` assignment, e.g. ``recovery.beta=2``.

    Returns the field path it set, or None (a problem is recorded) if it names no field.
    """
    path, sep, raw = item.partition("=")
    path = path.strip()
    where = f"--set {item}"
    if not sep or not path:
        rd.fail(
            where, "not an assignment", repr(item), "PATH=VALUE, e.g. recovery.beta=2.5"
        )
        return None
    try:
        value = yaml.load(raw, Loader=YAMLLoader)
    except (yaml.YAMLError, RecursionError, ValueError):
        value = raw
    tokens = re.findall(r"[^.\[\]]+|\[\d+\]", path)
    if "".join(t if t.startswith("[") else f".{t}" for t in tokens).lstrip(".") != path:
        rd.fail(
            where,
            "names no field",
            repr(path),
            "a dotted path like recovery.beta or vehicles[1].pose",
        )
        return None
    target: Any = doc
    for k, tok in enumerate(tokens):
        last = k == len(tokens) - 1
        if tok.startswith("["):
            idx = int(tok[1:-1])
            if not isinstance(target, list) or idx >= len(target):
                size = (
                    f"a list of {len(target)}"
                    if isinstance(target, list)
                    else "no list"
                )
                rd.fail(
                    where,
                    "names no field",
                    f"{size} at {path[: path.rfind(tok)]}",
                    f"an index below {len(target) if isinstance(target, list) else 0}",
                )
                return None
            if last:
                target[idx] = value
            else:
                target = target[idx]
            continue
        if not isinstance(target, dict):
            rd.fail(
                where,
                "names no field",
                f"{tok!r} under {describe(target)}",
                "a key under a mapping",
            )
            return None
        allowed = allowed_keys(tokens[:k], target)
        if tok not in allowed:
            rd.fail(
                where,
                f"names no field{hint(tok, allowed)}",
                repr(tok),
                f"one of: {', '.join(allowed)}",
            )
            return None
        if last:
            target[tok] = value
        else:
            if target.get(tok) is None:
                if tokens[k + 1].startswith("["):
                    rd.fail(
                        where,
                        "names no field",
                        f"no list at {tok}",
                        f"an existing item of {tok}, or --set {tok}=[...]",
                    )
                    return None
                target[tok] = {}
            target = target[tok]
    return path


#: The declared tables of the sections ``--set`` may reach, by the name a ``Param``'s
#: schema refers to them with (``{"$ref": "#/$defs/NAME"}``, as in the JSON Schema).
DECLARED: dict[str, dict[str, Param]] = {
    "vehicleParams": VEHICLE_PARAMS,
    "gains": GAINS,
    "vehicle": {**VEHICLE, **VEHICLE_PARAMS},
    "drive": DRIVE,
    "platoon": PLATOON,
    "platoonEntry": PLATOONS,
    "event": EVENT,
    "metrics": METRICS,
    "sensing": SENSING,
    "reconfigure": RECONFIGURE,
    "sensors": SENSORS,
    "range": RANGE,
}
#: The sections that select a plug-in, by the name their schema has, and its kind.
PLUGIN_DEFS = {
    KINDS[kind].section if kind not in ("failure", "obstacle") else kind: kind
    for kind in PLUGIN_SECTIONS
}


def allowed_keys(parents: list[str], node: dict[Any, Any]) -> tuple[str, ...]:
    """Keys allowed at a position in the document (for ``--set``).

    ``parents`` are the tokens of the path above the position (``["sensors",
    "range"]``, ``["vehicles", "[1]", "gains"]``). The keys come from the
    declarations, following each key's schema to the table of its section, so that a
    section the file does not have yet (``--set sensors.range.rate=5``) is made by
    the assignment; ``node`` is the mapping found there (a plug-in section's
    selector, keys of a free-form section).
    """
    names = [t for t in parents if not t.startswith("[")]
    if names and names[0] == "expect":
        return expect_keys(names[1:], node)
    schema: Any = {"$ref": "#/$defs/top"}
    for tok in parents:
        if tok.startswith("["):
            items = schema.get("items") if isinstance(schema, dict) else None
            if not isinstance(items, dict):
                return tuple(str(key) for key in node)
            schema = items
            continue
        table = _table(schema, {})  # a section above: its own keys and every plug-in's
        if table is None or tok not in table:
            return tuple(str(key) for key in node)
        schema = table[tok]
    table = _table(schema, node)
    return tuple(str(key) for key in node) if table is None else tuple(table)


def _table(schema: Any, node: dict[Any, Any]) -> dict[str, Any] | None:
    """The keys of a section's schema, each with its own schema (None: not known).

    A declared table gives its ``Param``s' schemas; a section that selects a plug-in
    gives its own keys and the selected plug-in's (every plug-in's for a lenient
    kind, or when none is selected yet); an inline object its properties.
    """
    if not isinstance(schema, dict):
        return None
    ref = schema.get("$ref", "")
    name = ref.rpartition("/")[2] if isinstance(ref, str) else ""
    if name == "top":
        return {k: _schema_of(p) for k, p in TOP.items()}
    if name in DECLARED:
        return {k: _schema_of(p) for k, p in DECLARED[name].items()}
    if name in PLUGIN_DEFS:
        kind = PLUGIN_DEFS[name]
        own = PLUGIN_SECTIONS[kind]
        info = KINDS[kind]
        selected = node.get(info.selector, own[info.selector].default)
        registered = plugins.registry(kind)
        if isinstance(selected, str) and selected in registered and not info.lenient:
            params = registered[selected].params
        else:
            params = plugins.all_params(kind)
        keys = {k: _schema_of(p) for k, p in own.items()}
        keys.update({k: {} for k in params if k not in keys})
        return keys
    properties = schema.get("properties")
    if isinstance(properties, dict):
        return dict(properties)
    return None


def _schema_of(p: Param) -> dict[str, Any]:
    """A declared key's schema as far as ``--set`` follows it (its sections)."""
    return dict(p.schema or {}) if p.type == "custom" else {}
