"""A scenario's expectations (its ``expect:`` section) evaluated on its run.

:func:`evaluate` returns one :class:`Outcome` per expectation of
:class:`~sandbox.scenario.expectations.Expectations` (read by the loader), each
comparing the quantity of ``metrics.json`` (:func:`sandbox.compute_metrics`) with its
bound, with a message that says what happened; ``sandbox check``, the pytest plugin
and :func:`sandbox.testing.check_scenario` report them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox.scenario.expectations import (
    SHOWN_EVENTS,
    SHOWN_NAMES,
    Bound,
    Expectations,
)

if TYPE_CHECKING:
    from sandbox.run.record import Run


@dataclass(frozen=True)
class Outcome:
    """One evaluated expectation.

    Attributes
    ----------
    key : str
        Its path below ``expect``, e.g. ``collisions.healthy``.
    expected : str
        The expectation in words, e.g. ``0`` or ``at most 8 s``.
    got : str
        The measured value, with what explains it (``1 (red-green at 2.68 s)``).
    holds : bool
    """

    key: str
    expected: str
    got: str
    holds: bool

    def line(self, source: str) -> str:
        """``SOURCE: key: expected X, got Y``, the line ``sandbox check`` prints."""
        return f"{source}: {self.key}: expected {self.expected}, got {self.got}"


def event_text(event: dict[str, Any]) -> str:
    """A collision event of ``metrics.json`` in words: ``red-green at 2.68 s``."""
    return f"{event['a']}-{event['b']} at {event['t']:.2f} s"


def events_text(events: Sequence[dict[str, Any]], shown: int = SHOWN_EVENTS) -> str:
    """The first ``shown`` events in words, then ``and N more``."""
    text = ", ".join(event_text(e) for e in events[:shown])
    if len(events) > shown:
        text += f", and {len(events) - shown} more"
    return text


def closest_approach(run: Run) -> tuple[float, float, str, str] | None:
    """The closest two vehicles came: ``(distance [m], t [s], a, b)``, or None.

    The same minimum as :func:`sandbox.run.metrics.min_distance` over the recorded
    samples, with where and when it happened (pairs in scenario order).
    """
    pos = np.asarray(run.pose[..., :2])
    T, n = pos.shape[:2]
    if n < 2 or T == 0:
        return None
    i, j = np.triu_indices(n, 1)
    best = (math.inf, 0.0, "", "")
    step = max(1, 2_000_000 // len(i))
    for start in range(0, T, step):
        d = np.linalg.norm(
            pos[start : start + step][:, i] - pos[start : start + step][:, j], axis=-1
        )
        k, p = np.unravel_index(int(np.argmin(d)), d.shape)
        if d[k, p] < best[0]:
            best = (
                float(d[k, p]),
                float(run.t[start + k]),
                run.names[i[p]],
                run.names[j[p]],
            )
    return best


def _first(items: list[str], shown: int = SHOWN_EVENTS) -> str:
    """The first ``shown`` items joined by ``;``, then ``and N more``."""
    text = "; ".join(items[:shown])
    return text + (f"; and {len(items) - shown} more" if len(items) > shown else "")


def _healthy(run: Run, metrics: dict[str, Any]) -> list[str]:
    """Vehicles with a slot and no failure active at the end (as ``converged``)."""
    out = []
    for k, name in enumerate(run.names):
        has_slot = metrics["vehicles"][name]["formation_error"]["final"] is not None
        if has_slot and not (len(run.t) and bool(run.failed[-1, k])):
            out.append(name)
    return out


def _unsettled(metrics: dict[str, Any], name: str) -> str:
    final = metrics["vehicles"][name]["formation_error"]["final"]
    tol = metrics["settle_tol"]
    if final is None:
        return f"{name} has no slot"
    return f"{name} never settles: final error {final:.4g} m, settle_tol {tol:g} m"


def evaluate(
    expect: Expectations, run: Run, metrics: dict[str, Any] | None = None
) -> list[Outcome]:
    """Evaluate every expectation of ``expect`` on a run; one outcome each.

    Parameters
    ----------
    expect : Expectations
    run : Run
    metrics : dict, optional
        ``compute_metrics(run)``, if already computed.

    Returns
    -------
    list of Outcome
        In the order of :data:`EXPECT_KEYS`; the status first.
    """
    if metrics is None:
        from sandbox.run.metrics import compute_metrics

        metrics = compute_metrics(run)
    out = [_status(expect.status, metrics)]
    events = metrics["collisions"]["events"]
    for kind, bound in expect.collisions:
        if kind == "healthy":
            chosen = [e for e in events if e["healthy"]]
        elif kind == "total":
            chosen = list(events)
        elif kind in ("intra_platoon", "inter_platoon"):
            chosen = _platoon_events(metrics, events, kind)
        else:
            chosen = [e for e in events if e["kind"] == kind]
        count = metrics["collisions"].get(kind, 0)
        got = f"{count}" + (f" ({events_text(chosen)})" if chosen else "")
        out.append(Outcome(f"collisions.{kind}", bound.text(), got, bound.holds(count)))
    if expect.converged is not None:
        conv = bool(metrics["converged"])
        got = "true" if conv else "false"
        if not conv:
            why = [
                _unsettled(metrics, n)
                for n in _healthy(run, metrics)
                if metrics["vehicles"][n]["settling_time"] is None
            ]
            got += f" ({_first(why) or 'no healthy vehicle with a slot'})"
        expected = "true" if expect.converged else "false"
        out.append(Outcome("converged", expected, got, conv is expect.converged))
    if expect.deadlocks is not None:
        found = metrics.get("deadlocks", [])
        got = f"{len(found)}"
        if found:
            shown = [
                f"{'-'.join(d['vehicles'][:SHOWN_NAMES])} at {d['t']:.2f} s for "
                f"{d['duration']:.2f} s"
                for d in found[:SHOWN_EVENTS]
            ]
            if len(found) > SHOWN_EVENTS:
                shown.append(f"{len(found) - SHOWN_EVENTS} more")
            got += f" ({', '.join(shown)})"
        out.append(
            Outcome(
                "deadlocks",
                expect.deadlocks.text(),
                got,
                expect.deadlocks.holds(len(found)),
            )
        )
    if expect.min_distance is not None:
        md = metrics["min_distance"]
        if md is None:
            got = "none (fewer than two vehicles)"
        else:
            got = f"{md:.4g} m"
            where = closest_approach(run)
            if where is not None:
                got += f" ({where[2]}-{where[3]} at {where[1]:.2f} s)"
        out.append(
            Outcome(
                "min_distance",
                expect.min_distance.text("m"),
                got,
                expect.min_distance.holds(md),
            )
        )
    if expect.settling_time is not None:
        out.append(_worst_settling(expect.settling_time, run, metrics))
    for name, bound in expect.settling_times:
        st = metrics["vehicles"][name]["settling_time"]
        got = (
            f"{st:.2f} s" if st is not None else f"never ({_unsettled(metrics, name)})"
        )
        out.append(
            Outcome(f"settling_time.{name}", bound.text("s"), got, bound.holds(st))
        )
    for name, stat, bound in expect.formation_error:
        value = metrics["vehicles"][name]["formation_error"][stat]
        got = f"{value:.4g} m" if value is not None else "none (no slot)"
        out.append(
            Outcome(
                f"formation_error.{name}.{stat}",
                bound.text("m"),
                got,
                bound.holds(value),
            )
        )
    out += _platoon_outcomes(expect, metrics, events)
    return out


def _platoon_events(
    metrics: dict[str, Any], events: list[dict[str, Any]], kind: str
) -> list[dict[str, Any]]:
    """The vehicle-vehicle events within one platoon, or between two."""
    of = {v: k for k, p in metrics.get("platoons", {}).items() for v in p["vehicles"]}
    same = kind == "intra_platoon"
    return [
        e
        for e in events
        if e["kind"] == "vehicle_vehicle" and (of.get(e["a"]) == of.get(e["b"])) == same
    ]


def _platoon_outcomes(
    expect: Expectations, metrics: dict[str, Any], events: list[dict[str, Any]]
) -> list[Outcome]:
    """The outcomes of ``expect: platoons:`` (per platoon, in the order given)."""
    out = []
    for name, key, value in expect.platoons:
        entry = metrics["platoons"][name]
        path = f"platoons.{name}.{key}"
        if key == "converged":
            got = bool(entry["converged"])
            out.append(
                Outcome(path, str(value).lower(), str(got).lower(), got is value)
            )
            continue
        if key == "settling_time":
            st = entry["settling_time"]
            got = f"{st:.2f} s" if st is not None else "never"
            out.append(Outcome(path, value.text("s"), got, value.holds(st)))
            continue
        head, stat = key.split(".")
        measured = entry[head][stat]
        if head == "collisions":
            mine = set(entry["vehicles"])
            shown = [
                e
                for e in _platoon_events(metrics, events, stat)
                if e["a"] in mine or e["b"] in mine
            ]
            if stat == "vehicle_obstacle":
                shown = [
                    e
                    for e in events
                    if e["kind"] == stat and (e["a"] in mine or e["b"] in mine)
                ]
            got = f"{measured}" + (f" ({events_text(shown)})" if shown else "")
            out.append(Outcome(path, value.text(), got, value.holds(measured)))
        else:
            got = f"{measured:.4g} m" if measured is not None else "none (no slot)"
            out.append(Outcome(path, value.text("m"), got, value.holds(measured)))
    return out


def _status(expected: str, metrics: dict[str, Any]) -> Outcome:
    status = metrics["status"]
    got = status
    d = metrics.get("diverged")
    if status == "diverged" and d:
        where = f"at {d.get('t', 0):.2f} s, vehicle {d.get('vehicle')}"
        got += f" ({where}: {d.get('reason')})"
    return Outcome("status", expected, got, status == expected)


def _worst_settling(bound: Bound, run: Run, metrics: dict[str, Any]) -> Outcome:
    healthy = _healthy(run, metrics)
    times = {n: metrics["vehicles"][n]["settling_time"] for n in healthy}
    never = [n for n, st in times.items() if st is None]
    if not healthy:
        got, value = "none (no healthy vehicle with a slot)", None
    elif never:
        got, value = f"never ({_first([_unsettled(metrics, n) for n in never])})", None
    else:
        name = max(times, key=lambda n: times[n])
        value = times[name]
        got = f"{value:.2f} s ({name})"
    return Outcome("settling_time", bound.text("s"), got, bound.holds(value))
