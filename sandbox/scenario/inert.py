"""Keys a run would not use: one warning each, as for an expectation that cannot fail.

A scenario may hold a key that is valid but does nothing where it is. Three classes
are found, each from the declarations rather than key by key where it can be:

- a key of another plug-in of the section's kind (``detection: {method: glr, shift:
  4}``, ``safety: {barrier: braking}`` without a filter): warned of where a section
  that selects a plug-in is read (:func:`sandbox.scenario.sections.read_plugin_section`,
  from every plug-in's declared parameters);
- a time longer than the run, found from each declared key's unit: a span [s]
  (``sensing.delay: 1000`` on a 4 s run, a detector's window) or a rate [Hz] whose
  period is (``sensors.range.rate: 1e-300``) (:func:`spans_beyond_run`); a detector's
  spans are also clipped to the run, so that no window is sized for more periods than
  the run has;
- a key that acts only with another section or another value of its own section
  (:data:`CONDITIONS`: ``safety.estimate_gain`` without sensing, ``gamma`` under the
  braking barrier, ``sensors.range.memory`` without sensed obstacles, a platoon's
  ``columns`` off the grid). The declarations say this only in words, so these are
  listed here.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Mapping
from typing import Any

from sandbox import plugins
from sandbox.plugins.registration import Param
from sandbox.scenario.reader import Reader
from sandbox.scenario.sections import METRICS, SENSING
from sandbox.scenario.sensors import RANGE
from sandbox.scenario.specs import DetectionSpec
from sandbox.scenario.vehicles import PLATOON

#: Spans [s] that say how long something is kept: longer than the run is the whole
#: run, which is what they then mean.
KEPT_SPANS = ("memory", "isolation")
#: Keys with a unit of seconds that are instants, not spans (checked on their own).
INSTANTS = ("at", "until", "duration", "dt")
#: What a span longer than the run means, by key (else: it cannot act within it).
BEYOND_RUN = {
    "delay": "every vehicle holds the first copy of the others' poses (t = 0) "
    "for the whole run",
    "settle_dwell": "no vehicle can count as settled (the run must go on that long "
    "after its settling time)",
    "deadlock_time": "no deadlock can be found",
}


@dataclasses.dataclass(frozen=True)
class Condition:
    """A key that acts only when ``acts`` holds, and what it needs, in words."""

    acts: Callable[[dict[str, Any]], bool]
    needs: str


def _sensing_on(parts: dict[str, Any]) -> bool:
    s = parts.get("sensing")
    return s is not None and bool(
        s.position_noise or s.heading_noise or s.delay or s.loss
    )


#: Keys that act only with another section or value, by (section path, key); the
#: predicate reads ``parts`` (the sections as read: ``safety``, ``sensing``,
#: ``recovery``, ``platoon``).
CONDITIONS: dict[tuple[str, str], Condition] = {
    ("safety", "estimate_gain"): Condition(
        lambda p: p["safety"].params.get("barrier") == "braking" and _sensing_on(p),
        "barrier: braking and a sensing: section with noise, delay or loss",
    ),
    ("safety", "gamma"): Condition(
        lambda p: p["safety"].params.get("barrier") != "braking",
        "barrier: velocity (the braking barrier has no rate)",
    ),
    ("sensors.range", "memory"): Condition(
        lambda p: p["recovery"] is not None and p["recovery"].obstacles == "sensed",
        "recovery.obstacles: sensed",
    ),
    ("platoon", "columns"): Condition(
        lambda p: p["platoon"] is not None and p["platoon"].pattern == "grid",
        "pattern: grid",
    ),
}


def given(doc: Any, *path: str) -> Mapping[Any, Any]:
    """The mapping at ``path`` in the document, or an empty one."""
    for key in path:
        doc = doc.get(key) if isinstance(doc, Mapping) else None
    return doc if isinstance(doc, Mapping) else {}


def _values(spec: Any) -> dict[str, Any]:
    if spec is None:
        return {}
    if isinstance(spec, Mapping):
        return dict(spec)
    return {f.name: getattr(spec, f.name) for f in dataclasses.fields(spec)}


def declared_sections(
    doc: Mapping[Any, Any], parts: dict[str, Any]
) -> Iterator[tuple[str, dict[str, Param], dict[str, Any], Mapping[Any, Any]]]:
    """``(path, declarations, values, given)`` of every section a scenario read.

    ``parts`` holds the sections as read (``sensing``, ``metrics``, ``detection``,
    ``safety``, ``recovery``, ``sensors``, ``vehicles``); ``given`` is the mapping
    the file wrote there (its keys are the keys given).
    """
    yield "sensing", SENSING, _values(parts["sensing"]), given(doc, "sensing")
    yield "metrics", METRICS, _values(parts["metrics"]), given(doc, "metrics")
    for section, kind, spec, name in (
        ("detection", "detector", parts["detection"], "method"),
        ("safety", "filter", parts["safety"], "filter"),
        ("recovery", "strategy", parts["recovery"], "strategy"),
    ):
        selected = getattr(spec, name, None)
        if selected in plugins.names(kind):
            params = plugins.get(kind, selected).params
            yield section, params, dict(spec.params), given(doc, section)
    fleet = parts["sensors"]
    if fleet is not None and fleet.range is not None:
        yield (
            "sensors.range",
            RANGE,
            _values(fleet.range),
            given(doc, "sensors", "range"),
        )
    items = doc.get("vehicles") if isinstance(doc.get("vehicles"), list) else []
    for i, item in enumerate(items):
        own = given(item, "sensors", "range")
        if own:
            yield f"vehicles[{i}].sensors.range", RANGE, dict(own), own


def spans_beyond_run(
    rd: Reader, doc: Mapping[Any, Any], duration: float, parts: dict[str, Any]
) -> None:
    """Warn of each span [s] longer than the run and rate [Hz] slower than it.

    Only keys the file gives are warned of (a default is the sandbox's own choice).
    """
    for path, params, values, written in declared_sections(doc, parts):
        for key, p in params.items():
            value = values.get(key)
            if written.get(key) is None or not isinstance(value, int | float):
                continue
            if value == p.default:
                continue  # a document written back (run directories) states defaults
            where = f"{path}.{key}"
            if p.unit == "s" and key not in INSTANTS + KEPT_SPANS:
                if value > duration:
                    clipped = path == "detection"
                    what = (
                        f"clipped to the run's {duration:g} s"
                        if clipped
                        else BEYOND_RUN.get(key, "it cannot act within it")
                    )
                    rd.warn(
                        where,
                        f"{value:g} s is longer than the run ({duration:g} s): {what}",
                    )
            elif p.unit == "Hz" and value > 0 and 1.0 / value > duration:
                rd.warn(
                    where,
                    f"{value:g} Hz is one scan every {1.0 / value:.3g} s, longer than "
                    f"the run ({duration:g} s): the scan at t = 0 is held for the "
                    "whole run",
                )


def clip_detection(
    detection: DetectionSpec, duration: float, dt: float
) -> DetectionSpec:
    """The detector's spans [s] clipped to the run's whole periods.

    A detector sizes its windows by its spans (the GLR keeps ``window / dt`` periods
    of every vehicle's observations, ``noise_window / dt`` of its innovations); no
    more periods than the run has can be filled, so a span beyond the run is the
    run's whole periods, and a window of 10^9 s costs what one of the run costs.
    """
    if detection.method not in plugins.names("detector"):
        return detection
    params = plugins.get("detector", detection.method).params
    steps = math.floor(duration / dt + 1e-9)
    longest = max(steps, 1) * dt
    changed = {
        key: longest
        for key, p in params.items()
        if p.unit == "s"
        and isinstance(detection.params.get(key), int | float)
        and detection.params[key] > longest
        and detection.params[key] != p.default  # the defaults are short
    }
    if not changed:
        return detection
    return DetectionSpec(detection.method, {**detection.params, **changed})


def conditional_keys(rd: Reader, doc: Mapping[Any, Any], parts: dict[str, Any]) -> None:
    """Warn of each key given where the section or value it acts with is not."""
    items = doc.get("vehicles") if isinstance(doc.get("vehicles"), list) else []
    written = {
        "safety": given(doc, "safety"),
        "platoon": given(doc, "platoon"),
        "sensors.range": given(doc, "sensors", "range"),
        **{
            f"vehicles[{i}].sensors.range": given(item, "sensors", "range")
            for i, item in enumerate(items)
        },
    }
    for path, mapping in written.items():
        section = "sensors.range" if path.endswith("sensors.range") else path
        for (where, key), condition in CONDITIONS.items():
            if where != section or mapping.get(key) is None:
                continue
            if mapping.get(key) == _default(section, key, parts):
                continue  # a document written back (run directories) states defaults
            if section == "safety" and parts["safety"].filter == "none":
                continue  # warned of as a key of another plug-in
            if not condition.acts(parts):
                rd.warn(
                    f"{path}.{key}",
                    f"does nothing here: it acts only with {condition.needs}",
                )


def _default(section: str, key: str, parts: dict[str, Any]) -> Any:
    """The declared default of a key of :data:`CONDITIONS`."""
    if section == "safety":
        name = parts["safety"].filter
        params = plugins.get("filter", name).params if name != "none" else {}
    else:
        params = RANGE if section == "sensors.range" else PLATOON
    declared = params.get(key)
    return None if declared is None else declared.default
