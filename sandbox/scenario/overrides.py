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
from sandbox.plugins.registration import (
    KINDS,
)
from sandbox.scenario.events import EVENT_KEYS
from sandbox.scenario.expectations import allowed_keys as expect_keys
from sandbox.scenario.platoons import PLATOONS_KEYS
from sandbox.scenario.reader import (
    _describe,
    _hint,
    _Reader,
)
from sandbox.scenario.sections import (
    METRICS_KEYS,
    PLUGIN_SECTIONS,
    RECONFIGURE_KEYS,
    SENSING_KEYS,
    TOP_KEYS,
)
from sandbox.scenario.vehicles import (
    DRIVE_KEYS,
    GAIN_KEYS,
    PLATOON_KEYS,
    VEHICLE_KEYS,
    VEHICLE_PARAM_KEYS,
)
from sandbox.scenario.yamlfile import (
    _YAMLLoader,
)


def _mark_overrides(
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


def _apply_override(rd: _Reader, doc: dict[Any, Any], item: str) -> str | None:
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
        value = yaml.load(raw, Loader=_YAMLLoader)
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
                f"{tok!r} under {_describe(target)}",
                "a key under a mapping",
            )
            return None
        allowed = _allowed_keys(tokens[:k], target)
        if tok not in allowed:
            rd.fail(
                where,
                f"names no field{_hint(tok, allowed)}",
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


def _allowed_keys(parents: list[str], node: dict[Any, Any]) -> tuple[str, ...]:
    """Keys allowed at a position in the document (for ``--set``)."""
    names = [t for t in parents if not t.startswith("[")]
    if not names:
        return TOP_KEYS
    if names[0] == "expect":
        return expect_keys(names[1:], node)
    head = names[-1]
    if head == "gains":
        return GAIN_KEYS
    table: dict[str, tuple[str, ...]] = {
        "vehicle": VEHICLE_PARAM_KEYS,
        "vehicles": VEHICLE_KEYS,
        "platoon": PLATOON_KEYS,
        "metrics": METRICS_KEYS,
        "sensing": SENSING_KEYS,
        "reconfigure": RECONFIGURE_KEYS,
        "drive": DRIVE_KEYS,
        "platoons": PLATOONS_KEYS,  # an entry of platoons: (scenario/platoons.py)
        "events": EVENT_KEYS,
    }
    if head in table:
        return table[head]
    for kind, own in PLUGIN_SECTIONS.items():
        if KINDS[kind].section != head:
            continue
        name = node.get(KINDS[kind].selector, own[KINDS[kind].selector].default)
        registered = plugins.registry(kind)
        if isinstance(name, str) and name in registered and not KINDS[kind].lenient:
            return (*own, *registered[name].params)
        return (*own, *plugins.all_params(kind))
    return tuple(str(k) for k in node)
