"""Scenario files: YAML -> validated, frozen dataclasses.

Everything a run needs is checked here, at load time, and every problem of a document is
reported at once as a :class:`~sandbox.errors.Problem` with the YAML line of the field
(``FILE:LINE: path.to.field: what is wrong (got X; expected Y)``). The simulation never
re-checks configuration.

The format is documented key by key in ``scenarios/reference.yaml``. Lengths may be
written
in metres (``0.75``) or as multiples of the default vehicle diameter (``"3d"``,
``1.5d``).
"""

from __future__ import annotations

import copy
import dataclasses
import datetime
import difflib
import math
import os
import re
import stat
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.spatial import cKDTree

from sandbox import plugins, randomize
from sandbox.control.flatness import (
    Gains,
    error_poles,
    max_control_period,
)
from sandbox.errors import Problem, ScenarioError
from sandbox.obstacles import SHAPES, ObstacleSpec
from sandbox.plugins import (
    KINDS,
    REQUIRED,
    ObstacleContext,
    Param,
    PluginError,
    ReferenceContext,
)

PLATOON_PATTERNS = ("grid", "line", "wedge", "ring")
DRIVE_TYPES = ("reference", "commands")
# : Default colours, in vehicle order (the report draws the leader blue, then red,
# green).
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


# -------------------------------------------------------------------------- dataclasses
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
    """One vehicle: identity, initial pose, slot offset, physical limits."""

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
    motor_accel: float | None = None
    drive: DriveSpec = field(default_factory=DriveSpec)


@dataclass(frozen=True)
class ReferenceSpec:
    """The reference trajectory: a registered reference ``type`` and its values.

    The values are also readable as attributes (``spec.radius``).
    """

    type: str
    params: dict[str, Any] = field(default_factory=dict)

    def __getattr__(self, name: str) -> Any:
        params = self.__dict__.get("params", {})
        if name in params:
            return params[name]
        raise AttributeError(name)

    def build(self) -> Any:
        """Return the reference object that evaluates ``(p, p', p'')``."""
        plugin = plugins.get("reference", self.type)
        if isinstance(plugin.obj, type):
            return plugin.obj(**self.params)
        return FunctionReference(plugin.obj, dict(self.params))


@dataclass(frozen=True)
class FunctionReference:
    """A reference registered as a function ``f(ctx) -> (p, dp, ddp)``."""

    func: Any
    params: dict[str, Any]

    def evaluate(self, t: float | np.ndarray) -> tuple[np.ndarray, ...]:
        """Return ``(p, dp, ddp)`` at time(s) ``t`` [s], each ``t.shape + (2,)``."""
        t = np.asarray(t, dtype=float)
        p, dp, ddp = self.func(ReferenceContext(t, self.params))
        shape = t.shape + (2,)
        return tuple(
            np.broadcast_to(np.asarray(a, dtype=float), shape).copy()
            for a in (p, dp, ddp)
        )


@dataclass(frozen=True)
class FormationSpec:
    """Which formation law the followers use, and its values."""

    law: str = "rotating"
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def rotate(self) -> bool:
        """The ``rotate`` value of the laws that have one (else False)."""
        return bool(self.params.get("rotate", False))


@dataclass(frozen=True)
class RecoverySpec:
    """Collision avoidance of section 4: the strategy and its values [m]."""

    strategy: str = "none"
    R: float = 1.5
    leader_avoids: bool = False
    target_derivatives: str = "hold"
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def beta(self) -> float | None:
        """``beta`` of the strategy (the built-in weighted ones have it)."""
        return self.params.get("beta")

    @property
    def r(self) -> float | None:
        """Inner radius ``r`` of the strategy (continuous and smooth)."""
        return self.params.get("r")

    @property
    def steepness(self) -> float | None:
        """``steepness`` of the strategy (smooth)."""
        return self.params.get("steepness")


@dataclass(frozen=True)
class FailureSpec:
    """A failure of one vehicle from ``at`` until ``until`` (or the end)."""

    vehicle: str
    at: float
    kind: str
    until: float | None = None
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def v1(self) -> float | None:
        """The ``v1`` value of the kinds that have one."""
        return self.params.get("v1")

    @property
    def v2(self) -> float | None:
        """The ``v2`` value of the kinds that have one."""
        return self.params.get("v2")


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
    """Parameters of the metrics (``metrics.json``).

    ``settle_tol`` [m]: formation error of a settled vehicle; ``settle_dwell`` [s]: how
    long the run must go on in band after the settling time; ``contact_release`` [m]:
    gap between two surfaces that ends a contact episode.
    """

    settle_tol: float = 0.05
    settle_dwell: float = 1.0
    contact_release: float = 0.01


@dataclass(frozen=True)
class Scenario:
    """A validated scenario (build it with :func:`load_scenario`)."""

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
    plugins: tuple[str, ...] = ()

    @property
    def leader_index(self) -> int:
        """Index of the leader vehicle, or -1."""
        for i, v in enumerate(self.vehicles):
            if v.leader:
                return i
        return -1

    def to_dict(self) -> dict[str, Any]:
        """A plain document that :func:`parse_scenario` reads back to this scenario.

        Lengths are resolved to metres. A platoon is written as its ``platoon`` section
        (with the vehicle parameters it uses under ``vehicle``), not as a list of its
        vehicles: parsing regenerates exactly the same vehicles (same seed), and the
        document of a 10,000-vehicle scenario stays a few lines long.
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
        if self.plugins:
            doc["plugins"] = list(self.plugins)
        if self.reference is not None:
            doc["reference"] = {"type": self.reference.type}
            doc["reference"].update(_plain(self.reference.params, skip_none=True))
        if self.formation is not None:
            doc["formation"] = {"law": self.formation.law}
            doc["formation"].update(_plain(self.formation.params, skip_none=True))
        listed = self.vehicles
        if self.platoon is not None:
            listed = self.vehicles[: len(self.vehicles) - self.platoon.count]
            made = self.vehicles[len(listed)]
            for key in ("mass", "v1_max", "v2_max", "max_accel", "motor_accel"):
                if getattr(made, key) is not None:
                    doc["vehicle"][key] = getattr(made, key)
            doc["vehicle"]["gains"] = _plain(made.gains)
            doc["platoon"] = _plain(self.platoon, skip_none=True)
        doc["vehicles"] = []
        for v in listed:
            item = _plain(v, skip_none=True)
            item["gains"] = _plain(v.gains)
            if v.drive.type == "reference":
                del item["drive"]
            doc["vehicles"].append(item)
        doc["recovery"] = _plain(self.recovery, skip_none=True)
        doc["recovery"].update(doc["recovery"].pop("params"))
        # A failure that never starts (a run shortened by --duration) is left out.
        failures = [f for f in self.failures if f.at < self.duration]
        if failures:
            doc["failures"] = []
            for f in failures:
                item = _plain(f, skip_none=True)
                item.update(item.pop("params"))
                doc["failures"].append(item)
        if self.obstacles:
            doc["obstacles"] = [o.document() for o in self.obstacles]
        doc["metrics"] = _plain(self.metrics)
        return doc


def _plain(obj: Any, skip_none: bool = False) -> Any:
    if isinstance(obj, Mapping):
        return {
            k: _plain(v, skip_none)
            for k, v in obj.items()
            if not (skip_none and v is None)
        }
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


# --------------------------------------------------------------------------- the reader
_REQUIRED = REQUIRED
_LENGTH = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*d\s*$")
#: Longest rendering of a value in a message (longer ones are cut with "...").
_SHOW_MAX = 60
#: Largest length or coordinate [m] (the simulation reports a vehicle beyond 1e6 m as
#: diverged), and largest magnitude of any other number.
MAX_LENGTH = 1e6
MAX_NUMBER = 1e9
#: Smallest vehicle diameter [m] (the physics tolerates 2 mm of contact overlap) and
#: mass [kg] (the body's moment of inertia must stay a positive float).
MIN_DIAMETER = 0.01
MIN_MASS = 0.001
#: Most vehicles a scenario may have (listed plus generated by a platoon).
MAX_VEHICLES = 100_000
#: Most control steps of a run (about 9 hours at 30,000 steps per second).
MAX_STEPS = 1e9
#: Most physics substeps per control period.
MAX_SUBSTEPS = 10_000
#: Largest recorded state a run may allocate [bytes] (about 100 bytes per vehicle and
#: recorded sample); beyond it the run is refused at load time instead of failing with a
#: memory error.
MAX_RECORD_BYTES = 1e12
_BYTES_PER_SAMPLE = (
    8 * 13 + 2 + 16
)  # pose, cmd, chi, slot, target; mode, failed; t, ref
#: Largest ``seed`` (numpy's generators take any 64-bit seed; it is stored as int64).
MAX_SEED = 2**63 - 1
#: Largest ``record_every`` (a run has at most MAX_STEPS steps).
MAX_RECORD_EVERY = int(MAX_STEPS)
#: Longest name of a scenario, vehicle or obstacle [characters]; a scenario's name is
#: also the name of its run directory.
MAX_NAME = 100
#: Largest scenario file [bytes]; larger files (and anything that is not a regular
#: file, like /dev/zero or a pipe) are refused before they are read.
MAX_FILE_BYTES = 4_000_000


class _YAMLLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """Safe YAML loader that also reads exponent floats like ``1e-3`` as numbers.

    YAML 1.1 (PyYAML's default) reads ``1e-3`` and ``2.5e3`` as text; YAML 1.2, JSON and
    the editors that check files against the JSON Schema read them as numbers. It is
    libyaml's C parser (``yaml.CSafeLoader``, about 20 times faster) when PyYAML was
    built with it, else the pure-Python ``yaml.SafeLoader``; both give the nodes with
    their lines, from which line numbers and duplicate keys are found.
    """


_YAMLLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _line_map(node: yaml.Node | None, path: str, out: dict[str, int]) -> None:
    """Record the 1-based line of every field of a composed YAML node tree.

    A node reached again through an alias is mapped once (its first path): recursive or
    exponentially aliased documents stay linear. Iterative, so deep nesting cannot
    exhaust the stack.
    """
    seen: set[int] = set()
    stack: list[tuple[yaml.Node | None, str]] = [(node, path)]
    while stack:
        node, path = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        out.setdefault(path, node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                sub = f"{path}.{_key_text(key)}" if path else _key_text(key)
                out.setdefault(sub, key.start_mark.line + 1)
                stack.append((value, sub))
        elif isinstance(node, yaml.SequenceNode):
            for i, value in enumerate(node.value):
                stack.append((value, f"{path}[{i}]"))


def _key_text(key: yaml.Node) -> str:
    return str(key.value) if isinstance(key, yaml.ScalarNode) else "?"


def _duplicate_keys(root: yaml.Node | None) -> list[Problem]:
    """Keys given twice in one mapping (PyYAML would silently keep the last one)."""
    problems = []
    seen: set[int] = set()
    stack: list[tuple[yaml.Node | None, str]] = [(root, "")]
    while stack:
        node, path = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            first: dict[tuple[str, str], int] = {}
            for key, value in node.value:
                text = _key_text(key)
                sub = f"{path}.{text}" if path else text
                stack.append((value, sub))
                if not isinstance(key, yaml.ScalarNode) or key.tag.endswith(":merge"):
                    continue
                line = key.start_mark.line + 1
                if (key.tag, key.value) in first:
                    problems.append(
                        Problem(
                            sub,
                            _says(
                                "duplicate key",
                                f"{text!r} again on line {line}",
                                "each key once; first on line "
                                f"{first[key.tag, key.value]}",
                            ),
                            line,
                        )
                    )
                else:
                    first[key.tag, key.value] = line
        elif isinstance(node, yaml.SequenceNode):
            for i, value in enumerate(node.value):
                stack.append((value, f"{path}[{i}]"))
    return sorted(problems, key=lambda p: p.line or 0)


def _says(what: str, got: str, expected: str) -> str:
    """The message form ``what is wrong (got X; expected Y)``."""
    return f"{what} (got {got}; expected {expected})"


def _describe(value: Any) -> str:
    """A short rendering of a value for messages."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "nothing (null)"
    if isinstance(value, Mapping):
        return f"a mapping of {len(value)} key{'s' if len(value) != 1 else ''}"
    if isinstance(value, list | tuple):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    if isinstance(value, int) and abs(value) > 10**15:
        digits = int(value.bit_length() * math.log10(2)) + 1
        return f"an integer of about {digits} digits"
    if isinstance(value, datetime.date):
        return f"the date {value.isoformat()}"
    text = repr(value)
    if len(text) > _SHOW_MAX:
        text = text[: _SHOW_MAX - 3] + "..."
    return text


def _number_kind(
    positive: bool = False, minimum: float | None = None, length: bool = False
) -> str:
    """What a numeric field expects, in words."""
    base = "a length in metres or a multiple of d like '3d'" if length else "a number"
    if positive:
        return f"{base}, greater than 0"
    if minimum is not None:
        return f"{base}, at least {minimum:g}"
    return base


def _hint(value: Any, allowed: tuple[str, ...]) -> str:
    near = difflib.get_close_matches(
        str(value), [str(a) for a in allowed], n=1, cutoff=0.6
    )
    return f"; did you mean {near[0]!r}?" if near else ""


class _Reader:
    """Typed field access that collects problems instead of raising."""

    def __init__(self, lines: dict[str, int]) -> None:
        self.lines = lines
        self.problems: list[Problem] = []
        self.warnings: list[Problem] = []
        self.diameter = 0.5
        #: ``(path, name, leader)`` of every listed vehicle, valid or not.
        self.declared: list[tuple[str, str, bool]] = []
        #: ``(path, vehicle, at)`` of every failure, with None where invalid.
        self.timed: list[tuple[str, str | None, float | None]] = []
        #: Field paths set by ``--set`` overrides.
        self.overridden: set[str] = set()

    def line(self, path: str) -> int | None:
        if path.startswith("--set"):
            return None
        while path:
            if path in self.lines:
                return self.lines[path]
            parent = re.sub(r"(\.[^.\[\]]*|\[\d+\])$", "", path)
            path = "" if parent == path else parent
        return self.lines.get("")

    def fail(
        self, path: str, what: str, got: str | None = None, expected: str | None = None
    ) -> None:
        """Record a problem: ``what (got X; expected Y)`` when ``got`` is given."""
        message = what if got is None else _says(what, got, expected or "")
        self.problems.append(Problem(path, message, self.line(path)))

    def warn(self, path: str, message: str) -> None:
        self.warnings.append(Problem(path, message, self.line(path)))

    # -- structure
    def items(
        self, doc: Any, path: str, what: str
    ) -> Iterator[tuple[int, str, dict[Any, Any]]]:
        """Yield ``(index, path, mapping)`` for each mapping of a list of ``what``.

        ``None`` is an empty list; a non-list, or an item that is not a mapping, is a
        problem (and is skipped).
        """
        if doc is None:
            return
        if not isinstance(doc, list):
            self.fail(path, "not a list", _describe(doc), f"a list of {what}")
            return
        for i, item in enumerate(doc):
            sub = f"{path}[{i}]"
            m = self.mapping(item, sub)
            if m is not None:
                yield i, sub, m

    def mapping(self, value: Any, path: str) -> dict[Any, Any] | None:
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            self.fail(
                path,
                "not a mapping",
                _describe(value),
                "a mapping of keys (key: value)",
            )
            return None
        return dict(value)

    def keys(self, m: dict[Any, Any], allowed: tuple[str, ...], path: str) -> None:
        for key in m:
            if isinstance(key, str) and key in allowed:
                continue
            sub = f"{path}.{key}" if path else str(key)
            what = "unknown key" if isinstance(key, str) else "unknown key (not a name)"
            self.fail(
                sub,
                f"{what}{_hint(key, allowed)}",
                _describe(key),
                f"one of: {', '.join(allowed)}",
            )

    def get(
        self,
        m: dict[Any, Any],
        key: str,
        path: str,
        default: Any,
        expected: str = "a value",
    ) -> tuple[Any, str]:
        sub = f"{path}.{key}" if path else key
        if key not in m or (m[key] is None and default is not _REQUIRED):
            if default is _REQUIRED:
                self.fail(sub, "required key is missing", "nothing", expected)
            return default, sub
        return m[key], sub

    # -- scalars
    def number(
        self,
        m: dict[Any, Any],
        key: str,
        path: str,
        default: Any = _REQUIRED,
        *,
        positive: bool = False,
        minimum: float | None = None,
        length: bool = False,
    ) -> Any:
        kind = _number_kind(positive, minimum, length)
        value, sub = self.get(m, key, path, default, kind)
        if value is default:
            return None if default is _REQUIRED else default
        return self.check_number(
            value, sub, positive=positive, minimum=minimum, length=length
        )

    def check_number(
        self,
        value: Any,
        path: str,
        *,
        positive: bool = False,
        minimum: float | None = None,
        length: bool = False,
    ) -> float | None:
        kind = _number_kind(positive, minimum, length)
        shown = _describe(value)
        if length and isinstance(value, str):
            match = _LENGTH.match(value)
            if not match:
                self.fail(path, "not a length", shown, kind)
                return None
            value = float(match.group(1)) * self.diameter
            shown = f"{shown} = {value:g} m"
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(path, "not a number", shown, kind)
            return None
        if isinstance(value, int) and abs(value) > 1e300:
            self.fail(path, "number too large", shown, f"a finite {kind[2:]}")
            return None
        value = float(value)
        if not math.isfinite(value):
            self.fail(path, "not a finite number", shown, f"a finite {kind[2:]}")
            return None
        limit = MAX_LENGTH if length else MAX_NUMBER
        if abs(value) > limit:
            self.fail(
                path,
                "beyond the supported range",
                shown,
                f"{kind}, within +-{limit:g}{' m' if length else ''}",
            )
            return None
        if positive and value <= 0:
            self.fail(path, "must be greater than 0", shown, kind)
            return None
        if minimum is not None and value < minimum:
            self.fail(path, f"must be at least {minimum:g}", shown, kind)
            return None
        return value

    def integer(
        self,
        m: dict[Any, Any],
        key: str,
        path: str,
        default: Any,
        *,
        minimum: int,
        maximum: int,
    ) -> Any:
        kind = f"a whole number from {minimum} to {maximum}"
        value, sub = self.get(m, key, path, default, kind)
        if value is default:
            return default
        if isinstance(value, float) and value.is_integer():
            if abs(value) >= 2**53:
                self.fail(sub, "out of range", _describe(value), kind)
                return None
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(sub, "not a whole number", _describe(value), kind)
            return None
        if value < minimum or value > maximum:
            self.fail(sub, "out of range", _describe(value), kind)
            return None
        return value

    def boolean(self, m: dict[Any, Any], key: str, path: str, default: bool) -> bool:
        value, sub = self.get(m, key, path, default, "true or false")
        if not isinstance(value, bool):
            self.fail(sub, "not a boolean", _describe(value), "true or false")
            return default
        return value

    def string(self, m: dict[Any, Any], key: str, path: str, default: Any) -> Any:
        value, sub = self.get(m, key, path, default, "a non-empty string")
        if value is default:
            return default
        if not isinstance(value, str) or not value.strip():
            self.fail(
                sub, "not a non-empty string", _describe(value), "a non-empty string"
            )
            return None if default is _REQUIRED else default
        return value

    def name(
        self, m: dict[Any, Any], key: str, path: str, default: Any, *, run: bool = False
    ) -> Any:
        """A name that is written into CSV rows and file names: one plain line.

        With ``run``, the name is also a run directory's name: one path component.
        """
        value = self.string(m, key, path, default)
        if isinstance(value, str) and value is not default:
            why = name_problem(value, run=run)
            if why is not None:
                self.fail(
                    f"{path}.{key}" if path else key,
                    "unusable name",
                    f"{_describe(value)}, which {why}",
                    NAME_RULE + (" or ." if run else ""),
                )
                return None if default is _REQUIRED else default
        return value

    def choice(
        self,
        m: dict[Any, Any],
        key: str,
        path: str,
        default: Any,
        choices: tuple[str, ...],
        what: str = "value",
    ) -> Any:
        expected = f"one of: {', '.join(choices)}"
        value, sub = self.get(m, key, path, default, expected)
        if value is default:
            return default
        if not isinstance(value, str) or value not in choices:
            self.fail(
                sub,
                f"unknown {what}{_hint(value, choices)}",
                _describe(value),
                expected,
            )
            return None
        return value

    def vector(
        self,
        m: dict[Any, Any],
        key: str,
        path: str,
        size: int,
        default: Any = _REQUIRED,
        *,
        length: bool = False,
    ) -> Any:
        value, sub = self.get(m, key, path, default, _vector_kind(size, length))
        if value is default:
            return None if default is _REQUIRED else default
        return self.check_vector(value, sub, size, length=length)

    def check_vector(
        self, value: Any, path: str, size: int, *, length: bool = False
    ) -> tuple[float, ...] | None:
        if not isinstance(value, list | tuple) or len(value) != size:
            what = (
                "wrong number of items"
                if isinstance(value, list | tuple)
                else "not a list"
            )
            self.fail(path, what, _describe(value), _vector_kind(size, length))
            return None
        out = [
            self.check_number(v, f"{path}[{i}]", length=length)
            for i, v in enumerate(value)
        ]
        if any(v is None for v in out):
            return None
        return tuple(out)

    def points(
        self, m: dict[Any, Any], key: str, path: str, minimum: int
    ) -> tuple[tuple[float, float], ...] | None:
        kind = f"a list of at least {minimum} [x1, x2] points"
        value, sub = self.get(m, key, path, _REQUIRED, kind)
        if value is _REQUIRED:
            return None
        if not isinstance(value, list) or len(value) < minimum:
            what = "too few points" if isinstance(value, list) else "not a list"
            self.fail(sub, what, _describe(value), kind)
            return None
        pts = [
            self.check_vector(p, f"{sub}[{i}]", 2, length=True)
            for i, p in enumerate(value)
        ]
        if any(p is None for p in pts):
            return None
        return tuple(pts)


#: Characters no name may hold: CSV separators and quotes, path separators, control
#: characters (C0, DEL, C1 such as U+0085), line and paragraph separators,
#: bidirectional overrides and the byte-order mark (they split lines or rewrite what a
#: terminal shows).
_BAD_NAME = re.compile(
    "[,\"'/\\\\\x00-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069\ufeff]"
)
#: Control characters a description may not hold (all but tab and line feed).
_BAD_TEXT = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")
#: A leading character a spreadsheet reads as the start of a formula (CSV injection).
_FORMULA_START = ("=", "+", "-", "@")
NAME_RULE = (
    f"at most {MAX_NAME} characters on one line, without commas, quotes, slashes, "
    "backslashes or control characters, not starting with = + - @"
)


def name_problem(value: str, *, run: bool = False) -> str | None:
    """Why ``value`` cannot be a name, or None if it can.

    Names end up in CSV cells, on the terminal and (the scenario's name) as a directory
    name under ``runs/``, so they are single plain lines of at most :data:`MAX_NAME`
    characters. A leading ``=``, ``+``, ``-`` or ``@`` is refused (a spreadsheet opening
    ``trajectory.csv`` would run it as a formula), and so, for a run name, is a leading
    ``.`` (``.`` and ``..`` name a directory and its parent; other dot names are
    hidden).
    """
    bad = _BAD_NAME.search(value)
    if bad is not None:
        return f"holds the character {bad.group()!r}"
    if len(value) > MAX_NAME:
        return f"has {len(value)} characters"
    if value.startswith(_FORMULA_START):
        return f"starts with {value[0]!r}"
    if run and value.startswith("."):
        return "starts with '.'"
    if value != value.strip():
        return "starts or ends with a space"
    return None


def _vector_kind(size: int, length: bool) -> str:
    return f"a list of {size} {'lengths' if length else 'numbers'}"


# ----------------------------------------------------------------------------- sections
# Every key of the format is declared once, here or in the plug-in that uses it: the
# reader below, the JSON Schema (sandbox.schema) and the documentation checks of
# scenarios/reference.yaml (tests/test_reference_doc.py) are derived from these tables.
def _section(name: str) -> dict[str, Any]:
    return {"type": "custom", "default": None, "schema": {"$ref": f"#/$defs/{name}"}}


def _list_of(name: str) -> dict[str, Any]:
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
#: The schema of ``randomize:`` (read by :mod:`sandbox.randomize`).
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
        **_section("vehicleParams"),
        doc="Defaults for every vehicle (each vehicle may override them)",
    ),
    "reference": Param(
        **_section("reference"),
        doc="The reference trajectory tracked by the leader (or by every slot with "
        "law virtual)",
    ),
    "formation": Param(
        **_section("formation"),
        doc="The formation law; required with more than one vehicle",
    ),
    "vehicles": Param(**_list_of("vehicle"), doc="The listed vehicles"),
    "platoon": Param(
        **_section("platoon"),
        doc="Followers generated on a pattern, named <prefix>0, <prefix>1, ...",
    ),
    "recovery": Param(**_section("recovery"), doc="Collision avoidance, section 4"),
    "failures": Param(**_list_of("failure"), doc="Failures injected into vehicles"),
    "obstacles": Param(**_list_of("obstacle"), doc="Static obstacles"),
    "metrics": Param(**_section("metrics"), doc="Parameters of metrics.json"),
    "randomize": Param(
        "custom",
        None,
        doc="Random draws from the seed: field paths (the --set syntax, e.g. "
        "vehicles[1].pose) mapped to {uniform: [low, high]}, {normal: [mean, std]} "
        "(numbers or equal-length lists, elementwise) or {choice: [a, b, ...]}; "
        "overlapping starts are redrawn (see sandbox/randomize.py)",
        schema=_RANDOMIZE_SCHEMA,
    ),
}
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
        **_section("gains"),
        doc="Flatness controller gains, eqs. (4)-(6) (default: the report's)",
    ),
    "max_accel": Param(
        "number",
        None,
        "m/s^2",
        "Limit on |d chi / dt| (chi is clamped: no wind-up); default: unlimited",
        minimum=0.0,
        exclusive=True,
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
        minimum=0.0,
        exclusive=True,
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
        doc="Colour name or #rrggbb (default: blue, red, green, ... in order)",
    ),
    "drive": Param(
        **_section("drive"), doc="How the vehicle is driven (default: by its law)"
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
    "contact_release": Param(
        "number",
        0.01,
        "m",
        "Gap between two surfaces beyond which a contact episode ends (closer "
        "returns are the same collision)",
        minimum=0.0,
        exclusive=True,
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
#: The sections by kind of plug-in they select.
PLUGIN_SECTIONS: dict[str, dict[str, Param]] = {
    "law": FORMATION,
    "strategy": RECOVERY,
    "failure": FAILURE,
    "reference": REFERENCE,
    "obstacle": OBSTACLE,
}
for _kind, _own in PLUGIN_SECTIONS.items():
    plugins.reserve_section_keys(_kind, tuple(_own))

TOP_KEYS = tuple(TOP)
VEHICLE_PARAM_KEYS = tuple(VEHICLE_PARAMS)
VEHICLE_KEYS = (*VEHICLE, *VEHICLE_PARAMS)
GAIN_KEYS = tuple(GAINS)
PLATOON_KEYS = tuple(PLATOON)
DRIVE_KEYS = tuple(DRIVE)
METRICS_KEYS = tuple(METRICS)


def _length_default(rd: _Reader, value: Any) -> Any:
    """A default written ``"3d"`` resolved to metres with the default diameter."""
    if isinstance(value, str):
        match = _LENGTH.match(value)
        if match:
            return float(match.group(1)) * rd.diameter
    return value


def read_param(
    rd: _Reader, m: dict[Any, Any], key: str, path: str, p: Param
) -> tuple[Any, bool]:
    """Read one declared key: ``(value, ok)``; problems are recorded in ``rd``.

    A missing optional key gives its default (lengths like ``"3d"`` in metres); a
    missing required key, or a value of the wrong type or out of bounds, gives
    ``(None, False)``.
    """
    before = len(rd.problems)
    default = _REQUIRED if p.required else p.default
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
            kind = _number_kind(positive, minimum, t == "length")
            if p.exclusive and not positive and value <= p.minimum:
                rd.fail(sub, f"must be greater than {p.minimum:g}", f"{value:g}", kind)
            elif p.maximum is not None and value > p.maximum:
                rd.fail(sub, f"must be at most {p.maximum:g}", f"{value:g}", kind)
    elif t == "integer":
        lo = int(p.minimum) if p.minimum is not None else -(2**63)
        hi = int(p.maximum) if p.maximum is not None else MAX_SEED
        value = rd.integer(m, key, path, default, minimum=lo, maximum=hi)
        if value is _REQUIRED:
            value = None
    elif t == "boolean":
        value = rd.boolean(m, key, path, False if default is _REQUIRED else default)
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
                _describe(value),
                "a text",
            )
    elif t == "choice":
        value = rd.choice(m, key, path, default, p.choices, f"{key} value")
    elif t == "point":
        value = rd.vector(m, key, path, 2, default, length=True)
    elif t == "points":
        if key not in m or m[key] is None:
            if p.required:
                value = rd.points(m, key, path, p.min_items)
            else:
                value = default
        else:
            value = rd.points(m, key, path, p.min_items)
    else:
        raise ValueError(f"{path}.{key}: a {t} key is read by its section's code")
    if value is _REQUIRED:
        value = None
    return value, len(rd.problems) == before


def read_params(
    rd: _Reader, m: dict[Any, Any], path: str, params: dict[str, Param]
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


def read_plugin_section(
    rd: _Reader,
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
    name = rd.choice(m, info.selector, path, default, registered, info.title)
    own_values, ok = read_params(rd, m, path, own)
    everyone = plugins.all_params(kind)
    if name is None or name is _REQUIRED:
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
                    f"applies only to the {_and(users)} {info.title}"
                    f"{'s' if len(users) > 1 else ''}",
                    f"{key} with {info.selector} {name}",
                    f"no '{key}' ({info.title} {name} does not take it)",
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


def _vehicle_params(
    rd: _Reader, m: dict[Any, Any], path: str, base: dict[str, Any]
) -> dict:
    """Read the physical/controller parameters of ``vehicle:`` or of one vehicle.

    ``base`` holds the values used for keys left out (the shared ``vehicle:`` ones
    for a listed vehicle).
    """
    out = dict(base)
    for key, p in VEHICLE_PARAMS.items():
        if p.type != "custom":
            p = dataclasses.replace(p, default=base[key])
            out[key], _ = read_param(rd, m, key, path, p)
    gains_doc, gains_path = rd.get(m, "gains", path, None)
    gains = dict(base["gains"])
    if gains_doc is not None:
        g = rd.mapping(gains_doc, gains_path)
        if g is not None:
            rd.keys(g, GAIN_KEYS, gains_path)
            for key, p in GAINS.items():
                p = dataclasses.replace(p, default=gains[key])
                gains[key], _ = read_param(rd, g, key, gains_path, p)
    out["gains"] = gains
    return out


def _vehicle_defaults() -> dict[str, Any]:
    """The declared defaults of ``vehicle:``, gains included."""
    base = {k: p.default for k, p in VEHICLE_PARAMS.items() if p.type != "custom"}
    base["gains"] = {k: p.default for k, p in GAINS.items()}
    return base


def _reference(rd: _Reader, doc: Any, path: str) -> ReferenceSpec | None:
    m = rd.mapping(doc, path)
    if m is None:
        return None
    plugin, _, values, ok = read_plugin_section(rd, m, path, "reference")
    if plugin is None or not ok:
        return None
    return ReferenceSpec(plugin.name, values)


def _formation(rd: _Reader, doc: Any, path: str) -> FormationSpec | None:
    m = rd.mapping(doc, path)
    if m is None:
        return None
    plugin, _, values, ok = read_plugin_section(rd, m, path, "law")
    if plugin is None or not ok:
        return None
    return FormationSpec(plugin.name, values)


def _drive(rd: _Reader, doc: Any, path: str) -> DriveSpec | None:
    """The drive of one vehicle, or None if it has problems (they are recorded)."""
    before = len(rd.problems)
    drive = _read_drive(rd, doc, path)
    return drive if len(rd.problems) == before else None


def _read_drive(rd: _Reader, doc: Any, path: str) -> DriveSpec:
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
    rows, sub = rd.get(m, "schedule", path, _REQUIRED, kind_rows)
    if rows is _REQUIRED:
        return DriveSpec()
    if not isinstance(rows, list) or not rows:
        rd.fail(
            sub,
            "not a list of rows" if not isinstance(rows, list) else "no rows",
            _describe(rows),
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


def _vehicles(
    rd: _Reader, doc: Any, path: str, params: dict[str, Any]
) -> list[tuple[str, VehicleSpec]]:
    """The listed vehicles as ``(path, spec)``; every name also goes to ``rd.declared``.

    A vehicle with an invalid field is left out of the list, but its name and leader
    flag are still declared so that checks across sections (failures naming it, the
    number of leaders) do not report follow-on problems.
    """
    if doc is None:
        return []
    if not isinstance(doc, list):
        rd.fail(path, "not a list", _describe(doc), "a list of vehicles")
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
        raw, pose_path = rd.get(m, "pose", sub, _REQUIRED, kind)
        pose: Any = None
        if raw is not _REQUIRED:
            if not isinstance(raw, list | tuple) or len(raw) != 3:
                what = (
                    "wrong number of items"
                    if isinstance(raw, list | tuple)
                    else "not a list"
                )
                rd.fail(pose_path, what, _describe(raw), kind)
            else:
                pose = (
                    rd.check_number(raw[0], f"{pose_path}[0]", length=True),
                    rd.check_number(raw[1], f"{pose_path}[1]", length=True),
                    rd.check_number(raw[2], f"{pose_path}[2]"),
                )
        offset = rd.vector(m, "offset", sub, 2, (0.0, 0.0), length=True)
        color = rd.string(m, "color", sub, PALETTE[i % len(PALETTE)])
        drive: DriveSpec | None = DriveSpec()
        if m.get("drive") is not None:
            drive = _drive(rd, m["drive"], f"{sub}.drive")
        p = _vehicle_params(rd, m, sub, params)
        if pose is None or offset is None or None in pose or drive is None:
            continue
        if None in (p["diameter"], p["mass"]):
            continue
        if any(v is None for v in p["gains"].values()):
            continue
        out.append((sub, _make_vehicle(name, pose, offset, leader, color, drive, p)))
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


def _platoon_frame(
    formation: FormationSpec | None,
    leader: VehicleSpec | None,
    reference: ReferenceSpec | None,
) -> tuple[float, float, float, float]:
    """Where a platoon's slots are at t = 0, as its formation law defines them.

    Returns ``(x, y, angle, heading)``: the point the offsets are added to [m], the
    angle they are turned by [rad], and the heading the vehicles start with [rad]:

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
    law = formation.law if formation is not None else None
    rotate = formation is not None and formation.rotate
    if law == "virtual" and ref is not None:
        x, y, heading = float(ref[0][0]), float(ref[0][1]), tangent
        return x, y, tangent if rotate else 0.0, heading
    if law == "fixed":
        return x, y, 0.0, heading
    if law == "leader_ref":
        return x, y, tangent if rotate and ref is not None else 0.0, heading
    return x, y, heading, heading


def _expand_platoon(
    spec: PlatoonSpec,
    listed: list[VehicleSpec],
    params: dict[str, Any],
    seed: int,
    reference: ReferenceSpec | None,
    formation: FormationSpec | None = None,
) -> list[VehicleSpec]:
    """Create the platoon's vehicles, starting on their slots (jittered by ``seed``).

    The slots are those the formation law gives at t = 0 (see :func:`_platoon_frame`),
    so that an unjittered platoon starts in formation. The jitter is uniform in
    ``[-jitter, jitter]`` on each axis, drawn from ``numpy.random.default_rng(seed)``.
    """
    leader = next((v for v in listed if v.leader), None)
    x, y, angle, heading = _platoon_frame(formation, leader, reference)
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


def _recovery(rd: _Reader, doc: Any, path: str) -> RecoverySpec:
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
    )


def _failures(rd: _Reader, doc: Any, path: str) -> list[tuple[str, FailureSpec]]:
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


def _obstacles(rd: _Reader, doc: Any, path: str) -> list[tuple[str, ObstacleSpec]]:
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
                _describe(spec),
                f"an ObstacleSpec of type {', '.join(SHAPES)}",
            )
            continue
        if spec.name != name:
            spec = dataclasses.replace(spec, name=name)
        out.append((sub, spec))
    return out


# ------------------------------------------------------------------------- entry points
def parse_scenario(
    doc: Any,
    *,
    source: str | None = None,
    lines: dict[str, int] | None = None,
    overrides: list[str] | None = None,
    problems: list[Problem] | None = None,
) -> Scenario:
    """Validate a scenario document (as loaded from YAML); return a :class:`Scenario`.

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
    problems : list of Problem, optional
        Problems already found in the file (e.g. duplicate keys), reported together with
        those of the document.

    Raises
    ------
    ScenarioError
        With one :class:`~sandbox.errors.Problem` per problem found.
    """
    rd = _Reader(lines or {})
    rd.problems.extend(problems or [])
    first_line = (lines or {}).get("", 1) if lines is not None else None
    if doc is None:
        raise ScenarioError(
            [
                *rd.problems,
                Problem(
                    "",
                    _says("the file is empty", "nothing", "a mapping of scenario keys"),
                    first_line,
                ),
            ],
            source,
        )
    if not isinstance(doc, Mapping):
        raise ScenarioError(
            [
                *rd.problems,
                Problem(
                    "",
                    _says(
                        "the scenario is not a mapping",
                        _describe(doc),
                        "a mapping of scenario keys (name, duration, vehicles, ...)",
                    ),
                    first_line,
                ),
            ],
            source,
        )
    try:
        doc = copy.deepcopy(dict(doc))
    except RecursionError:
        raise ScenarioError(
            [
                *rd.problems,
                Problem(
                    "",
                    _says(
                        "the document is nested too deeply",
                        "hundreds of levels",
                        "a scenario a few levels deep",
                    ),
                    first_line,
                ),
            ],
            source,
        ) from None
    overridden = []
    for item in overrides or []:
        where = _apply_override(rd, doc, item)
        if where is not None:
            overridden.append((where, item))
            rd.overridden.add(where)
    loaded = _load_plugins(rd, doc.get("plugins"), source)
    if doc.get("randomize") is not None:  # draws into the document (randomize.py)
        doc, found = randomize.resolve(
            doc, skip=rd.overridden, line=rd.line, check=parse_scenario
        )
        rd.problems.extend(found)
    rd.keys(doc, TOP_KEYS, "")

    default_name = Path(source).stem if source else "scenario"
    if doc.get("name") is None and name_problem(default_name, run=True):
        rd.fail(
            "name",
            "the file name gives an unusable run name",
            f"{_describe(default_name)}, which {name_problem(default_name, run=True)}",
            f"a 'name:' key: {NAME_RULE} or .",
        )
        default_name = "scenario"
    name = rd.name(doc, "name", "", default_name, run=True) or default_name
    description = doc.get("description")
    description = "" if description is None else description
    if not isinstance(description, str):
        rd.fail("description", "not a string", _describe(description), "a text")
        description = ""
    elif bad := _BAD_TEXT.search(description):
        rd.fail(
            "description",
            f"holds the control character {bad.group()!r}",
            _describe(description),
            "plain text (line breaks and tabs allowed)",
        )
        description = ""
    duration = read_param(rd, doc, "duration", "", TOP["duration"])[0]
    dt = read_param(rd, doc, "dt", "", TOP["dt"])[0]
    substeps = read_param(rd, doc, "substeps", "", TOP["substeps"])[0]
    seed = read_param(rd, doc, "seed", "", TOP["seed"])[0]
    record_every = read_param(rd, doc, "record_every", "", TOP["record_every"])[0]

    vehicle_doc = rd.mapping(doc.get("vehicle"), "vehicle") or {}
    rd.keys(vehicle_doc, VEHICLE_PARAM_KEYS, "vehicle")
    base = _vehicle_defaults()
    params = _vehicle_params(rd, vehicle_doc, "vehicle", base)
    rd.diameter = params["diameter"] or 0.5
    # An invalid shared parameter is reported once; vehicles then use the default.
    params = {k: base[k] if v is None else v for k, v in params.items()}
    params["gains"] = {
        k: base["gains"][k] if v is None else v for k, v in params["gains"].items()
    }

    reference = None
    if doc.get("reference") is not None:
        reference = _reference(rd, doc["reference"], "reference")
    formation = None
    if doc.get("formation") is not None:
        formation = _formation(rd, doc["formation"], "formation")

    listed = _vehicles(rd, doc.get("vehicles"), "vehicles", params)
    platoon = None
    generated: list[tuple[str, VehicleSpec]] = []
    if doc.get("platoon") is not None:
        platoon = _platoon(rd, doc["platoon"], "platoon")
        if platoon is not None and seed is not None:
            if len(listed) + platoon.count > MAX_VEHICLES:
                rd.fail(
                    "platoon.count",
                    "too many vehicles",
                    f"{len(listed)} listed + {platoon.count} generated",
                    f"at most {MAX_VEHICLES} in all",
                )
            else:
                made = _expand_platoon(
                    platoon, [v for _, v in listed], params, seed, reference, formation
                )
                generated = [("platoon", v) for v in made]
    recovery = _recovery(rd, doc.get("recovery"), "recovery")
    failures = _failures(rd, doc.get("failures"), "failures")
    obstacles = _obstacles(rd, doc.get("obstacles"), "obstacles")
    mdoc = rd.mapping(doc.get("metrics"), "metrics") or {}
    rd.keys(mdoc, METRICS_KEYS, "metrics")
    read, _ = read_params(rd, mdoc, "metrics", METRICS)
    metrics = MetricsSpec(
        **{k: METRICS[k].default if v is None else v for k, v in read.items()}
    )

    _check_consistency(
        rd,
        doc,
        duration,
        dt,
        record_every,
        listed + generated,
        reference,
        formation,
        failures,
        obstacles,
        platoon,
        recovery,
    )
    if rd.problems:
        found = _mark_overrides(rd.problems, overridden)
        raise ScenarioError(
            sorted(found, key=lambda p: (p.line is None, p.line or 0)), source
        )
    vehicles = [v for _, v in listed + generated]
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
        failures=tuple(f for _, f in failures),
        obstacles=tuple(o for _, o in obstacles),
        platoon=platoon,
        metrics=metrics,
        diameter=rd.diameter,
        source=source,
        plugins=tuple(loaded),
        warnings=tuple(
            w.format(source) for w in _mark_overrides(rd.warnings, overridden)
        ),
    )


def _load_plugins(rd: _Reader, listed: Any, source: str | None) -> list[str]:
    """Import the plug-ins a scenario lists; return them as they reload from anywhere.

    Files are relative to the scenario's directory and returned as absolute paths;
    module names are returned as they are. A plug-in that fails is a problem of its
    ``plugins[i]`` entry.
    """
    if listed is None:
        return []
    if not isinstance(listed, list):
        listed = [listed] if isinstance(listed, str) else listed
        if not isinstance(listed, list):
            rd.fail(
                "plugins",
                "not a list",
                _describe(listed),
                "a list of plug-in files (.py) or module names",
            )
            return []
    base = Path(source).resolve().parent if source else None
    out = []
    try:
        plugins.load_entry_points()
    except PluginError as exc:
        rd.fail("plugins", str(exc), "a broken entry point", "plug-ins that import")
    for i, spec in enumerate(listed):
        where = f"plugins[{i}]"
        if not isinstance(spec, str) or not spec.strip():
            rd.fail(
                where, "not a plug-in name", _describe(spec), "a .py file or a module"
            )
            continue
        try:
            plugins.load_plugin(spec, base)
        except PluginError as exc:
            rd.fail(
                where, "plug-in cannot be loaded", str(exc), "a plug-in that imports"
            )
            continue
        if plugins.looks_like_file(spec):
            out.append(str(plugins.resolve_file(spec, base)))
        else:
            out.append(spec.strip())
    return out


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


def _check_consistency(
    rd: _Reader,
    doc: dict[Any, Any],
    duration: float | None,
    dt: float | None,
    record_every: int | None,
    vehicles: list[tuple[str, VehicleSpec]],
    reference: ReferenceSpec | None,
    formation: FormationSpec | None,
    failures: list[tuple[str, FailureSpec]],
    obstacles: list[tuple[str, ObstacleSpec]],
    platoon: PlatoonSpec | None,
    recovery: RecoverySpec | None = None,
) -> None:
    """Checks that involve several sections.

    They run even when some sections have problems, on what is valid: a field that
    could not be read is skipped here (its own problem is already reported), so every
    problem of a file is reported at once without follow-on noise.
    """
    declared = list(rd.declared)
    if platoon is not None:
        declared += [
            ("platoon", f"{platoon.prefix}{i}", False) for i in range(platoon.count)
        ]
    if (
        not declared
        and doc.get("platoon") is None
        and doc.get("vehicles") in (None, [])
    ):
        rd.fail(
            "vehicles",
            "required key is missing (no vehicles)",
            _describe(doc.get("vehicles")),
            "a 'vehicles' list with at least one vehicle, or a 'platoon'",
        )
    if duration is not None and dt is not None:
        if dt >= duration:
            rd.fail(
                "dt",
                "must be shorter than the duration",
                f"dt = {dt:g} s, duration = {duration:g} s",
                "dt < duration",
            )
        elif duration / dt > MAX_STEPS:
            rd.fail(
                "dt",
                "too many control steps",
                f"duration / dt = {duration / dt:.3g} steps",
                f"at most {MAX_STEPS:g} steps: a longer dt or a shorter duration",
            )
        elif record_every is not None:
            samples = duration / dt // record_every + 1
            size = samples * max(len(declared), 1) * _BYTES_PER_SAMPLE
            if size > MAX_RECORD_BYTES:
                rd.fail(
                    "duration",
                    "the run would not fit in memory",
                    f"{samples:.3g} recorded samples of {len(declared)} vehicles, "
                    f"about {size / 1e9:.3g} GB",
                    f"at most {MAX_RECORD_BYTES / 1e9:g} GB: a shorter duration, a "
                    "longer dt or a larger record_every",
                )
    if dt is not None:
        _check_gains(rd, doc, dt, vehicles)

    names: dict[str, str] = {}
    for where, name, _ in declared:
        if name in names:
            if where == "platoon":
                rd.fail(
                    "platoon.prefix",
                    "generated names clash with listed vehicles",
                    f"{name!r} (also {names[name]})",
                    "a prefix no listed name uses",
                )
                break
            rd.fail(
                f"{where}.name",
                "duplicate vehicle name",
                f"{name!r} (also {names[name]})",
                "unique names",
            )
        names.setdefault(name, where)
    leaders = [(where, name) for where, name, leader in declared if leader]
    if len(leaders) > 1:
        rd.fail(
            f"{leaders[1][0]}.leader",
            "two leaders",
            f"{leaders[0][1]} and {leaders[1][1]}",
            "at most one vehicle with leader: true",
        )
    law = formation.law if formation else None
    if doc.get("formation") is None and len(declared) > 1:
        rd.fail(
            "formation",
            "required key is missing (several vehicles need a formation law)",
            "nothing",
            f"formation: {{law: one of {', '.join(plugins.names('law'))}}}",
        )
    law_options = plugins.get("law", law).options if law is not None else {}
    if law is not None and law_options["needs_leader"] and not leaders:
        rd.fail(
            "vehicles",
            f"the {law} law needs a leader",
            "no vehicle with leader: true",
            "exactly one vehicle with leader: true",
        )
    needs_ref = []
    for where, v in vehicles:
        tracks = v.drive.type == "reference"
        if tracks and (len(declared) == 1 or v.leader or law == "virtual"):
            needs_ref.append((where, v))
    needed = needs_ref or (law is not None and law_options["needs_reference"])
    if needed and doc.get("reference") is None:
        who = f"vehicle {needs_ref[0][1].name}" if needs_ref else f"the {law} law"
        rd.fail(
            "reference",
            f"required key is missing ({who} tracks the reference)",
            "nothing",
            "a reference trajectory, or drive: {type: commands, schedule: "
            "...} for the leader",
        )
    _check_geometry(rd, vehicles, law, recovery)
    _check_obstacle_starts(rd, vehicles, obstacles)
    for where, vehicle, at in rd.timed:
        if vehicle is not None and vehicle not in names:
            rd.fail(
                f"{where}.vehicle",
                f"no such vehicle{_hint(vehicle, tuple(names))}",
                repr(vehicle),
                f"one of: {', '.join(list(names)[:10])}"
                + (", ..." if len(names) > 10 else ""),
            )
        if duration is not None and at is not None and at >= duration:
            if "duration" in rd.overridden:
                rd.warn(
                    f"{where}.at",
                    f"failure at {at:g} s never starts: the run was "
                    f"shortened to {duration:g} s",
                )
                continue
            rd.fail(
                f"{where}.at",
                "timed outside the run",
                f"at = {at:g} s",
                f"a time before the end of the run, duration = {duration:g} s",
            )
    seen: dict[str, str] = {}
    for where, o in obstacles:
        if o.name in names or o.name in seen:
            rd.fail(
                f"{where}.name",
                "duplicate name",
                f"{o.name!r} (also {names.get(o.name) or seen.get(o.name)})",
                "names unique among vehicles and obstacles",
            )
        seen.setdefault(o.name, where)


def _gains_path(doc: dict[Any, Any], where: str) -> str:
    """Where a vehicle's gains were set: its own ``gains``, else ``vehicle.gains``."""
    if where.startswith("vehicles["):
        index = int(where[len("vehicles[") : -1])
        item = doc["vehicles"][index]
        if isinstance(item, Mapping) and item.get("gains") is not None:
            return f"{where}.gains"
    shared = doc.get("vehicle")
    if isinstance(shared, Mapping) and shared.get("gains") is not None:
        return "vehicle.gains"
    return ""


def _check_gains(
    rd: _Reader, doc: dict[Any, Any], dt: float, vehicles: list[tuple[str, VehicleSpec]]
) -> None:
    """Check that the discrete update of eq. (6) is stable with the gains and period.

    The loop advances chi by forward Euler once per period ``dt`` and the vehicle moves
    with the chi of the period's start, so the tracking error obeys ``e+ = e + dt c``,
    ``c+ = c + dt (k_pos e + k_vel c)``: its poles are ``z = 1 + dt s`` for the poles
    ``s`` of ``s^2 - k_vel s - k_pos``. The bound is
    :func:`~sandbox.control.flatness.max_control_period` (``|z| < 1`` and ``Re z > 0``;
    0.1 s for the report's gains). Gains unstable for every period are a warning (a
    deliberate experiment); stable gains with too long a period are an error. The
    heading loop ``e3+ = (1 - dt kp) e3`` needs ``dt kp < 2``.
    """
    checked: set[tuple[Any, ...]] = set()
    for where, v in vehicles:
        if v.drive.type != "reference":
            continue
        g = v.gains
        gains_path = _gains_path(doc, where)
        key = (g.k1, g.k2, g.k3, g.k4, g.kp, gains_path)
        if key in checked:
            continue
        checked.add(key)
        here = gains_path or "vehicle"
        who = v.name if gains_path.startswith("vehicles[") else "the vehicles"
        dt_path = "dt" if doc.get("dt") is not None else (gains_path or "dt")
        axes = [("1", g.k1, g.k2), ("2", g.k3, g.k4)]
        if (g.k1, g.k2) == (g.k3, g.k4):
            axes = axes[:1]
        for axis, k_pos, k_vel in axes:
            names = f"k{2 * int(axis) - 1} = {k_pos:g}, k{2 * int(axis)} = {k_vel:g}"
            if len(axes) == 1:
                names = f"k1 = k3 = {k_pos:g}, k2 = k4 = {k_vel:g}"
            bound = max_control_period(k_pos, k_vel)
            poles = error_poles(k_pos, k_vel)
            shown = ", ".join(_pole_text(s) for s in poles)
            if bound == 0.0:
                rd.warn(
                    here,
                    f"gains {names} of {who} do not stabilise eq. (6) for "
                    f"any control period: the error poles s = {shown} [1/s] (roots "
                    "of s^2 - k_vel s - k_pos) need k_pos < 0 and k_vel < 0, the "
                    "report's sign convention; expect the run to diverge",
                )
                continue
            if dt >= bound:
                z = 1.0 + dt * poles
                got_z = ", ".join(_pole_text(complex(v)) for v in z)
                rd.fail(
                    dt_path,
                    f"control period too long for the gains of {who} "
                    f"({names}): eq. (6) is advanced by forward Euler once per "
                    f"period, so its error poles s = {shown} [1/s] become "
                    "z = 1 + dt s; the loop needs |z| < 1 and, because a unicycle "
                    "cannot back up (v1 = |chi| >= 0) and so cannot follow a chi "
                    "that reverses every period, Re z > 0: dt < min(-2 Re s / "
                    f"|s|^2, 1 / max|Re s|) = {bound:.4g} s",
                    f"dt = {dt:g} s, z = {got_z}",
                    f"dt < {bound:.4g} s, and well below it; the report uses 0.01 s",
                )
                return
        if g.kp <= 0:
            rd.warn(
                here,
                f"kp = {g.kp:g} of {who} does not turn the vehicle toward chi "
                "(eq. (5) needs kp > 0): its heading error will not decay",
            )
        elif dt * g.kp >= 2.0:
            rd.fail(
                dt_path,
                f"control period too long for kp = {g.kp:g} of {who}: the "
                "heading error of eq. (5) evolves as e3+ = (1 - dt kp) e3, stable only "
                "while dt kp < 2",
                f"dt = {dt:g} s, dt kp = {dt * g.kp:.3g}",
                f"dt < {2.0 / g.kp:.4g} s",
            )
            return


def _pole_text(s: complex) -> str:
    if abs(s.imag) < 1e-12:
        return f"{s.real:.4g}"
    return f"{s.real:.4g}{s.imag:+.4g}j"


def _overlapping_pairs(
    pos: np.ndarray, rad: np.ndarray, limit: int
) -> Iterator[tuple[int, int, float]]:
    """Yield up to ``limit`` pairs ``(a, b, distance)`` of discs that overlap.

    Discs overlap when their centres are closer than the sum of their radii. The work
    is near-linear in the number of discs however many overlap: discs are grouped by
    radius in octaves, and each disc of a group looks for overlaps in each group of
    radii at least as large, within the sum of its radius and that group's largest. In
    that neighbourhood at most about 36 discs of the larger group fit without
    overlapping each other, so a query that returns more candidates holds an
    overlapping pair among its first 37, which is reported instead of reading on.
    """
    if len(pos) < 2:
        return
    octave = np.floor(np.log2(rad)).astype(int)
    groups = [np.flatnonzero(octave == o) for o in np.unique(octave)]
    trees = [cKDTree(pos[g]) for g in groups]
    reported: set[tuple[int, int]] = set()

    def overlap(a: int, b: int) -> float | None:
        if a == b or (min(a, b), max(a, b)) in reported:
            return None
        dist = float(np.hypot(*(pos[a] - pos[b])))
        if dist < rad[a] + rad[b] - 1e-9:
            reported.add((min(a, b), max(a, b)))
            return dist
        return None

    for gi, small in enumerate(groups):
        for gj in range(gi, len(groups)):
            big, tree = groups[gj], trees[gj]
            reach = float(rad[big].max())
            for a in small:
                found = tree.query_ball_point(pos[a], rad[a] + reach)
                found = [int(big[k]) for k in found[:37]]
                if len(found) == 37:
                    pairs = [(a, b) for b in found]
                    pairs += [(c, b) for i, c in enumerate(found) for b in found[i:]]
                else:
                    pairs = [(a, b) for b in found]
                for c, b in pairs:
                    dist = overlap(c, b)
                    if dist is not None:
                        yield (min(c, b), max(c, b), dist)
                        limit -= 1
                        if limit <= 0:
                            return


def _check_geometry(
    rd: _Reader,
    vehicles: list[tuple[str, VehicleSpec]],
    law: str | None,
    recovery: RecoverySpec | None = None,
) -> None:
    """Report vehicles that start overlapping, warn of slots too close together.

    Slots closer than a diameter cannot both be reached; with a recovery strategy on,
    slots closer than its radius R keep avoidance active for good, so the formation
    never settles (report section 3.3: avoidance acts inside R).
    """
    if len(vehicles) < 2:
        return
    pos = np.array([v.pose[:2] for _, v in vehicles])
    rad = np.array([v.diameter / 2 for _, v in vehicles])
    for shown, (a, b, dist) in enumerate(_overlapping_pairs(pos, rad, 6)):
        if shown == 5:
            rd.fail(
                f"{vehicles[b][0]}.pose",
                "more vehicles start overlapping",
                "more than 5 overlapping pairs",
                "no overlap (first 5 shown)",
            )
            break
        where, vb = vehicles[b]
        path = f"{where}.pose" if where != "platoon" else "platoon.spacing"
        rd.fail(
            path,
            f"{vb.name} starts overlapping {vehicles[a][1].name}",
            f"centres {dist:.3g} m apart",
            f"at least {rad[a] + rad[b]:g} m, the sum of their radii",
        )
    if law is None:
        return
    # Slots of the vehicles a law drives; a leader the law follows sits at the origin
    # of the formation frame, whatever its offset.
    slotted = [i for i, (_, v) in enumerate(vehicles) if v.drive.type == "reference"]
    if len(slotted) < 2:
        return
    vehicles = [vehicles[i] for i in slotted]
    rad = rad[slotted]
    off = np.array([v.offset for _, v in vehicles], dtype=float)
    leads = np.array([v.leader for _, v in vehicles])
    if plugins.get("law", law).options["needs_leader"]:
        off[leads] = 0.0
    idx = np.flatnonzero(~leads)
    close = set()
    for a, b, gap in _overlapping_pairs(off[idx], rad[idx], 3):
        a, b = int(idx[a]), int(idx[b])
        close.add((a, b))
        where = vehicles[b][0]
        rd.warn(
            f"{where}.offset" if where != "platoon" else "platoon.spacing",
            f"slots of {vehicles[a][1].name} and {vehicles[b][1].name} are "
            f"{gap:.3g} m apart, closer than a diameter: they cannot both reach "
            "them",
        )
    if recovery is None or recovery.strategy == "none":
        return
    # The leader's slot is its own offset (the origin of the formation frame).
    half = np.full(len(vehicles), recovery.R / 2.0)
    shown = 0
    for a, b, gap in _overlapping_pairs(off, half, 6):
        if (a, b) in close:
            continue
        shown += 1
        if shown > 3:
            break
        where = vehicles[b][0]
        rd.warn(
            f"{where}.offset" if where != "platoon" else "platoon.spacing",
            f"slots of {vehicles[a][1].name} and {vehicles[b][1].name} are "
            f"{gap:.3g} m apart, within recovery.R = {recovery.R:g} m: avoidance "
            f"({recovery.strategy}) stays active between them and the formation "
            f"never settles (slots at least R apart, or a smaller R)",
        )


def _distance_to_obstacle(o: ObstacleSpec, p: np.ndarray) -> np.ndarray:
    """Distance [m] from points ``p`` (k, 2) to an obstacle's shape; 0 inside it.

    Circles and walls are measured as pymunk builds them (a wall is a segment with
    rounded ends, radius half its thickness); boxes and polygons by their outline.
    """
    if o.type == "circle":
        return np.maximum(np.hypot(*(p - np.asarray(o.center)).T) - o.radius, 0.0)
    if o.type == "wall":
        a, b = np.asarray(o.start), np.asarray(o.end)
        ab = b - a
        t = np.clip((p - a) @ ab / float(ab @ ab), 0.0, 1.0)
        near = a + t[:, None] * ab
        return np.maximum(np.hypot(*(p - near).T) - o.thickness / 2.0, 0.0)
    poly = np.asarray(o.outline(), dtype=float)
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a  # (m, 2)
    ap = p[:, None, :] - a[None]  # (k, m, 2)
    t = np.clip(np.einsum("kmi,mi->km", ap, ab) / np.einsum("mi,mi->m", ab, ab), 0, 1)
    edge = np.hypot(*(ap - t[..., None] * ab[None]).transpose(2, 0, 1)).min(axis=1)
    cross = ab[None, :, 0] * ap[..., 1] - ab[None, :, 1] * ap[..., 0]
    inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    return np.where(inside, 0.0, edge)


def _check_obstacle_starts(
    rd: _Reader,
    vehicles: list[tuple[str, VehicleSpec]],
    obstacles: list[tuple[str, ObstacleSpec]],
) -> None:
    """Report vehicles that start inside or touching into an obstacle (first 5).

    Only the vehicles near each obstacle's bounding circle are measured, found with a
    k-d tree, and the search stops at the fifth problem.
    """
    if not vehicles or not obstacles:
        return
    pos = np.array([v.pose[:2] for _, v in vehicles])
    rad = np.array([v.diameter / 2 for _, v in vehicles])
    tree = cKDTree(pos)
    shown = 0
    for where, o in obstacles:
        if o.type == "circle":
            centre, bound = np.asarray(o.center), o.radius
        elif o.type == "wall":
            a, b = np.asarray(o.start), np.asarray(o.end)
            centre = (a + b) / 2
            bound = float(np.hypot(*(b - a))) / 2 + o.thickness / 2
        else:
            pts = np.asarray(o.outline(), dtype=float)
            centre = pts.mean(axis=0)
            bound = float(np.hypot(*(pts - centre).T).max())
        near = np.array(tree.query_ball_point(centre, bound + rad.max()), dtype=int)
        for lo in range(0, len(near), 4096):
            chunk = near[lo : lo + 4096]
            gap = _distance_to_obstacle(o, pos[chunk])
            for k in np.flatnonzero(gap < rad[chunk] - 1e-9):
                i = int(chunk[k])
                shown += 1
                if shown > 5:
                    rd.fail(
                        f"{where}",
                        "more vehicles start overlapping obstacles",
                        "more than 5",
                        "vehicles clear of every obstacle (first 5 shown)",
                    )
                    return
                vw, v = vehicles[i]
                got = (
                    f"its centre {gap[k]:.3g} m from it, radius {rad[i]:g} m"
                    if gap[k] > 0
                    else "its centre inside it"
                )
                rd.fail(
                    f"{vw}.pose" if vw != "platoon" else "platoon",
                    f"{v.name} starts overlapping obstacle {o.name} "
                    f"({o.type}, {where})",
                    got,
                    "a start clear of every obstacle",
                )


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
    head = names[-1]
    if head == "gains":
        return GAIN_KEYS
    table: dict[str, tuple[str, ...]] = {
        "vehicle": VEHICLE_PARAM_KEYS,
        "vehicles": VEHICLE_KEYS,
        "platoon": PLATOON_KEYS,
        "metrics": METRICS_KEYS,
        "drive": DRIVE_KEYS,
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


_YAML_HINTS = (
    ("'\\t'", "indentation with spaces (YAML does not allow tabs)"),
    ("mapping values are not allowed", "one 'key: value' per line, a space after ':'"),
    ("could not find expected ':'", "'key: value' pairs"),
    ("expected a single document", "one document (no second '---')"),
    ("constructor for the tag", "plain YAML without custom tags"),
    ("unhashable key", "keys that are plain names"),
    ("unacceptable character", "a text file"),
)


def _yaml_problem(exc: yaml.YAMLError, text: str) -> Problem:
    """One problem for a YAML syntax error, with its line and the text found there."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    context = getattr(exc, "context", None)
    if context:
        what = f"{context}, {what}"
    if isinstance(exc, yaml.reader.ReaderError):
        line = text.count("\n", 0, exc.position) + 1
        char = exc.character
        code = char if isinstance(char, int) else ord(char)
        got, what = f"character {code:#x} at line {line}", "not text"
    elif mark is not None:
        line = mark.line + 1
        rows = text.splitlines()
        row = rows[mark.line] if mark.line < len(rows) else ""
        if "\t" in row[: len(row) - len(row.lstrip())]:
            what += " (a tab, '\\t', in the indentation)"
        got = (
            f"{row.strip()[:40]!r} at column {mark.column + 1}"
            if row.strip()
            else (f"the end of the file at column {mark.column + 1}")
        )
    else:
        line, got = None, "text that is not YAML"
    expected = next(
        (hint for key, hint in _YAML_HINTS if key in what), "well-formed YAML"
    )
    return Problem("", _says(f"malformed YAML: {what}", got, expected), line)


class _NotAFile(OSError):
    """A scenario path that is not a regular file of a readable size."""


def _read_limited(path: Path) -> bytes:
    """The bytes of a regular file of at most :data:`MAX_FILE_BYTES` bytes.

    Devices, pipes and sockets are refused before they are opened (opening a pipe
    could block, reading /dev/zero would never end), and at most one byte beyond the
    limit is read, so a file that grows while it is read is refused too.
    """
    mode = path.stat().st_mode
    if stat.S_ISDIR(mode):
        raise IsADirectoryError(path)
    if not stat.S_ISREG(mode):
        raise _NotAFile("not a regular file (a device, pipe or socket)")
    too_big = f"larger than {MAX_FILE_BYTES // 1_000_000} MB"
    if path.stat().st_size > MAX_FILE_BYTES:
        raise _NotAFile(f"{path.stat().st_size:,} bytes, {too_big}")
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            raise _NotAFile("not a regular file (a device, pipe or socket)")
        data = f.read(MAX_FILE_BYTES + 1)
    if len(data) > MAX_FILE_BYTES:
        raise _NotAFile(f"more than {MAX_FILE_BYTES:,} bytes, {too_big}")
    return data


def _long_integer_problem(node: yaml.Node | None, exc: ValueError) -> Problem:
    """The problem of a value YAML cannot construct, like an over-long integer."""
    stack, seen = [node], set()
    while stack:
        n = stack.pop()
        if n is None or id(n) in seen:
            continue
        seen.add(id(n))
        if isinstance(n, yaml.ScalarNode):
            if n.tag.endswith(":int") and len(n.value) > 4000:
                return Problem(
                    "",
                    _says(
                        "number too large",
                        "an integer of more than 4000 digits",
                        f"a number within +-{MAX_NUMBER:g}",
                    ),
                    n.start_mark.line + 1,
                )
        elif isinstance(n, yaml.MappingNode):
            stack.extend(v for kv in n.value for v in kv)
        elif isinstance(n, yaml.SequenceNode):
            stack.extend(n.value)
    return Problem(
        "",
        _says(
            "a value YAML cannot read", _describe(str(exc)), "valid numbers and dates"
        ),
        None,
    )


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
        The file cannot be read or parsed, or the document is invalid. Never any other
        exception for any file content.
    """
    if isinstance(source, Mapping):
        return parse_scenario(source, overrides=overrides)
    path = Path(source)
    name = str(source)
    expected = "a readable YAML scenario file"
    try:
        data = _read_limited(path)
    except _NotAFile as exc:
        raise ScenarioError(
            [Problem("", _says("cannot read the scenario", str(exc), expected))],
            name,
        ) from None
    except FileNotFoundError:
        raise ScenarioError(
            [Problem("", _says("cannot read the scenario", "no such file", expected))],
            name,
        ) from None
    except IsADirectoryError:
        raise ScenarioError(
            [Problem("", _says("cannot read the scenario", "a directory", expected))],
            name,
        ) from None
    except OSError as exc:
        raise ScenarioError(
            [
                Problem(
                    "",
                    _says(
                        "cannot read the scenario", exc.strerror or str(exc), expected
                    ),
                )
            ],
            name,
        ) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ScenarioError(
            [
                Problem(
                    "",
                    _says(
                        "not UTF-8 text",
                        f"byte {data[exc.start]:#04x} at offset {exc.start}",
                        "a UTF-8 encoded YAML file",
                    ),
                    line,
                )
            ],
            name,
        ) from None
    try:
        loader = _YAMLLoader(text)
        node = None
        try:
            node = loader.get_single_node()
            # Lines and duplicate keys come from the nodes as written: constructing
            # the document expands merge keys (<<: *anchor) into the nodes in place.
            lines: dict[str, int] = {}
            _line_map(node, "", lines)
            duplicates = _duplicate_keys(node)
            doc = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except ValueError as exc:  # an integer beyond Python's digit limit
        raise ScenarioError([_long_integer_problem(node, exc)], name) from None
    except yaml.YAMLError as exc:
        raise ScenarioError([_yaml_problem(exc, text)], name) from None
    except RecursionError:
        raise ScenarioError(
            [
                Problem(
                    "",
                    _says(
                        "the document is nested too deeply",
                        "hundreds of levels",
                        "a scenario a few levels deep",
                    ),
                    1,
                )
            ],
            name,
        ) from None
    return parse_scenario(
        doc, source=name, lines=lines, overrides=overrides, problems=duplicates
    )
