"""The validated scenario: frozen dataclasses built by the loader only.

A :class:`Scenario` is made by :func:`~sandbox.scenario.load_scenario` or
:func:`~sandbox.scenario.parse_scenario`; one made any other way (its constructor,
``dataclasses.replace``) is validated by the same loader in ``__post_init__``, and
:meth:`Scenario.with_overrides` changes one through it. :meth:`Scenario.to_dict` is the
document that parses back to the same scenario.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field, fields, is_dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox import plugins
from sandbox.errors import Problem, ScenarioError
from sandbox.model.flatness import (
    Gains,
)
from sandbox.model.obstacles import ObstacleSpec
from sandbox.plugins.registration import (
    ReferenceContext,
)

if TYPE_CHECKING:
    from sandbox.scenario.expectations import Expectations

PLATOON_PATTERNS = ("grid", "line", "wedge", "ring")

DRIVE_TYPES = ("reference", "commands")

#: The sections an entry of ``platoons:`` replaces whole (its ``vehicle`` is merged
#: key by key over the top level's); the keys of an entry are declared in
#: :mod:`sandbox.scenario.platoons` (``PLATOONS``: these, ``name``, ``color`` and
#: ``vehicle``).
ENTRY_SECTIONS = (
    "vehicles",
    "platoon",
    "reference",
    "formation",
    "recovery",
    "safety",
    "reconfigure",
    "on_leader_failure",
)

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


@dataclass(frozen=True)
class DriveSpec:
    """How a vehicle is driven: by its law (``reference``) or by a command schedule.

    ``schedule`` rows are ``(t [s], v1 [m/s], v2 [rad/s])``, held from ``t`` until the
    next row (zero before the first row).
    """

    type: str = "reference"
    schedule: tuple[tuple[float, float, float], ...] = ()


@dataclass(frozen=True)
class RangeSpec:
    """A planar range sensor (``sensors.range``): a LiDAR of ``beams`` beams.

    ``beams`` beams spread over the field of view ``fov`` [rad] about the heading,
    from ``-fov/2`` (right) to ``+fov/2`` (left) (a full turn: ``2 pi / beams``
    apart, from ``-pi``); each reaches ``max_range`` [m] from the vehicle's centre;
    ``noise`` [m] is the standard deviation of the Gaussian noise on each range;
    ``rate`` [Hz] the scan rate (None: a scan every control period); ``memory``
    [s] how long recovery from sensed obstacles keeps one no longer seen.
    """

    beams: int = 32
    fov: float = 2.0 * math.pi
    max_range: float = 5.0
    noise: float = 0.0
    rate: float | None = None
    memory: float = 0.0


@dataclass(frozen=True)
class SensorsSpec:
    """The sensors of a vehicle (``sensors:``): ``range``, or None for none."""

    range: RangeSpec | None = None


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
    #: Its own ``sensors:`` (the fleet's, ``Scenario.sensors``, merged in); None:
    #: the fleet's.
    sensors: SensorsSpec | None = None


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
            return plugins.runnable(plugin)(**self.params)
        return FunctionReference(plugins.runnable(plugin), dict(self.params))


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
    #: Where the static obstacles come from: ``map`` (the scenario's) or ``sensed``
    #: (the range sensor's hits, :mod:`sandbox.behaviour.ranges`).
    obstacles: str = "map"

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
class PlatoonGroup:
    """One platoon of a world of several (an entry of ``platoons:``).

    Attributes
    ----------
    name, color : str
        The platoon's name (in ``metrics.json`` and the legends) and colour.
    rows : tuple of int
        The indices of its vehicles in the scenario's vehicle order.
    scenario : Scenario
        The platoon alone: its vehicles, reference, formation, recovery, safety,
        reconfiguration and leader-failure rule, the top-level sections filling in
        what the entry does not give.
    """

    name: str
    color: str
    rows: tuple[int, ...]
    scenario: Scenario

    @property
    def leader(self) -> int:
        """The fleet index of the platoon's leader, or -1."""
        lead = self.scenario.leader_index
        return self.rows[lead] if lead >= 0 else -1


@dataclass(frozen=True)
class MetricsSpec:
    """Parameters of the metrics (``metrics.json``).

    ``settle_tol`` [m]: formation error of a settled vehicle; ``settle_dwell`` [s]: how
    long the run must go on in band after the settling time; ``settle_speed`` [m/s]:
    largest drift relative to the slot over the run's last ``settle_dwell`` of a
    settled vehicle; ``contact_release`` [m]: gap between two surfaces that ends a
    contact episode; ``deadlock_speed`` [m/s], ``deadlock_time`` [s],
    ``deadlock_distance`` [m], ``deadlock_progress``: a healthy vehicle farther than
    ``deadlock_distance`` from its slot is in a deadlock when it stays slower than
    ``deadlock_speed`` for ``deadlock_time``, or comes nearer to its slot by less than
    ``deadlock_progress`` times ``deadlock_distance`` over ``deadlock_time``
    (``deadlock_creeping``: ``to_end``, only when that lasts to the end of the run, or
    ``any``) (:mod:`sandbox.run.deadlock`).
    """

    settle_tol: float = 0.05
    settle_dwell: float = 1.0
    settle_speed: float = 0.02
    contact_release: float = 0.01
    deadlock_speed: float = 0.01
    deadlock_time: float = 2.0
    deadlock_distance: float = 0.5
    deadlock_progress: float = 0.5
    deadlock_creeping: str = "to_end"


@dataclass(frozen=True)
class DetectionSpec:
    """How the platoon learns of failures (``detection:``).

    ``method``: the registered detector (``oracle``: the truth at once, the default;
    ``residual``: a CUSUM on the residual of the observed motion against the
    broadcast commands); ``params``: its YAML values.
    """

    method: str = "oracle"
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SensingSpec:
    """What the vehicles see of each other (``sensing:``).

    ``position_noise`` [m] and ``heading_noise`` [rad]: standard deviations of the
    broadcast noise; ``delay`` [s]: the latency, a whole number of control periods;
    ``loss``: the probability that a packet is lost. All 0: the truth.
    """

    position_noise: float = 0.0
    heading_noise: float = 0.0
    delay: float = 0.0
    loss: float = 0.0


@dataclass(frozen=True)
class SafetySpec:
    """The safety filter on the commands (``safety:``).

    ``filter``: the registered name (``none``: no filter, the default); ``params``:
    its YAML values (lengths in metres, defaults filled in).
    """

    filter: str = "none"
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ReconfigureSpec:
    """Slot reassignment after failures (``reconfigure:``).

    ``assign``: ``none`` (every vehicle keeps its slot) or ``hungarian``;
    ``close_gap``: whether the slots are the formation's first ones (one per healthy
    vehicle) rather than all but the failed vehicles' slots.
    """

    assign: str = "none"
    close_gap: bool = False


#: The loader that validates the document a :class:`Scenario` is built from
#: (:func:`sandbox.scenario.parse.parse_scenario`). That module imports this one, so
#: it installs itself here when it is imported (:func:`install_loader`), which
#: importing :mod:`sandbox.scenario` does before any scenario can be made.
_LOADER: list[Callable[..., Scenario]] = []


def install_loader(parse: Callable[..., Scenario]) -> None:
    """Make ``parse`` the loader that validates every :class:`Scenario` built."""
    _LOADER[:] = [parse]


def loader() -> Callable[..., Scenario]:
    """The loader installed by :func:`install_loader`."""
    if not _LOADER:
        raise RuntimeError("sandbox.scenario.parse is not imported")
    return _LOADER[0]


#: Set while the loader constructs a scenario (which it has just validated).
_LOADER_BUILDS: ContextVar[bool] = ContextVar("loader_builds", default=False)


@contextmanager
def from_loader() -> Iterator[None]:
    """Construct scenarios without validating them again (the loader's own)."""
    token = _LOADER_BUILDS.set(True)
    try:
        yield
    finally:
        _LOADER_BUILDS.reset(token)


@dataclass(frozen=True)
class Scenario:
    """A validated scenario (build it with :func:`load_scenario`).

    Change one with :meth:`with_overrides`; any other construction is validated too.
    """

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
    #: The ``expect:`` section (see :mod:`sandbox.run.expectations`), or None.
    expect: Expectations | None = None
    #: The ``sensing:`` section (all 0 by default: the truth).
    sensing: SensingSpec = SensingSpec()
    #: The ``detection:`` section (default: the oracle).
    detection: DetectionSpec = DetectionSpec()
    #: The ``safety:`` section (filter ``none`` by default).
    safety: SafetySpec = SafetySpec()
    #: The ``reconfigure:`` section (default: every vehicle keeps its slot).
    reconfigure: ReconfigureSpec = ReconfigureSpec()
    #: The ``on_leader_failure:`` key: keep, virtual or elect.
    on_leader_failure: str = "keep"
    #: The fleet's ``sensors:`` (default: none).
    sensors: SensorsSpec = SensorsSpec()
    #: The ``platoons:`` section (empty: the file is one platoon).
    platoons: tuple[PlatoonGroup, ...] = ()
    #: The ``events:`` section: merges and splits of platoons (scenario/events.py).
    events: tuple[Any, ...] = ()

    def range_specs(self) -> list[RangeSpec | None]:
        """Each vehicle's range sensor (its own, else the fleet's), None: none."""
        return [
            (v.sensors if v.sensors is not None else self.sensors).range
            for v in self.vehicles
        ]

    def __post_init__(self) -> None:
        """Validate a scenario not made by the loader (the constructor, ``replace``).

        The loader builds scenarios under :func:`from_loader`; any other
        construction, such as ``dataclasses.replace(sc, dt=0.5)``, is parsed again
        from :meth:`to_dict` by the same loader, so it raises the loader's
        :class:`~sandbox.errors.ScenarioError` for an invalid value and otherwise
        holds exactly what the loader makes of it.
        """
        if _LOADER_BUILDS.get():
            return
        try:
            doc = self.to_dict()
        except (AttributeError, TypeError, ValueError, IndexError) as exc:
            raise ScenarioError(
                [Problem("", f"not a valid scenario ({type(exc).__name__}: {exc})")],
                self.source,
            ) from None
        checked = loader()(doc, source=self.source)
        for f in fields(self):
            if f.name != "source":
                object.__setattr__(self, f.name, getattr(checked, f.name))

    def with_overrides(self, *assignments: str, **changes: Any) -> Scenario:
        """A copy with some fields changed, validated by the loader.

        Parameters
        ----------
        *assignments : str
            ``path=value`` assignments in the ``--set`` syntax, e.g.
            ``"recovery.beta=2.5"`` or ``"vehicles[1].pose=[0, 1, 0]"``.
        **changes
            Top-level keys replaced whole, e.g. ``dt=0.02`` or
            ``recovery={"strategy": "smooth"}`` (YAML values: lengths may be
            ``"3d"``).

        Raises
        ------
        ScenarioError
            The changed scenario is invalid (every problem at once, each naming its
            ``--set``).

        Examples
        --------
        >>> from sandbox.scenario import load_scenario
        >>> sc = load_scenario({"reference": {"type": "point", "position": [1, 0]},
        ...     "vehicles": [{"pose": [0, 0, 0]}]})
        >>> sc.with_overrides("duration=2", dt=0.02).duration
        2.0
        """
        import json

        sets = list(assignments)
        for key, value in changes.items():
            sets.append(f"{key}={json.dumps(plain(value))}")
        return loader()(self.to_dict(), source=self.source, overrides=sets)

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
        document of a 10,000-vehicle scenario stays a few lines long. Several
        platoons are written as ``platoons:``, each entry its platoon's own sections.
        """
        if self.platoons:
            return platoons_document(self)
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
            doc["reference"].update(plain(self.reference.params, skip_none=True))
        if self.formation is not None:
            doc["formation"] = {"law": self.formation.law}
            doc["formation"].update(plain(self.formation.params, skip_none=True))
        listed = self.vehicles
        if self.platoon is not None:
            listed = self.vehicles[: len(self.vehicles) - self.platoon.count]
            made = self.vehicles[len(listed)]
            for key in ("mass", "v1_max", "v2_max", "max_accel", "motor_accel"):
                if getattr(made, key) is not None:
                    doc["vehicle"][key] = getattr(made, key)
            doc["vehicle"]["gains"] = plain(made.gains)
            doc["platoon"] = plain(self.platoon, skip_none=True)
        doc["vehicles"] = []
        for v in listed:
            item = plain(v, skip_none=True)
            item["gains"] = plain(v.gains)
            if v.drive.type == "reference":
                del item["drive"]
            doc["vehicles"].append(item)
        doc["recovery"] = plain(self.recovery, skip_none=True)
        doc["recovery"].update(doc["recovery"].pop("params"))
        if self.recovery.obstacles == "map":  # the default, left out
            del doc["recovery"]["obstacles"]
        # A failure that never starts (a run shortened by --duration) is left out.
        failures = [f for f in self.failures if f.at < self.duration]
        if failures:
            doc["failures"] = []
            for f in failures:
                item = plain(f, skip_none=True)
                item.update(item.pop("params"))
                doc["failures"].append(item)
        if self.obstacles:
            doc["obstacles"] = [o.document() for o in self.obstacles]
        doc["metrics"] = plain(self.metrics)
        if self.sensing != SensingSpec():
            doc["sensing"] = plain(self.sensing)
        if self.detection != DetectionSpec():
            doc["detection"] = {"method": self.detection.method}
            doc["detection"].update(plain(self.detection.params, skip_none=True))
        if self.safety != SafetySpec():
            doc["safety"] = {"filter": self.safety.filter}
            doc["safety"].update(plain(self.safety.params, skip_none=True))
        if self.reconfigure != ReconfigureSpec():
            doc["reconfigure"] = plain(self.reconfigure)
        if self.on_leader_failure != "keep":
            doc["on_leader_failure"] = self.on_leader_failure
        if self.sensors != SensorsSpec():
            doc["sensors"] = plain(self.sensors, skip_none=True)
        if self.expect is not None:
            doc["expect"] = self.expect.to_dict()
        return doc


def platoons_document(sc: Scenario) -> dict[str, Any]:
    """The document of a scenario of several platoons (:meth:`Scenario.to_dict`).

    The top level holds the world's keys and the first platoon's sections; each
    entry holds its name, colour, vehicles and the sections in which it differs
    from the first platoon, so that a ``--set`` of a top-level section changes
    every platoon that shares it.
    """
    first = sc.platoons[0].scenario
    with from_loader():  # the world's own keys, as one platoon writes them
        alone = dataclasses.replace(
            sc,
            vehicles=first.vehicles,
            platoon=first.platoon,
            platoons=(),
            failures=(),
            expect=None,
        )
    doc = alone.to_dict()
    for key in ("vehicles", "platoon", *ENTRY_SECTIONS):
        doc.pop(key, None)
    doc["vehicle"] = {"diameter": sc.diameter}
    shared = first.to_dict()
    sections = [k for k in ENTRY_SECTIONS if k not in ("vehicles", "platoon")]
    doc.update({k: shared[k] for k in sections if k in shared})
    doc["platoons"] = []
    for p in sc.platoons:
        own = p.scenario.to_dict()
        entry: dict[str, Any] = {"name": p.name, "color": p.color}
        for key in ("vehicle", "vehicles", "platoon"):
            if key in own:
                entry[key] = own[key]
        for key in ENTRY_SECTIONS:
            if key in own and own[key] != shared.get(key):
                entry[key] = own[key]
        doc["platoons"].append(entry)
    failures = [f for f in sc.failures if f.at < sc.duration]
    if failures:
        doc["failures"] = []
        for f in failures:
            item = {k: v for k, v in dataclasses.asdict(f).items() if v is not None}
            item.update(item.pop("params"))
            doc["failures"].append(item)
    if sc.events:
        doc["events"] = [e.document() for e in sc.events]
    if sc.expect is not None:
        doc["expect"] = sc.expect.to_dict()
    return doc


def plain(obj: Any, skip_none: bool = False) -> Any:
    """A plain document of a value: dataclasses and tuples as dicts and lists."""
    if isinstance(obj, Mapping):
        return {
            k: plain(v, skip_none)
            for k, v in obj.items()
            if not (skip_none and v is None)
        }
    if is_dataclass(obj):
        out = {}
        for f in fields(obj):
            value = getattr(obj, f.name)
            if skip_none and value is None:
                continue
            out[f.name] = plain(value, skip_none)
        return out
    if isinstance(obj, tuple | list):
        return [plain(v, skip_none) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
