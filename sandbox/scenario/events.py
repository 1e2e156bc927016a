"""The ``events:`` section: platoons that merge and split during the run.

Each event fires once, at a time (``at: T`` [s]) or on a condition (``when: {platoon:
B, within: D, of: A}``: the first period some vehicle of B is within ``D`` metres,
centre to centre, of some vehicle of A), and is a merge or a split::

    events:
      - when: {platoon: B, within: 3.0, of: A}
        merge: {into: A, from: B}       # B's vehicles join A's formation; B ends
      - at: 12
        split: {platoon: A, vehicles: [a3, a4], new: C,
                reference: {type: line, start: [0, 2], heading: 0, speed: 1}}

A merge appends B's slots behind A's (B's offsets shifted along the first axis to
start one spacing behind A's last slot) and assigns A's and B's followers to the
slots by minimum total squared distance (the Hungarian assignment of
:mod:`sandbox.behaviour.reconfigure`); A's leader keeps the lead. A split forms the
platoon C of the listed vehicles of A (not its leader), led by the first listed, with
A's law, offsets relative to the new leader's and its own reference; A keeps the
others. The loop's side is :mod:`sandbox.loop.platoons`.

The checks: exactly one of ``at`` and ``when`` and one of ``merge`` and ``split``;
every platoon named exists at that point of the list (the initial ones, those split
off by earlier events, less those merged away); a time within the run; a split's
vehicles in its platoon, not its leader, not all of it, and a new name. An event that
can never fire is an error.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from sandbox.plugins.registration import Param
from sandbox.scenario.reader import NAME_RULE, Reader, describe, hint, name_problem
from sandbox.scenario.sections import read_reference
from sandbox.scenario.specs import ReferenceSpec, plain

_WHEN = {
    "type": "object",
    "properties": {
        "platoon": {"type": "string"},
        "within": {"type": "number", "exclusiveMinimum": 0},
        "of": {"type": "string"},
    },
    "required": ["platoon", "within", "of"],
    "additionalProperties": False,
}
_MERGE = {
    "type": "object",
    "properties": {"into": {"type": "string"}, "from": {"type": "string"}},
    "required": ["into", "from"],
    "additionalProperties": False,
}
_SPLIT = {
    "type": "object",
    "properties": {
        "platoon": {"type": "string"},
        "vehicles": {"type": "array", "items": {"type": "string"}, "minItems": 1},
        "new": {"type": "string"},
        "reference": {"$ref": "#/$defs/reference"},
    },
    "required": ["platoon", "vehicles", "new", "reference"],
    "additionalProperties": False,
}

#: The keys of an entry of ``events:``.
EVENT: dict[str, Param] = {
    "at": Param("number", None, "s", "When the event fires (or when:)", minimum=0.0),
    "when": Param(
        "custom",
        None,
        doc="{platoon: B, within: D [m], of: A}: fires the first period a vehicle of "
        "B is within D of a vehicle of A (or at:)",
        schema=_WHEN,
    ),
    "merge": Param(
        "custom",
        None,
        doc="{into: A, from: B}: B's vehicles join A's formation (Hungarian slots)",
        schema=_MERGE,
    ),
    "split": Param(
        "custom",
        None,
        doc="{platoon: A, vehicles: [...], new: C, reference: {...}}: the listed "
        "vehicles of A form platoon C, led by the first, on its own reference",
        schema=_SPLIT,
    ),
}
EVENT_KEYS = tuple(EVENT)


@dataclass(frozen=True)
class EventSpec:
    """One event of ``events:`` (see the module docstring).

    ``at`` [s] or ``when`` ``(platoon, within [m], of)``; ``kind`` ``merge`` (``into``,
    ``source``) or ``split`` (``platoon``, ``vehicles``, ``new``, ``reference``).
    """

    kind: str
    at: float | None = None
    when: tuple[str, float, str] | None = None
    into: str | None = None
    source: str | None = None
    platoon: str | None = None
    vehicles: tuple[str, ...] = ()
    new: str | None = None
    reference: ReferenceSpec | None = None

    def document(self) -> dict[str, Any]:
        """The event as written in ``events:`` (read back to the same event)."""
        doc: dict[str, Any] = {}
        if self.at is not None:
            doc["at"] = self.at
        if self.when is not None:
            doc["when"] = dict(zip(("platoon", "within", "of"), self.when, strict=True))
        if self.kind == "merge":
            doc["merge"] = {"into": self.into, "from": self.source}
        else:
            ref = {"type": self.reference.type, **plain(self.reference.params, True)}
            doc["split"] = {
                "platoon": self.platoon,
                "vehicles": list(self.vehicles),
                "new": self.new,
                "reference": ref,
            }
        return doc


def read_events(
    rd: Reader,
    doc: Any,
    platoons: list[Any],
    duration: float,
) -> list[EventSpec]:
    """The ``events:`` of a world of several platoons; problems go to ``rd``."""
    out: list[EventSpec] = []
    alive = {p.name: [v.name for v in p.scenario.vehicles] for p in platoons}
    leaders = {
        p.name: p.scenario.vehicles[p.scenario.leader_index].name for p in platoons
    }
    for _, path, m in rd.items(doc, "events", "events"):
        rd.keys(m, EVENT_KEYS, path)
        at = None
        if m.get("at") is not None:
            at = rd.number(m, "at", path, None, minimum=0.0)
            if isinstance(at, float) and at >= duration:
                rd.fail(
                    f"{path}.at",
                    "the event can never fire",
                    f"at = {at:g} s, the run lasts {duration:g} s",
                    "a time within the run",
                )
        when = _when(rd, m.get("when"), f"{path}.when", alive)
        if (m.get("at") is None) == (m.get("when") is None):
            rd.fail(path, "needs exactly one of at and when", _keys(m), "at: or when:")
        kinds = [k for k in ("merge", "split") if m.get(k) is not None]
        if len(kinds) != 1:
            rd.fail(
                path,
                "needs exactly one of merge and split",
                _keys(m),
                "merge: or split:",
            )
            continue
        if kinds[0] == "merge":
            event = _merge(rd, m["merge"], f"{path}.merge", alive, leaders)
        else:
            event = _split(rd, m["split"], f"{path}.split", alive, leaders)
        if event is not None:
            out.append(dataclasses.replace(event, at=at, when=when))
    return out


def _keys(m: dict[Any, Any]) -> str:
    return ", ".join(str(k) for k in m) or "nothing"


def _name(
    rd: Reader, m: dict[Any, Any], key: str, path: str, alive: dict
) -> str | None:
    value = m.get(key)
    if isinstance(value, str) and value in alive:
        return value
    rd.fail(
        f"{path}.{key}",
        "no such platoon"
        + (hint(value, tuple(alive)) if isinstance(value, str) else ""),
        describe(value),
        f"one of: {', '.join(alive)} (at this point of the events)",
    )
    return None


def _when(
    rd: Reader, doc: Any, path: str, alive: dict
) -> tuple[str, float, str] | None:
    if doc is None:
        return None
    m = rd.mapping(doc, path)
    if m is None:
        return None
    rd.keys(m, ("platoon", "within", "of"), path)
    a, b = _name(rd, m, "platoon", path, alive), _name(rd, m, "of", path, alive)
    within = rd.number(m, "within", path, None, positive=True, length=True)
    if a is not None and a == b:
        rd.fail(
            f"{path}.of",
            "the event can never fire",
            f"{a} within of itself",
            "another platoon",
        )
        return None
    if a is None or b is None or not isinstance(within, float):
        return None
    return (a, within, b)


def _merge(
    rd: Reader, doc: Any, path: str, alive: dict, leaders: dict
) -> EventSpec | None:
    m = rd.mapping(doc, path)
    if m is None:
        return None
    rd.keys(m, ("into", "from"), path)
    into, source = _name(rd, m, "into", path, alive), _name(rd, m, "from", path, alive)
    if into is not None and into == source:
        rd.fail(
            f"{path}.from",
            "a platoon cannot merge into itself",
            into,
            "another platoon",
        )
        return None
    if into is None or source is None:
        return None
    alive[into] = alive[into] + alive.pop(source)
    leaders.pop(source, None)
    return EventSpec("merge", into=into, source=source)


def _split(
    rd: Reader, doc: Any, path: str, alive: dict, leaders: dict
) -> EventSpec | None:
    m = rd.mapping(doc, path)
    if m is None:
        return None
    rd.keys(m, ("platoon", "vehicles", "new", "reference"), path)
    name = _name(rd, m, "platoon", path, alive)
    new = m.get("new")
    if not isinstance(new, str) or not new.strip() or new in alive:
        rd.fail(
            f"{path}.new",
            "not a new platoon name",
            describe(new),
            "a name no platoon has",
        )
        new = None
    elif (why := name_problem(new)) is not None:  # the rule of every platoon's name
        rd.fail(
            f"{path}.new",
            "unusable name",
            f"{describe(new)}, which {why}",
            NAME_RULE,
        )
        new = None
    vehicles = m.get("vehicles")
    if (
        not isinstance(vehicles, list)
        or not vehicles
        or not all(isinstance(v, str) for v in vehicles)
    ):
        rd.fail(
            f"{path}.vehicles",
            "not a list of vehicle names",
            describe(vehicles),
            "names of the platoon's vehicles",
        )
        return None
    reference = None
    if m.get("reference") is None:
        rd.fail(
            f"{path}.reference",
            "required key is missing",
            "nothing",
            "the new platoon's reference",
        )
    else:
        reference = read_reference(rd, m["reference"], f"{path}.reference")
    if name is None or new is None or reference is None:
        return None
    mine = alive[name]
    for k, v in enumerate(vehicles):
        if v not in mine:
            rd.fail(
                f"{path}.vehicles[{k}]",
                f"not a vehicle of platoon {name}",
                repr(v),
                f"one of: {', '.join(mine)}",
            )
            return None
        if v == leaders.get(name):
            rd.fail(
                f"{path}.vehicles[{k}]",
                f"{v} leads platoon {name}",
                repr(v),
                "followers only (the leader stays)",
            )
            return None
    if len(set(vehicles)) != len(vehicles):
        rd.fail(
            f"{path}.vehicles",
            "a vehicle listed twice",
            describe(vehicles),
            "each once",
        )
        return None
    alive[name] = [v for v in mine if v not in vehicles]
    alive[new] = list(vehicles)
    leaders[new] = vehicles[0]
    return EventSpec(
        "split", platoon=name, vehicles=tuple(vehicles), new=new, reference=reference
    )
