"""Entry points: a scenario file or document to a validated :class:`Scenario`.

:func:`load_scenario` reads a file (or takes a mapping) and :func:`parse_scenario`
validates a document: the plug-ins the scenario lists (after the ``--set`` overrides
of ``plugins`` itself), the other ``--set`` overrides, its ``randomize`` draws, every
section, and the checks across sections.

The plug-in code a scenario lists runs only on trust (:mod:`sandbox.scenario.trust`);
``--set`` overrides are applied by :mod:`sandbox.scenario.overrides`. A valid
document's warnings are kept in ``Scenario.warnings`` and issued with
:func:`warnings.warn` as :class:`~sandbox.errors.SandboxWarning`, one per line, pointing
at the caller's code.
"""

from __future__ import annotations

import copy
import os
import sys
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sandbox import plugins
from sandbox.errors import Problem, SandboxWarning, ScenarioError
from sandbox.geometry.neighbours import NeighbourList
from sandbox.model.barriers import ESTIMATE_GAIN, sensing_margin
from sandbox.model.tunnelling import tunnelling_warning
from sandbox.plugins.registration import (
    Param,
)
from sandbox.scenario import bundled, randomize
from sandbox.scenario.checks import check_consistency
from sandbox.scenario.expectations import read_expectations
from sandbox.scenario.inert import clip_detection, conditional_keys, spans_beyond_run
from sandbox.scenario.needs import check_needs, estimate
from sandbox.scenario.overrides import apply_override, mark_overrides
from sandbox.scenario.platoons import parse_platoons
from sandbox.scenario.reader import (
    BAD_TEXT,
    MAX_VEHICLES,
    NAME_RULE,
    Reader,
    describe,
    name_problem,
    says,
)
from sandbox.scenario.sections import (
    METRICS,
    METRICS_KEYS,
    RECONFIGURE,
    SENSING,
    TOP,
    TOP_KEYS,
    read_detection,
    read_failures,
    read_formation,
    read_obstacles,
    read_param,
    read_params,
    read_recovery,
    read_reference,
    read_safety,
)
from sandbox.scenario.sensors import read_sensors
from sandbox.scenario.specs import (
    MetricsSpec,
    ReconfigureSpec,
    Scenario,
    SensingSpec,
    SensorsSpec,
    VehicleSpec,
    from_loader,
    install_loader,
)
from sandbox.scenario.trust import (
    PLUGIN_CODE,
    PLUGIN_OWNED,
    TRUST_ENV,
    UncheckedScenario,
    load_listed_plugins,
    trusted_by_environment,
)
from sandbox.scenario.vehicles import (
    VEHICLE_PARAM_KEYS,
    expand_platoon,
    platoon_frame,
    read_platoon,
    read_vehicle_params,
    read_vehicles,
    vehicle_defaults,
)
from sandbox.scenario.yamlfile import (
    NotAFile,
    YAMLLoader,
    duplicate_keys,
    line_map,
    long_integer_problem,
    read_limited,
    yaml_problem,
)

__all__ = [
    "TRUST_ENV",
    "UncheckedScenario",
    "load_scenario",
    "parse_scenario",
    "trusted_by_environment",
]


def parse_scenario(
    doc: Any,
    *,
    source: str | None = None,
    lines: dict[str, int] | None = None,
    overrides: list[str] | None = None,
    problems: list[Problem] | None = None,
    plugin_code: str | None = None,
    varied: frozenset[str] = frozenset(),
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
    plugin_code : str, optional
        One of :data:`PLUGIN_CODE`: ``load`` the listed plug-ins, ``refuse`` a scenario
        that lists one not yet loaded, or ``skip`` them (``sandbox validate``); default
        ``load`` if ``SANDBOX_TRUST_PLUGINS=1``, else ``refuse``.
    varied : frozenset of str, optional
        Field paths a caller set or drew already (a world's ``--set`` of the
        sections a platoon inherits): where one selects a plug-in, the document's
        keys of another plug-in are not warned of, as for ``overrides``.

    Raises
    ------
    ScenarioError
        With one :class:`~sandbox.errors.Problem` per problem found.
    UncheckedScenario
        Under ``skip``: sections select names of plug-ins that were not loaded.
    """
    if plugin_code is None:
        plugin_code = "load" if trusted_by_environment() else "refuse"
    if plugin_code not in PLUGIN_CODE:
        raise ValueError(f"plugin_code {plugin_code!r} is not one of {PLUGIN_CODE}")
    rd = Reader(lines or {})
    rd.problems.extend(problems or [])
    first_line = (lines or {}).get("", 1) if lines is not None else None
    if doc is None:
        raise ScenarioError(
            [
                *rd.problems,
                Problem(
                    "",
                    says("the file is empty", "nothing", "a mapping of scenario keys"),
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
                    says(
                        "the scenario is not a mapping",
                        describe(doc),
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
                    says(
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
    # ``--set plugins=...`` first: the plug-ins' own keys exist once they are loaded.
    first = [s for s in overrides or [] if s.strip().startswith("plugins")]
    for item in first:
        where = apply_override(rd, doc, item)
        if where is not None:
            overridden.append((where, item))
            rd.overridden.add(where)
    loaded = load_listed_plugins(rd, doc.get("plugins"), source, plugin_code)
    for item in [s for s in overrides or [] if s not in first]:
        before = len(rd.problems)
        where = apply_override(rd, doc, item)
        if where is not None:
            overridden.append((where, item))
            rd.overridden.add(where)
        elif rd.unloaded and item.strip().split(".")[0] in PLUGIN_OWNED:
            del rd.problems[before:]  # a key an unloaded plug-in may own
            rd.unchecked.append((f"--set {item}", "a key of an unloaded plug-in"))
    rd.varied.update(rd.overridden, varied)
    if doc.get("randomize") is not None:  # draws into the document (randomize.py)
        if isinstance(doc["randomize"], Mapping):
            rd.varied.update(str(path) for path in doc["randomize"])
        doc, found = randomize.resolve(
            doc, skip=rd.overridden, line=rd.line, check=_quietly_parsed
        )
        rd.problems.extend(found)
    rd.keys(doc, TOP_KEYS, "")
    if doc.get("platoons") is not None:  # several platoons: scenario/platoons.py
        scenario = parse_platoons(rd, doc, source, parse_scenario)
        for line in scenario.warnings:
            warnings.warn(line, SandboxWarning, stacklevel=_caller_level())
        return scenario

    default_name = Path(source).stem if source else "scenario"
    if doc.get("name") is None and name_problem(default_name, run=True):
        rd.fail(
            "name",
            "the file name gives an unusable run name",
            f"{describe(default_name)}, which {name_problem(default_name, run=True)}",
            f"a 'name:' key: {NAME_RULE} or .",
        )
        default_name = "scenario"
    name = rd.name(doc, "name", "", default_name, run=True) or default_name
    description = doc.get("description")
    description = "" if description is None else description
    if not isinstance(description, str):
        rd.fail("description", "not a string", describe(description), "a text")
        description = ""
    elif bad := BAD_TEXT.search(description):
        rd.fail(
            "description",
            f"holds the control character {bad.group()!r}",
            describe(description),
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
    base = vehicle_defaults()
    params = read_vehicle_params(rd, vehicle_doc, "vehicle", base)
    rd.diameter = params["diameter"] or 0.5
    # An invalid shared parameter is reported once; vehicles then use the default.
    params = {k: base[k] if v is None else v for k, v in params.items()}
    params["gains"] = {
        k: base["gains"][k] if v is None else v for k, v in params["gains"].items()
    }

    reference = None
    if doc.get("reference") is not None:
        reference = read_reference(rd, doc["reference"], "reference")
    formation = None
    if doc.get("formation") is not None:
        formation = read_formation(rd, doc["formation"], "formation")

    sensors = read_sensors(rd, doc.get("sensors"), "sensors") or SensorsSpec()
    listed = read_vehicles(rd, doc.get("vehicles"), "vehicles", params, sensors)
    platoon = None
    generated: list[tuple[str, VehicleSpec]] = []
    if doc.get("platoon") is not None:
        platoon = read_platoon(rd, doc["platoon"], "platoon")
        if platoon is not None and seed is not None:
            if len(listed) + platoon.count > MAX_VEHICLES:
                rd.fail(
                    "platoon.count",
                    "too many vehicles",
                    f"{len(listed)} listed + {platoon.count} generated",
                    f"at most {MAX_VEHICLES} in all",
                )
            else:
                made = expand_platoon(
                    platoon, [v for _, v in listed], params, seed, reference, formation
                )
                generated = [("platoon", v) for v in made]
    recovery = read_recovery(rd, doc.get("recovery"), "recovery")
    failures = read_failures(rd, doc.get("failures"), "failures")
    obstacles = read_obstacles(rd, doc.get("obstacles"), "obstacles")
    mdoc = rd.mapping(doc.get("metrics"), "metrics") or {}
    rd.keys(mdoc, METRICS_KEYS, "metrics")
    read, _ = read_params(rd, mdoc, "metrics", METRICS)
    metrics = MetricsSpec(
        **{k: METRICS[k].default if v is None else v for k, v in read.items()}
    )
    sensing = _sensing(rd, doc.get("sensing"), dt)
    detection = read_detection(rd, doc.get("detection"), "detection")
    _detection_window(rd, detection, dt)
    safety = read_safety(rd, doc.get("safety"), "safety")
    parts = {
        "sensing": sensing,
        "metrics": metrics,
        "detection": detection,
        "safety": safety,
        "recovery": recovery,
        "sensors": sensors,
        "platoon": platoon,
    }
    if isinstance(duration, float) and isinstance(dt, float) and dt > 0:
        spans_beyond_run(rd, doc, duration, parts)
        detection = clip_detection(detection, duration, dt)
    conditional_keys(rd, doc, parts)
    _sensed_obstacles(rd, recovery, sensors, listed)
    reconfigure = _reconfigure(rd, doc.get("reconfigure"))
    on_leader_failure = read_param(
        rd, doc, "on_leader_failure", "", TOP["on_leader_failure"]
    )[0]

    names = [n for _, n, _ in rd.declared] + [v.name for _, v in generated]
    expect = read_expectations(rd, doc.get("expect"), "expect", names)

    if rd.unchecked:  # sandbox validate of a scenario that needs its plug-ins
        owned = tuple(path for path, _ in rd.unchecked)
        rd.problems = [
            p
            for p in rd.problems
            if not any(
                p.path == o or p.path.startswith((f"{o}.", f"{o}[")) for o in owned
            )
        ]
        if rd.problems:
            found = mark_overrides(rd.problems, overridden)
            raise ScenarioError(
                sorted(found, key=lambda p: (p.line is None, p.line or 0)), source
            )
        raise UncheckedScenario(rd.unchecked, rd.unloaded, source or "scenario")
    check_consistency(
        rd,
        doc,
        duration,
        dt,
        listed + generated,
        reference,
        formation,
        failures,
        obstacles,
        platoon,
        recovery,
    )
    _safety_range(rd, safety, listed + generated)
    _safety_braking(rd, safety, listed + generated, sensing, dt)
    if None not in (duration, dt, record_every):
        fleet = [v for _, v in listed + generated]
        ranges = [(v.sensors or sensors).range for v in fleet]
        needs = estimate(
            duration,
            dt,
            record_every,
            fleet,
            ranges=ranges,
            sensing=sensing,
            detection=detection,
            safety=safety,
        )
        check_needs(rd, needs)
    _check_handover(
        rd,
        on_leader_failure,
        [v for _, v in listed + generated],
        formation.law if formation is not None else None,
        reference,
    )
    if rd.problems:
        found = mark_overrides(rd.problems, overridden)
        raise ScenarioError(
            sorted(found, key=lambda p: (p.line is None, p.line or 0)), source
        )
    vehicles = [v for _, v in listed + generated]
    law = formation.law if formation is not None else None
    fails = [f for _, f in failures]
    leader = next((v for v in vehicles if v.leader), None)
    x, y, angle, _ = platoon_frame(formation, leader, reference)
    tunnel = tunnelling_warning(
        vehicles, fails, reference, law, dt, substeps, duration, (x, y, angle)
    )
    if tunnel is not None:
        rd.warn("substeps", tunnel)
    with from_loader():
        scenario = Scenario(
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
            sensing=sensing,
            detection=detection,
            safety=safety,
            reconfigure=reconfigure,
            on_leader_failure=on_leader_failure or "keep",
            sensors=sensors,
            diameter=rd.diameter,
            source=source,
            plugins=tuple(loaded),
            warnings=tuple(
                w.format(source) for w in mark_overrides(rd.warnings, overridden)
            ),
            expect=expect,
        )
    for line in scenario.warnings:
        warnings.warn(line, SandboxWarning, stacklevel=_caller_level())
    return scenario


def _quietly_parsed(doc: dict[str, Any]) -> Scenario:
    """A candidate document of ``randomize:`` parsed without showing its warnings.

    The draws are checked by parsing them; the scenario drawn in the end shows its
    own warnings.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SandboxWarning)
        return parse_scenario(doc)


#: The package's folder, with a trailing separator (frames inside it are skipped).
PACKAGE_DIR = os.path.join(str(Path(__file__).parents[1]), "")


def _caller_level() -> int:
    """The ``stacklevel`` of the first frame outside sandbox, for :func:`warnings.warn`.

    The frame of ``warnings.warn``'s caller is level 1; the loader's own frames (and
    those of the sandbox code that called it) are skipped.
    """
    package = PACKAGE_DIR
    frame = sys._getframe(1)  # the caller of warnings.warn
    level = 1
    while frame.f_back is not None and frame.f_code.co_filename.startswith(package):
        frame = frame.f_back
        level += 1
    return level


def load_scenario(
    source: str | Path | Mapping[str, Any],
    overrides: list[str] | None = None,
    *,
    trust_plugins: bool | None = None,
    check_only: bool = False,
) -> Scenario:
    """Load and validate a scenario from a YAML file or a mapping.

    Parameters
    ----------
    source : path or mapping
        A ``.yaml`` file, the name of a bundled scenario (``paper/rotating_circle``,
        see :mod:`sandbox.scenario.bundled`; a file of that name wins), or an
        already-loaded document (a dict).
    overrides : list of str, optional
        ``path=value`` assignments applied before validation.
    trust_plugins : bool, optional
        Whether to run the code of the plug-ins the scenario lists (``plugins:``);
        default: whether ``SANDBOX_TRUST_PLUGINS=1``. Without trust, a scenario that
        lists a plug-in not loaded yet is a :class:`ScenarioError` naming it.
    check_only : bool
        Never run listed plug-in code (``sandbox validate``): check the listed paths
        and names, and raise :class:`UncheckedScenario` if a section needs them.

    Raises
    ------
    ScenarioError
        The file cannot be read or parsed, or the document is invalid. Never any other
        exception for any file content.
    """
    if check_only:
        code = "skip"
    elif trust_plugins is None:
        code = None
    else:
        code = "load" if trust_plugins else "refuse"
    if isinstance(source, Mapping):
        return parse_scenario(source, overrides=overrides, plugin_code=code)
    path = Path(source)
    name = str(source)
    if not path.exists() and not path.is_absolute():
        # A bundled scenario's name (``paper/rotating_circle``), as on the command
        # line: a file that exists under the name given always wins.
        path = bundled.find(name) or path
    expected = "a readable YAML scenario file"
    try:
        data = read_limited(path)
    except NotAFile as exc:
        raise ScenarioError(
            [Problem("", says("cannot read the scenario", str(exc), expected))],
            name,
        ) from None
    except FileNotFoundError:
        raise ScenarioError(
            [Problem("", says("cannot read the scenario", "no such file", expected))],
            name,
        ) from None
    except IsADirectoryError:
        raise ScenarioError(
            [Problem("", says("cannot read the scenario", "a directory", expected))],
            name,
        ) from None
    except OSError as exc:
        raise ScenarioError(
            [
                Problem(
                    "",
                    says(
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
                    says(
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
        loader = YAMLLoader(text)
        node = None
        try:
            node = loader.get_single_node()
            # Lines and duplicate keys come from the nodes as written: constructing
            # the document expands merge keys (<<: *anchor) into the nodes in place.
            lines: dict[str, int] = {}
            line_map(node, "", lines)
            duplicates = duplicate_keys(node)
            doc = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except ValueError as exc:  # an integer beyond Python's digit limit
        raise ScenarioError([long_integer_problem(node, exc)], name) from None
    except yaml.YAMLError as exc:
        raise ScenarioError([yaml_problem(exc, text)], name) from None
    except RecursionError:
        raise ScenarioError(
            [
                Problem(
                    "",
                    says(
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
        doc,
        source=name,
        lines=lines,
        overrides=overrides,
        problems=duplicates,
        plugin_code=code,
    )


def _sensing(rd: Reader, doc: Any, dt: Any) -> SensingSpec:
    """The ``sensing:`` section: bounds, and a delay of whole control periods."""
    values, ok = _section_values(rd, doc, "sensing", SENSING)
    if not ok:
        return SensingSpec()
    if values["loss"] >= 1:
        rd.fail(
            "sensing.loss", "must be below 1", f"{values['loss']:g}", "0 <= loss < 1"
        )
    if values["delay"] > 0:
        _whole_periods(rd, "sensing.delay", values["delay"], dt, minimum=0)
    return SensingSpec(**values)


def _sensed_obstacles(
    rd: Reader, recovery: Any, sensors: SensorsSpec, listed: list[tuple[str, Any]]
) -> None:
    """``recovery.obstacles: sensed`` needs a range sensor on some vehicle."""
    if recovery.obstacles != "sensed" or sensors.range is not None:
        return
    if any(v.sensors is not None and v.sensors.range is not None for _, v in listed):
        return
    rd.fail(
        "recovery.obstacles",
        "sensed obstacles need a range sensor",
        "no sensors.range",
        "sensors: {range: {...}} (fleet-wide or on a vehicle), or obstacles: map",
    )


def _section_values(
    rd: Reader, doc: Any, name: str, params: dict[str, Param]
) -> tuple[dict[str, Any], bool]:
    """A flat section's values, its defaults where unset, and whether all were valid."""
    m = rd.mapping(doc, name) or {}
    rd.keys(m, tuple(params), name)
    read, ok = read_params(rd, m, name, params)
    return {k: params[k].default if v is None else v for k, v in read.items()}, ok


def _whole_periods(rd: Reader, field: str, value: float, dt: Any, minimum: int) -> None:
    """A duration [s] that must be a whole number of control periods, >= ``minimum``."""
    if not (isinstance(dt, int | float) and dt > 0):
        return
    periods = value / dt
    whole = abs(periods - round(periods)) <= 1e-9 * max(1.0, periods)
    if periods < minimum - 1e-9 or not whole:
        rd.fail(
            field,
            f"must be a whole number of control periods dt = {dt:g} s",
            f"{value:g} s = {periods:g} periods",
            f"a multiple of {dt:g} s",
        )


def _detection_window(rd: Reader, detection: Any, dt: Any) -> None:
    """A detector's ``window`` [s], if it has one, is a whole number of periods."""
    window = detection.params.get("window")
    if isinstance(window, float):
        _whole_periods(rd, "detection.window", window, dt, minimum=1)


def _safety_range(rd: Reader, safety: Any, vehicles: list[tuple[str, Any]]) -> None:
    """A filter's automatic ``range`` needs every vehicle's ``v1_max``."""
    if "range" not in safety.params or safety.params["range"] is not None:
        return
    fast = [v.name for _, v in vehicles if v.v1_max is None]
    if fast:
        rd.fail(
            "safety.range",
            f"needed: vehicle {fast[0]} has no v1_max, and the automatic range is the "
            "distance beyond which no barrier can bind at the speed limits",
            "no range",
            "a range [m], or vehicle.v1_max",
        )


def _safety_braking(
    rd: Reader,
    safety: Any,
    vehicles: list[tuple[str, Any]],
    sensing: Any,
    dt: float,
) -> None:
    """A braking barrier's needs: drive limits, a margin it can keep, a safe start.

    ``barrier: braking`` needs every vehicle's finite ``max_accel`` and ``v1_max``
    (an error); a margin for the error of the estimated poses under sensing larger
    than a vehicle, or a start whose look-ahead points are closer than the
    barrier's ``D`` are warned of (the start is also reported in ``metrics.json``,
    ``safety.unsafe_start``). From such a start the barrier's guarantee does not
    hold: two vehicles 0.62 m apart facing each other turn at 4 rad/s, speed up and
    touch at 0.35 s (``tests/test_hostile_limits.py``).
    """
    if safety.params.get("barrier") != "braking":
        return
    specs = [v for _, v in vehicles]
    for key in ("max_accel", "v1_max"):
        slow = [v.name for v in specs if getattr(v, key) is None]
        if slow:
            rd.fail(
                "safety.barrier",
                f"braking needs every vehicle's {key}: vehicle {slow[0]} has none",
                "barrier: braking",
                f"vehicle.{key} (a finite bound), or barrier: velocity",
            )
            return
    if not specs:
        return
    look = float(safety.params["look_ahead"])
    margin = float(safety.params["margin"])
    sensed = 0.0
    if sensing is not None:
        gain = safety.params.get("estimate_gain")
        sensed = sensing_margin(
            sensing.position_noise,
            sensing.heading_noise,
            ESTIMATE_GAIN if gain is None else float(gain),
            look,
            max(v.v1_max for v in specs),
            min(v.max_accel for v in specs),
            dt,
        )
        smallest = min(v.diameter for v in specs)
        if sensed > smallest:
            rd.warn(
                "sensing.position_noise",
                f"the braking barrier's sensing margin 3 sqrt(K) (sigma_p + (l + S) "
                f"sigma_theta) = {sensed:.3g} m is larger than a vehicle "
                f"({smallest:g} m): the filter keeps the platoon that much further "
                "apart (a smaller safety.estimate_gain K makes it smaller)",
            )
    pose = np.array([v.pose for v in specs], dtype=float).reshape(-1, 3)
    point = pose[:, :2] + look * np.stack((np.cos(pose[:, 2]), np.sin(pose[:, 2])), -1)
    diameter = np.array([v.diameter for v in specs], dtype=float)
    reach = float(diameter.max()) + 2.0 * look + margin + sensed
    i, j, rel = NeighbourList(reach).near(point)
    gap = np.hypot(rel[:, 0], rel[:, 1])
    big_d = 0.5 * (diameter[i] + diameter[j]) + 2.0 * look + margin + sensed
    close = np.flatnonzero(gap < big_d)
    if len(close):
        k = close[np.argmin(gap[close] - big_d[close])]
        rd.warn(
            "safety.margin",
            f"the start is unsafe for barrier: braking: the look-ahead points of "
            f"{specs[i[k]].name} and {specs[j[k]].name} are {gap[k]:.3g} m apart, "
            f"below D = {big_d[k]:.3g} m (d + 2 l + margin + sensing margin); the "
            "barrier keeps vehicles apart only from a safe start: from this one the "
            "filter does not hold them at rest, and they may touch (metrics.json: "
            "safety.unsafe_start)",
        )


def _reconfigure(rd: Reader, doc: Any) -> ReconfigureSpec:
    """The ``reconfigure:`` section; ``close_gap`` needs ``assign: hungarian``."""
    values, ok = _section_values(rd, doc, "reconfigure", RECONFIGURE)
    if not ok:
        return ReconfigureSpec()
    if values["close_gap"] and values["assign"] == "none":
        rd.fail(
            "reconfigure.close_gap",
            "closes gaps only when slots are reassigned",
            "true with assign: none",
            "assign: hungarian, or close_gap: false",
        )
    return ReconfigureSpec(**values)


def _check_handover(
    rd: Reader,
    mode: Any,
    vehicles: list[VehicleSpec],
    law: str | None,
    reference: Any,
) -> None:
    """``on_leader_failure`` other than keep: a leader to replace, a reference."""
    if mode in (None, "keep") or (law is not None and law not in plugins.names("law")):
        return
    has_leader = any(v.leader for v in vehicles)
    needs_leader = law is not None and plugins.get("law", law).options["needs_leader"]
    if not (has_leader and needs_leader):
        rd.warn(
            "on_leader_failure",
            f"{mode} has no effect: the formation follows no leader"
            + (f" (law {law})" if law is not None and has_leader else ""),
        )
    elif reference is None:
        rd.fail(
            "on_leader_failure",
            f"{mode} needs a reference for the formation to follow",
            "no reference section",
            "a reference, or on_leader_failure: keep",
        )


# Every Scenario built another way is validated by this loader (specs.py).
install_loader(parse_scenario)
