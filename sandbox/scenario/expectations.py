"""The ``expect:`` section of a scenario: its grammar, its schema and its reader.

A scenario may state what its run must show; ``sandbox check``, the pytest plugin and
:func:`sandbox.testing.check_scenario` run it and compare
(:mod:`sandbox.run.expectations` evaluates it on the run). The grammar (documented key
by key in ``scenarios/reference.yaml``)::

    expect:
      status: ok                  # ok | diverged; default ok (checked even if left out)
      collisions:                 # counts of contact episodes (metrics.json)
        healthy: 0                #   a whole number: exactly that many
        total: {at_most: 3}       #   or a bound (at_least and/or at_most)
        vehicle_vehicle: {at_least: 1}
        vehicle_obstacle: 0
      converged: true             # every healthy vehicle settles (metrics.json)
      deadlocks: 0                # entries of metrics.json's deadlocks (or a bound)
      min_distance: {at_least: 0.45}        # [m] (or "0.9d")
      settling_time:                        # [s]
        at_most: 8                          #   the worst healthy vehicle, and/or
        red: {at_most: 5}                   #   per vehicle by name
      formation_error:                      # [m] per vehicle: rms_last_quarter,
        red: {rms_last_quarter: {at_most: 0.06}, final: {at_most: 0.001}}  # final, max

Bounds are inclusive. Every quantity is the one of ``metrics.json``
(:func:`sandbox.compute_metrics`), so a check reads exactly what ``sandbox run``
reports. Reading the section is the loader's business (:func:`read_expectations`,
called by :func:`sandbox.scenario.parse_scenario` with its field reader, so problems
come with line numbers and did-you-mean hints like those of every other section).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sandbox.scenario.reader import Reader

#: Keys of the ``expect:`` section.
EXPECT_KEYS = (
    "status",
    "collisions",
    "converged",
    "deadlocks",
    "min_distance",
    "settling_time",
    "formation_error",
    "platoons",
)
#: Collision counts that can be expected (keys of ``metrics.json``'s ``collisions``).
COLLISION_KINDS = (
    "healthy",
    "total",
    "vehicle_vehicle",
    "vehicle_obstacle",
    "intra_platoon",
    "inter_platoon",
)
#: The collision counts of a world of several platoons only.
PLATOON_KINDS = ("intra_platoon", "inter_platoon")
#: Keys of a platoon's entry under ``expect: platoons:``.
PLATOON_EXPECT_KEYS = ("converged", "settling_time", "formation_error", "collisions")
#: Statistics of a vehicle's formation error (``metrics.json``).
FORMATION_STATS = ("rms_last_quarter", "final", "max")
#: Keys of a bound.
BOUND_KEYS = ("at_least", "at_most")
#: Run statuses that can be expected.
STATUSES = ("ok", "diverged")
#: Largest count an expectation may state (counts beyond it cannot be told apart).
MAX_COUNT = 10**9
#: Upper bounds that no run can exceed in practice, by kind: with no lower bound above
#: 0, such an expectation cannot fail (10^6 m or s: far beyond any run's scale).
NEVER_FAILS = {"count": MAX_COUNT, "length": 1e6, "time": 1e6}
#: Collision events named in a message before "... and N more".
SHOWN_EVENTS = 3
#: Vehicle names listed in a message before "... (N vehicles)".
SHOWN_NAMES = 8


# ------------------------------------------------------------------------- the schema
def _bound_schema(end: dict[str, Any], what: str) -> dict[str, Any]:
    return {
        "type": "object",
        "description": f"A bound on {what}: at_least and/or at_most (inclusive)",
        "properties": {
            "at_least": {
                "anyOf": [end, {"type": "null"}],
                "description": "Smallest value allowed (inclusive)",
            },
            "at_most": {
                "anyOf": [end, {"type": "null"}],
                "description": "Largest value allowed (inclusive)",
            },
        },
        "additionalProperties": False,
        "minProperties": 1,
    }


_COUNT = {"type": "integer", "minimum": 0}
_TIME = {"type": "number", "minimum": 0}
_LENGTH_END = {
    "anyOf": [
        {"type": "number", "minimum": 0},
        {
            "type": "string",
            "pattern": r"^\s*\+?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*d\s*$",
        },
    ]
}
_COUNT_BOUND = {
    "anyOf": [_COUNT, _bound_schema(_COUNT, "a count")],
    "description": "A whole number (exactly that many), or at_least and/or at_most",
}
_LENGTH_BOUND = _bound_schema(_LENGTH_END, "a length [m] (or like '3d')")
_TIME_BOUND = _bound_schema(_TIME, "a time [s]")


def _nullable(fragment: dict[str, Any]) -> dict[str, Any]:
    """A fragment that also accepts null (the loader reads null as "not given")."""
    docs = {k: v for k, v in fragment.items() if k == "description"}
    core = {k: v for k, v in fragment.items() if k != "description"}
    return {"anyOf": [core, {"type": "null"}], **docs}


_COLLISION_DOCS = {
    "healthy": "Contacts in which no vehicle had an active failure",
    "total": "Every contact episode",
    "vehicle_vehicle": "Contacts between two vehicles",
    "vehicle_obstacle": "Contacts of a vehicle with an obstacle",
    "intra_platoon": "Contacts between two vehicles of one platoon (with platoons:)",
    "inter_platoon": "Contacts between vehicles of two platoons (with platoons:)",
}
_STAT_DOCS = {
    "rms_last_quarter": "RMS over the last quarter of the run [m]",
    "final": "At the last sample [m]",
    "max": "Largest over the run [m]",
}
#: The JSON Schema of the ``expect:`` section (used by :mod:`sandbox.scenario.schema`).
EXPECT_SCHEMA: dict[str, Any] = {
    "type": "object",
    "additionalProperties": False,
    "properties": {
        "status": {
            "anyOf": [{"type": "string", "enum": list(STATUSES)}, {"type": "null"}],
            "description": "The status the run must end with (checked even when "
            "left out)",
            "default": "ok",
        },
        "collisions": _nullable(
            {
                "type": "object",
                "description": "Bounds on the collision counts of metrics.json",
                "properties": {
                    k: _nullable({**_COUNT_BOUND, "description": doc})
                    for k, doc in _COLLISION_DOCS.items()
                },
                "additionalProperties": False,
            }
        ),
        "converged": _nullable(
            {
                "type": "boolean",
                "description": "Whether every healthy vehicle must settle "
                "(metrics.json)",
            }
        ),
        "deadlocks": _nullable(
            {
                **_COUNT_BOUND,
                "description": "Bound on the number of deadlocks (metrics.json)",
            }
        ),
        "min_distance": _nullable(
            {
                **_LENGTH_BOUND,
                "description": "Bound on the smallest centre distance between two "
                "vehicles [m]",
            }
        ),
        "settling_time": _nullable(
            {
                "type": "object",
                "description": "at_least/at_most: bound on the latest settling time of "
                "the healthy vehicles [s]; a vehicle name: bound on that vehicle's",
                "properties": {
                    k: {"anyOf": [_TIME, {"type": "null"}]}
                    for k in ("at_least", "at_most")
                },
                "additionalProperties": _nullable(_TIME_BOUND),
                "minProperties": 1,
            }
        ),
        "formation_error": _nullable(
            {
                "type": "object",
                "description": "Per vehicle name: bounds on its formation-error "
                "statistics (metrics.json) [m]",
                "additionalProperties": _nullable(
                    {
                        "type": "object",
                        "properties": {
                            k: _nullable({**_LENGTH_BOUND, "description": doc})
                            for k, doc in _STAT_DOCS.items()
                        },
                        "additionalProperties": False,
                    }
                ),
            }
        ),
        "platoons": _nullable(
            {
                "type": "object",
                "description": "Per platoon name (with platoons:): converged, "
                "settling_time (a bound [s]), formation_error (bounds on the worst "
                "vehicle's statistics [m]) and collisions (intra_platoon, "
                "inter_platoon, vehicle_obstacle counts involving the platoon)",
                "additionalProperties": _nullable(
                    {
                        "type": "object",
                        "properties": {
                            "converged": _nullable({"type": "boolean"}),
                            "settling_time": _nullable(_TIME_BOUND),
                            "formation_error": _nullable(
                                {
                                    "type": "object",
                                    "properties": {
                                        k: _nullable({**_LENGTH_BOUND})
                                        for k in _STAT_DOCS
                                    },
                                    "additionalProperties": False,
                                }
                            ),
                            "collisions": _nullable(
                                {
                                    "type": "object",
                                    "properties": {
                                        k: _nullable({**_COUNT_BOUND})
                                        for k in (*PLATOON_KINDS, "vehicle_obstacle")
                                    },
                                    "additionalProperties": False,
                                }
                            ),
                        },
                        "additionalProperties": False,
                    }
                ),
            }
        ),
    },
}


@dataclass(frozen=True)
class Bound:
    """An inclusive range ``at_least <= x <= at_most``; either end may be open.

    >>> Bound(at_most=8.0).text("s")
    'at most 8 s'
    >>> Bound(0, 0).text()
    '0'
    >>> Bound(0.45).holds(0.5)
    True
    """

    at_least: float | None = None
    at_most: float | None = None

    def holds(self, value: float | None) -> bool:
        """Whether ``value`` lies in the range (an unmeasured None never does)."""
        if value is None or not math.isfinite(value):
            return False
        if self.at_least is not None and value < self.at_least:
            return False
        return self.at_most is None or value <= self.at_most

    def text(self, unit: str = "") -> str:
        """The bound in words: ``0``, ``at most 8 s``, ``from 1 to 3``."""
        u = f" {unit}" if unit else ""
        lo, hi = self.at_least, self.at_most
        if lo is not None and hi is not None:
            return f"{lo:g}{u}" if lo == hi else f"from {lo:g} to {hi:g}{u}"
        if lo is not None:
            return f"at least {lo:g}{u}"
        return f"at most {hi:g}{u}"

    def to_doc(self, exact: bool = False) -> Any:
        """The YAML form: a mapping, or the bare count of an exact count."""
        if exact and self.at_least is not None and self.at_least == self.at_most:
            return self.at_least
        return {k: getattr(self, k) for k in BOUND_KEYS if getattr(self, k) is not None}


@dataclass(frozen=True)
class Expectations:
    """A validated ``expect:`` section (see the module docstring for its grammar).

    Attributes
    ----------
    status : str
        ``ok`` or ``diverged``: the status the run must end with.
    collisions : tuple of (kind, Bound)
        Bounds on collision counts, ``kind`` one of :data:`COLLISION_KINDS`.
    converged : bool or None
        Whether ``converged`` must be true or false (None: not checked).
    deadlocks : Bound or None
        Bound on the number of entries of ``deadlocks`` (metrics.json).
    min_distance : Bound or None
        Bound on the smallest centre distance between two vehicles [m].
    settling_time : Bound or None
        Bound on the latest settling time of the healthy vehicles [s].
    settling_times : tuple of (vehicle, Bound)
        Bounds on the settling times of named vehicles [s].
    formation_error : tuple of (vehicle, statistic, Bound)
        Bounds on formation-error statistics of named vehicles [m], ``statistic`` one
        of :data:`FORMATION_STATS`.
    """

    status: str = "ok"
    collisions: tuple[tuple[str, Bound], ...] = ()
    converged: bool | None = None
    deadlocks: Bound | None = None
    min_distance: Bound | None = None
    settling_time: Bound | None = None
    settling_times: tuple[tuple[str, Bound], ...] = ()
    formation_error: tuple[tuple[str, str, Bound], ...] = ()
    #: Per platoon: ``(platoon, key, value)``, ``key`` ``converged`` (a bool),
    #: ``settling_time``, ``formation_error.STAT`` or ``collisions.KIND`` (a Bound).
    platoons: tuple[tuple[str, str, Any], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """A plain ``expect:`` document that :func:`read_expectations` reads back."""
        doc: dict[str, Any] = {"status": self.status}
        if self.collisions:
            doc["collisions"] = {k: b.to_doc(exact=True) for k, b in self.collisions}
        if self.converged is not None:
            doc["converged"] = self.converged
        if self.deadlocks is not None:
            doc["deadlocks"] = self.deadlocks.to_doc(exact=True)
        if self.min_distance is not None:
            doc["min_distance"] = self.min_distance.to_doc()
        settle: dict[str, Any] = {}
        if self.settling_time is not None:
            settle.update(self.settling_time.to_doc())
        settle.update({name: b.to_doc() for name, b in self.settling_times})
        if settle:
            doc["settling_time"] = settle
        if self.formation_error:
            fe: dict[str, dict[str, Any]] = {}
            for name, stat, b in self.formation_error:
                fe.setdefault(name, {})[stat] = b.to_doc()
            doc["formation_error"] = fe
        if self.platoons:
            pl: dict[str, dict[str, Any]] = {}
            for name, key, value in self.platoons:
                entry = pl.setdefault(name, {})
                if key == "converged":
                    entry[key] = value
                elif key == "settling_time":
                    entry[key] = value.to_doc()
                else:
                    head, stat = key.split(".")
                    exact = head == "collisions"
                    entry.setdefault(head, {})[stat] = value.to_doc(exact=exact)
            doc["platoons"] = pl
        return doc


# ------------------------------------------------------------------------------ reading
def read_expectations(
    rd: Reader,
    doc: Any,
    path: str,
    names: Sequence[str] | None,
    platoons: Sequence[str] | None = None,
) -> Expectations | None:
    """Read an ``expect:`` section; problems go to the reader ``rd``.

    Parameters
    ----------
    rd : sandbox.scenario.reader.Reader
        The loader's field reader (collects problems with their YAML lines).
    doc : Any
        The section as loaded from YAML; None or an empty mapping: no expectations.
    path : str
        Its field path (``"expect"``).
    names : sequence of str or None
        The scenario's vehicle names (None when the vehicles are invalid: names are
        then not checked).
    platoons : sequence of str, optional
        The names of the platoons of a world of several (``platoons:``); without,
        the per-platoon expectations are errors.

    Returns
    -------
    Expectations or None
        None when there is no section or it has problems.
    """
    from sandbox.scenario.reader import describe

    m = rd.mapping(doc, path)
    if not m:
        return None
    before = len(rd.problems)
    rd.keys(m, EXPECT_KEYS, path)
    status = rd.choice(m, "status", path, "ok", STATUSES, "status") or "ok"
    collisions = []
    if m.get("collisions") is not None:
        cm = rd.mapping(m["collisions"], f"{path}.collisions") or {}
        rd.keys(cm, COLLISION_KINDS, f"{path}.collisions")
        for kind in COLLISION_KINDS:
            if kind in PLATOON_KINDS and cm.get(kind) is not None and not platoons:
                rd.fail(
                    f"{path}.collisions.{kind}",
                    "counted only in a world of several platoons",
                    f"{kind} without platoons:",
                    "a platoons: section, or another count",
                )
                continue
            if cm.get(kind) is not None:
                b = _bound(rd, cm[kind], f"{path}.collisions.{kind}", "count")
                if b is not None:
                    collisions.append((kind, b))
    converged = None
    if m.get("converged") is not None:
        converged = rd.boolean(m, "converged", path, False)
    deadlocks = None
    if m.get("deadlocks") is not None:
        deadlocks = _bound(rd, m["deadlocks"], f"{path}.deadlocks", "count")
    min_distance = None
    if m.get("min_distance") is not None:
        min_distance = _bound(rd, m["min_distance"], f"{path}.min_distance", "length")
    settling_time, settling_times = None, []
    if m.get("settling_time") is not None:
        sub = f"{path}.settling_time"
        sm = rd.mapping(m["settling_time"], sub)
        if sm is not None:
            own = {k: v for k, v in sm.items() if k in BOUND_KEYS and v is not None}
            if own:
                settling_time = _bound(rd, own, sub, "time")
            for name, value in sm.items():
                if name in BOUND_KEYS or not _vehicle(rd, name, names, sub, True):
                    continue
                if value is None:  # null: not given, as everywhere in the format
                    continue
                b = _bound(rd, value, f"{sub}.{name}", "time")
                if b is not None:
                    settling_times.append((name, b))
            if not sm:
                rd.fail(sub, "empty", describe(sm), _settle_kind())
    formation_error = []
    if m.get("formation_error") is not None:
        sub = f"{path}.formation_error"
        fm = rd.mapping(m["formation_error"], sub) or {}
        for name, value in fm.items():
            if not _vehicle(rd, name, names, sub, False):
                continue
            vm = rd.mapping(value, f"{sub}.{name}") or {}
            rd.keys(vm, FORMATION_STATS, f"{sub}.{name}")
            for stat in FORMATION_STATS:
                if vm.get(stat) is not None:
                    b = _bound(rd, vm[stat], f"{sub}.{name}.{stat}", "length")
                    if b is not None:
                        formation_error.append((name, stat, b))
    per_platoon = _read_platoons(rd, m.get("platoons"), f"{path}.platoons", platoons)
    if len(rd.problems) > before:
        return None
    return Expectations(
        platoons=per_platoon,
        status=status,
        collisions=tuple(collisions),
        converged=converged,
        deadlocks=deadlocks,
        min_distance=min_distance,
        settling_time=settling_time,
        settling_times=tuple(settling_times),
        formation_error=tuple(formation_error),
    )


def _read_platoons(
    rd: Reader, doc: Any, path: str, platoons: Sequence[str] | None
) -> tuple[tuple[str, str, Any], ...]:
    """The ``expect: platoons:`` entries, ``(platoon, key, value)``."""
    from sandbox.scenario.reader import describe, hint

    if doc is None:
        return ()
    if not platoons:
        rd.fail(path, "only with platoons:", describe(doc), "a platoons: section")
        return ()
    out: list[tuple[str, str, Any]] = []
    for name, value in (rd.mapping(doc, path) or {}).items():
        sub = f"{path}.{name}"
        if name not in platoons:
            rd.fail(
                sub,
                f"no such platoon{hint(name, tuple(platoons))}",
                describe(name),
                f"one of: {', '.join(platoons)}",
            )
            continue
        pm = rd.mapping(value, sub) or {}
        rd.keys(pm, PLATOON_EXPECT_KEYS, sub)
        if pm.get("converged") is not None:
            out.append((name, "converged", rd.boolean(pm, "converged", sub, False)))
        if pm.get("settling_time") is not None:
            b = _bound(rd, pm["settling_time"], f"{sub}.settling_time", "time")
            if b is not None:
                out.append((name, "settling_time", b))
        for head, keys, kind in (
            ("formation_error", FORMATION_STATS, "length"),
            ("collisions", (*PLATOON_KINDS, "vehicle_obstacle"), "count"),
        ):
            if pm.get(head) is None:
                continue
            hm = rd.mapping(pm[head], f"{sub}.{head}") or {}
            rd.keys(hm, keys, f"{sub}.{head}")
            for key in keys:
                if hm.get(key) is not None:
                    b = _bound(rd, hm[key], f"{sub}.{head}.{key}", kind)
                    if b is not None:
                        out.append((name, f"{head}.{key}", b))
    return tuple(out)


def _settle_kind() -> str:
    return "at_least and/or at_most [s] (the worst healthy vehicle), or vehicle names"


def _names_text(names: Sequence[str]) -> str:
    shown = ", ".join(names[:SHOWN_NAMES])
    if len(names) > SHOWN_NAMES:
        shown += f", ... ({len(names)} vehicles)"
    return shown


def _vehicle(
    rd: Reader, name: Any, names: Sequence[str] | None, path: str, bounds: bool
) -> bool:
    """Whether ``name`` is a vehicle of the scenario; records a problem if not."""
    from sandbox.scenario.reader import describe, hint

    if isinstance(name, str) and (names is None or name in names):
        return True
    allowed = (*BOUND_KEYS, *(names or ())) if bounds else tuple(names or ())
    expected = f"one of: {_names_text(list(names or ()))}"
    if bounds:
        expected = (
            f"at_least, at_most, or a vehicle name: {_names_text(list(names or ()))}"
        )
    what = "unknown key" if bounds else "no such vehicle"
    rd.fail(f"{path}.{name}", f"{what}{hint(name, allowed)}", describe(name), expected)
    return False


def _bound(rd: Reader, value: Any, path: str, kind: str) -> Bound | None:
    """Read a bound: ``{at_least: x, at_most: y}``, or a bare whole number for counts.

    ``kind`` is ``count`` (whole numbers >= 0), ``length`` (metres or ``"3d"``, >= 0) or
    ``time`` (seconds, >= 0).
    """
    from sandbox.scenario.reader import describe

    expected = {
        "count": "a whole number >= 0, or {at_least: N} and/or {at_most: N}",
        "length": "{at_least: X} and/or {at_most: X}, in metres or like '3d'",
        "time": "{at_least: T} and/or {at_most: T}, in seconds",
    }[kind]
    if kind == "count" and not isinstance(value, dict):
        n = _count(rd, value, path)
        return None if n is None else Bound(n, n)
    if not isinstance(value, dict):
        rd.fail(path, "not a bound", describe(value), expected)
        return None
    rd.keys(value, BOUND_KEYS, path)
    ends: dict[str, float | None] = {}
    for key in BOUND_KEYS:
        if value.get(key) is None:
            continue
        sub = f"{path}.{key}"
        if kind == "count":
            ends[key] = _count(rd, value[key], sub)
        else:
            ends[key] = rd.check_number(
                value[key], sub, minimum=0, length=kind == "length"
            )
        if ends[key] is None:
            return None
    if not ends:
        if not any(k not in BOUND_KEYS for k in value):
            rd.fail(path, "no bound given", describe(value), expected)
        return None
    lo, hi = ends.get("at_least"), ends.get("at_most")
    if lo is not None and hi is not None and lo > hi:
        rd.fail(path, "empty range", f"at_least {lo:g} > at_most {hi:g}", expected)
        return None
    if (lo is None or lo <= 0) and (hi is None or hi >= NEVER_FAILS[kind]):
        rd.warn(
            path,
            f"this expectation cannot fail ({_bound_text(lo, hi)}): state a "
            "bound a run could miss",
        )
    return Bound(lo, hi)


def _bound_text(lo: float | None, hi: float | None) -> str:
    parts = [
        f"at_least {lo:g}" if lo is not None else "",
        f"at_most {hi:g}" if hi is not None else "",
    ]
    return ", ".join(p for p in parts if p)


def _count(rd: Reader, value: Any, path: str) -> int | None:
    from sandbox.scenario.reader import describe

    if isinstance(value, float) and value.is_integer() and abs(value) < 2**53:
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        rd.fail(path, "not a count", describe(value), "a whole number >= 0")
        return None
    if value > MAX_COUNT:
        shown = (
            f"{value:.3g}"
            if value < 10**300
            else f"a number of {len(str(value))} digits"
        )
        rd.fail(path, "too large a count", shown, f"a whole number up to {MAX_COUNT:,}")
        return None
    return value


class _VehicleNames(tuple):
    """Keys where ``--set`` names a vehicle: any name passes here.

    The loader checks the name against the scenario's vehicles afterwards.
    """

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str)


def allowed_keys(tokens: Sequence[str], node: dict[Any, Any]) -> tuple[str, ...]:
    """Keys ``--set`` may name inside ``expect`` (``tokens``: the keys below it)."""
    depth = len(tokens)
    head = tokens[0] if tokens else ""
    if not tokens:
        return EXPECT_KEYS
    if head == "collisions":
        return COLLISION_KINDS if depth == 1 else BOUND_KEYS
    if head == "min_distance" or (head == "settling_time" and depth == 2):
        return BOUND_KEYS
    if head == "settling_time" or (head == "formation_error" and depth == 1):
        return _VehicleNames(("at_least", "at_most", "<vehicle name>"))
    if head == "formation_error":
        return FORMATION_STATS if depth == 2 else BOUND_KEYS
    return tuple(str(k) for k in node)


# --------------------------------------------------------------------------- evaluation
