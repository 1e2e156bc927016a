"""Entry points: a scenario file or document to a validated :class:`Scenario`.

:func:`load_scenario` reads a file (or takes a mapping) and :func:`parse_scenario`
validates a document: ``--set`` overrides first, then the plug-ins the scenario lists,
its ``randomize`` draws, every section, and the checks across sections. A valid
document's warnings are kept in ``Scenario.warnings`` and issued with
:func:`warnings.warn` as :class:`~sandbox.errors.SandboxWarning`, one per line, pointing
at the caller's code.
"""

from __future__ import annotations

import copy
import os
import re
import sys
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from sandbox import plugins
from sandbox.errors import Problem, SandboxWarning, ScenarioError
from sandbox.model.tunnelling import tunnelling_warning
from sandbox.plugins.registration import (
    KINDS,
    Param,
    PluginError,
)
from sandbox.scenario import randomize
from sandbox.scenario.checks import _check_consistency
from sandbox.scenario.expectations import allowed_keys as expect_keys
from sandbox.scenario.expectations import read_expectations
from sandbox.scenario.reader import (
    _BAD_TEXT,
    MAX_VEHICLES,
    NAME_RULE,
    _describe,
    _hint,
    _Reader,
    _says,
    name_problem,
)
from sandbox.scenario.sections import (
    METRICS,
    METRICS_KEYS,
    PLUGIN_SECTIONS,
    RECONFIGURE,
    RECONFIGURE_KEYS,
    SENSING,
    SENSING_KEYS,
    TOP,
    TOP_KEYS,
    _detection,
    _failures,
    _formation,
    _obstacles,
    _recovery,
    _reference,
    _safety,
    read_param,
    read_params,
)
from sandbox.scenario.specs import (
    MetricsSpec,
    ReconfigureSpec,
    Scenario,
    SensingSpec,
    VehicleSpec,
    _from_loader,
)
from sandbox.scenario.vehicles import (
    DRIVE_KEYS,
    GAIN_KEYS,
    PLATOON_KEYS,
    VEHICLE_KEYS,
    VEHICLE_PARAM_KEYS,
    _expand_platoon,
    _platoon,
    _platoon_frame,
    _vehicle_defaults,
    _vehicle_params,
    _vehicles,
)
from sandbox.scenario.yamlfile import (
    _duplicate_keys,
    _line_map,
    _long_integer_problem,
    _NotAFile,
    _read_limited,
    _yaml_problem,
    _YAMLLoader,
)


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
    sensing = _sensing(rd, doc.get("sensing"), dt)
    detection = _detection(rd, doc.get("detection"), "detection")
    _detection_window(rd, detection, dt)
    safety = _safety(rd, doc.get("safety"), "safety")
    reconfigure = _reconfigure(rd, doc.get("reconfigure"))
    on_leader_failure = read_param(
        rd, doc, "on_leader_failure", "", TOP["on_leader_failure"]
    )[0]

    names = [n for _, n, _ in rd.declared] + [v.name for _, v in generated]
    expect = read_expectations(rd, doc.get("expect"), "expect", names)

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
    _safety_range(rd, safety, listed + generated)
    _check_handover(
        rd,
        on_leader_failure,
        [v for _, v in listed + generated],
        formation.law if formation is not None else None,
        reference,
    )
    if rd.problems:
        found = _mark_overrides(rd.problems, overridden)
        raise ScenarioError(
            sorted(found, key=lambda p: (p.line is None, p.line or 0)), source
        )
    vehicles = [v for _, v in listed + generated]
    law = formation.law if formation is not None else None
    fails = [f for _, f in failures]
    leader = next((v for v in vehicles if v.leader), None)
    x, y, angle, _ = _platoon_frame(formation, leader, reference)
    tunnel = tunnelling_warning(
        vehicles, fails, reference, law, dt, substeps, duration, (x, y, angle)
    )
    if tunnel is not None:
        rd.warn("substeps", tunnel)
    with _from_loader():
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
            diameter=rd.diameter,
            source=source,
            plugins=tuple(loaded),
            warnings=tuple(
                w.format(source) for w in _mark_overrides(rd.warnings, overridden)
            ),
            expect=expect,
        )
    for line in scenario.warnings:
        warnings.warn(line, SandboxWarning, stacklevel=_caller_level())
    return scenario


def _caller_level() -> int:
    """The ``stacklevel`` of the first frame outside sandbox, for :func:`warnings.warn`.

    The frame of ``warnings.warn``'s caller is level 1; the loader's own frames (and
    those of the sandbox code that called it) are skipped.
    """
    package = os.path.join(str(Path(__file__).parents[1]), "")
    frame = sys._getframe(1)  # the caller of warnings.warn
    level = 1
    while frame.f_back is not None and frame.f_code.co_filename.startswith(package):
        frame = frame.f_back
        level += 1
    return level


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


def _sensing(rd: _Reader, doc: Any, dt: Any) -> SensingSpec:
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


def _section_values(
    rd: _Reader, doc: Any, name: str, params: dict[str, Param]
) -> tuple[dict[str, Any], bool]:
    """A flat section's values, its defaults where unset, and whether all were valid."""
    m = rd.mapping(doc, name) or {}
    rd.keys(m, tuple(params), name)
    read, ok = read_params(rd, m, name, params)
    return {k: params[k].default if v is None else v for k, v in read.items()}, ok


def _whole_periods(
    rd: _Reader, field: str, value: float, dt: Any, minimum: int
) -> None:
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


def _detection_window(rd: _Reader, detection: Any, dt: Any) -> None:
    """A detector's ``window`` [s], if it has one, is a whole number of periods."""
    window = detection.params.get("window")
    if isinstance(window, float):
        _whole_periods(rd, "detection.window", window, dt, minimum=1)


def _safety_range(rd: _Reader, safety: Any, vehicles: list[tuple[str, Any]]) -> None:
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


def _reconfigure(rd: _Reader, doc: Any) -> ReconfigureSpec:
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
    rd: _Reader,
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
