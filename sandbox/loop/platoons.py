"""Several platoons in one world: each platoon's law on its rows, stitched together.

With ``platoons:`` (:mod:`sandbox.scenario.platoons`) the loop keeps one fleet, one
physics and one record; what differs by platoon is planned here, on plain arrays:

- **targets** (:meth:`Platoons.targets`): each platoon's reference is evaluated and
  its law sees only its own rows (positions, headings, velocities, offsets), its own
  leader and its own reference; the slots, ``x_ref'`` and ``x_ref''`` of all platoons
  are stitched into the fleet-wide arrays the controller reads
  (:mod:`sandbox.loop.platoon_targets`, which evaluates the ``virtual`` and
  ``leader_ref`` laws of all platoons, of one world or of K, in one pass);
- **recovery** (:meth:`Platoons.strategy`): the platoons that share a recovery
  section are shifted by one call of its strategy, with the whole fleet as
  neighbours and only their own rows allowed to avoid;
- **safety** (:meth:`Platoons.filter`): likewise, each safety section filters the
  commands of its platoons against every vehicle of the world.

What a vehicle knows of another platoon's vehicles is what it knows of its own
platoon's: their broadcast positions and velocities (the truth without ``sensing:``,
the noisy, delayed broadcast with it). It does not know their slots, references or
plans. Every vehicle is a neighbour of every other for recovery and the filters,
whatever their platoons; only the formation law is per platoon.

The contexts passed to plug-ins carry ``platoon``, the index of each vehicle's
platoon (for a law: of its rows). Everything here takes and returns arrays, so that
it can serve any loop that holds the fleet as arrays: a world's platoons change only
themselves, and :meth:`Platoons.prepare` returns what the loop takes of a change
(:class:`PlatoonChange`: the records of the run's description, a restart of the
recovery shift's estimate).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from sandbox.geometry.neighbours import NeighbourList
from sandbox.loop import platoon_events
from sandbox.loop.platoon_reconfigure import PlatoonView, merged_records
from sandbox.plugins.registration import get, make_law, runnable


class PlatoonGroup:
    """One platoon's reference, law and the rows they drive.

    Parameters
    ----------
    name : str
    rows : ndarray (m,) int
        The platoon's vehicles, its leader among them at ``leader``.
    offset : ndarray (m, 2) [m]
        Their offsets in the platoon's formation.
    law : str or None
        The registered law (None: every vehicle tracks the reference).
    params : dict
        The law's values.
    reference : object or None
        The built reference (``evaluate(t)``).
    leader : int
        The leader's position in ``rows`` (-1: none).
    commanded : ndarray (n,) bool
        The fleet's open-loop vehicles.
    h : float [s]
    """

    def __init__(
        self,
        name: str,
        rows: np.ndarray,
        offset: np.ndarray,
        law: str | None,
        params: dict,
        reference: Any,
        leader: int,
        commanded: np.ndarray,
        h: float,
    ) -> None:
        self.name = name
        self.rows = np.asarray(rows, dtype=np.intp)
        self.reference = reference
        self.law_name = law
        self.params = dict(params)
        self.offset = np.asarray(offset, dtype=float)
        self.law = make_law(law, self.params, self.offset, h) if law else None
        self.memory: dict = {}
        self.leader = leader
        tracks = np.zeros(len(self.rows), dtype=bool)
        if self.law is None:
            tracks[:] = True
        elif get("law", law).options["needs_leader"] and self.leader >= 0:
            tracks[self.leader] = True
        tracks &= ~commanded[self.rows]
        self.track = self.rows[tracks]
        self.commanded = self.rows[commanded[self.rows]]
        #: The reference's rows of some periods from the first (loop/platoon_targets).
        self.reference_rows: tuple[int, Any] = (0, None)

    @classmethod
    def of(
        cls, group: Any, offset: np.ndarray, commanded: np.ndarray, h: float
    ) -> PlatoonGroup:
        """The platoon of a ``platoons:`` entry (a scenario's ``PlatoonSpec``)."""
        sc = group.scenario
        spec = sc.formation
        rows = np.asarray(group.rows, dtype=np.intp)
        return cls(
            group.name,
            rows,
            offset[rows],
            spec.law if spec else None,
            dict(spec.params) if spec else {},
            sc.reference.build() if sc.reference else None,
            sc.leader_index,
            commanded,
            h,
        )


@dataclass(frozen=True)
class PlatoonChange:
    """What the loop takes of a world's platoons' merges, splits and reconfigurations.

    Attributes
    ----------
    records : dict or None
        The entries of the run's description that changed (None: none).
    reset_shift : bool
        Restart the world's recovery shift's estimate now (after a reconfiguration).
    """

    records: dict[str, Any] | None = None
    reset_shift: bool = False


class Platoons:
    """The platoons of one world (``platoons:``); see the module docstring.

    A world's platoons are its own: its merges, splits and reconfigurations happen
    at its own times (a loop of K worlds keeps one :class:`Platoons` a world).

    Parameters
    ----------
    scenario : Scenario
        A scenario with ``platoons:``.
    offset : ndarray, shape (n, 2) [m]
        The fleet's offsets (each vehicle's within its platoon's formation).
    commanded : ndarray, shape (n,), bool
        Vehicles driven open loop.
    h : float [s]
        The control period.
    """

    def __init__(
        self, scenario: Any, offset: np.ndarray, commanded: np.ndarray, h: float
    ) -> None:
        self.h = h
        self.n = len(offset)
        self.groups = [
            PlatoonGroup.of(g, offset, commanded, h) for g in scenario.platoons
        ]
        self.commanded = commanded
        #: The events still to fire (``events:``), and the record of those fired.
        self.events = list(scenario.events)
        self.fired: list[dict[str, Any]] = []
        #: Each vehicle's platoon, shape (n,), int.
        self.index = np.zeros(self.n, dtype=np.intp)
        for k, g in enumerate(self.groups):
            self.index[g.rows] = k
        self.names = [g.name for g in self.groups]
        self.vehicle_names = [v.name for v in scenario.vehicles]
        #: Vehicles that may avoid: not open loop, no leader that does not avoid.
        self.avoid_candidates = ~commanded
        for g, spec in zip(self.groups, scenario.platoons, strict=True):
            if not spec.scenario.recovery.leader_avoids and g.leader >= 0:
                self.avoid_candidates[g.rows[g.leader]] = False
        #: The recovery sections: ``(spec, (strategy, neighbours), rows mask)`` each.
        self.recoveries = _sections(
            scenario.platoons,
            lambda sc: sc.recovery,
            lambda spec: (
                runnable(get("strategy", spec.strategy)),
                NeighbourList(spec.R),
            ),
            self.n,
        )
        #: The safety sections: ``(spec, filter or None, rows mask)`` each.
        self.filters = _sections(
            scenario.platoons,
            lambda sc: sc.safety,
            lambda spec: (
                None if spec.filter == "none" else runnable(get("filter", spec.filter))
            ),
            self.n,
        )
        self._filter_memory: list[dict] = [{} for _ in self.filters]
        #: Each safety section's counters (summed into the run's by :meth:`filter`).
        self.filter_stats: list[dict] = [{} for _ in self.filters]
        #: Each vehicle's platoon and offset over time (with ``events:``).
        self.timeline: dict[str, list[list]] | None = None
        #: Each platoon's own scenario by name (a split's: the one it leaves).
        self._scenarios = {p.name: p.scenario for p in scenario.platoons}
        #: The platoons' own reconfigurations, and those retired by a merge or split.
        self.views: list[PlatoonView] = []
        self._retired: list[PlatoonView] = []
        #: How many reconfiguration records the run's ``info`` holds (-1: none yet).
        self._records = -1
        self._first: dict[str, Any] = {}
        if scenario.events:
            self._first["platoon_events"] = self.fired
            self.timeline = {name: [] for name in self.vehicle_names}
            self._note_formation(0.0)
            self._first["formation_timeline"] = self.timeline
        self._view_platoons(0.0)
        self._first.update(self._record_reconfiguration() or {})

    def records(self) -> dict[str, Any]:
        """The entries of the run's description at the start, in order.

        With ``events:``, ``platoon_events`` (the record of the events fired, a list
        filled as they fire) and ``formation_timeline``; with a reconfiguring
        platoon, the merged ``reassignments``, ``leader_changes`` and ``slots``.
        """
        return dict(self._first)

    def _note_formation(self, t: float) -> None:
        """Append to :attr:`timeline` each vehicle whose platoon or offset changed.

        The timeline (with ``events:`` only; ``info["formation_timeline"]``) is the
        fleet's slots through merges, splits and reassignments alike: each vehicle's
        ``[[t, platoon, offset], ...]``, held from ``t`` [s] (the first period that
        plans with it), the offset [m] in its platoon's formation (None: no slot).
        """
        for g in self.groups:
            for i, o in zip(g.rows, g.offset, strict=True):
                held = (
                    [round(float(o[0]), 9), round(float(o[1]), 9)]
                    if np.all(np.isfinite(o))
                    else None
                )
                steps = self.timeline[self.vehicle_names[int(i)]]
                if not steps or steps[-1][1] != g.name or steps[-1][2] != held:
                    steps.append([round(t, 9), g.name, held])

    def _view_platoons(self, t: float) -> None:
        """Build the views the platoons now need, and retire those of platoons gone.

        A reconfiguring platoon without a view gets one: at the start, or when a merge
        or split at ``t`` formed it. Each platoon's own reconfiguration
        (loop/platoon_reconfigure.py) reacts at the start of a period to what was
        believed failed at the end of the last one (the single-platoon loop reacts
        after planning the period: either way the new configuration drives from the
        next period on).
        """
        live = {id(g) for g in self.groups}
        self._retired += [v for v in self.views if id(v.group) not in live]
        self.views = [v for v in self.views if id(v.group) in live]
        viewed = {id(v.group) for v in self.views}
        for g in self.groups:
            sc = self._scenarios[g.name]
            if id(g) in viewed or (
                sc.reconfigure.assign == "none" and sc.on_leader_failure == "keep"
            ):
                continue
            view = PlatoonView(
                g,
                sc,
                self.vehicle_names,
                self.commanded,
                self.avoid_candidates,
                self.h,
                since=t,
            )
            if view.reconfiguration is not None:
                self.views.append(view)

    def _record_reconfiguration(self) -> dict[str, Any] | None:
        """The platoons' merged records when they changed (None: unchanged)."""
        views = self._retired + self.views
        if not views:
            return None
        count = len(views) + sum(
            len(v.reconfiguration.reassignments)
            + len(v.reconfiguration.leader_changes)
            + sum(len(s) for s in v.reconfiguration.slots.values())
            for v in views
        )
        if count == self._records:
            return None
        self._records = count
        rows = [g.rows for g in self.groups]
        return merged_records(views, self.vehicle_names, rows)

    def of_vehicles(self) -> tuple[str, ...]:
        """The name of each vehicle's platoon, in vehicle order."""
        return tuple(self.names[k] for k in self.index)

    @property
    def filtered(self) -> bool:
        """Whether some platoon has a safety filter."""
        return any(f is not None for _, f, _ in self.filters)

    def prepare(
        self,
        t: float,
        pos: np.ndarray,
        theta: np.ndarray,
        vel: np.ndarray,
        seen: np.ndarray | None,
        believed: np.ndarray | None,
        known: np.ndarray,
    ) -> PlatoonChange:
        """The merges and splits due at ``t``, and each platoon's reconfiguration.

        What precedes the laws' evaluation
        (:func:`~sandbox.loop.platoon_targets.platoon_targets`, once for the
        platoons of every world after each world's ``prepare``).

        Parameters
        ----------
        t : float [s]
        pos, theta, vel : ndarray, shapes (n, 2), (n,), (n, 2)
            The world's true positions [m], headings [rad] and velocities [m/s].
        seen, believed : ndarray, shape (n, 3), or None
            The broadcast copies and what the laws see of them (None: the truth).
        known : ndarray, shape (n,), bool
            What the world's platoons believe has failed (at the end of the last
            period).
        """
        before = (len(self.fired), self._records)
        if self.events:  # merges and splits due now (loop/platoon_events.py)
            self._fire(t, (pos, theta, vel))
        records = None
        reset = False
        if self.views:  # each platoon's own reconfiguration
            for view in self.views:
                reset |= view.react(t, known, pos, theta, vel, seen, believed)
            records = self._record_reconfiguration()
        if self.timeline is not None and before != (len(self.fired), self._records):
            # offsets change only at an event or a reconfiguration
            self._note_formation(t)
        return PlatoonChange(records, reset)

    def _make(self, name, rows, offset, law, params, reference, leader) -> PlatoonGroup:
        return PlatoonGroup(
            name, rows, offset, law, params, reference, leader, self.commanded, self.h
        )

    def _fire(self, t: float, state: tuple[np.ndarray, ...]) -> None:
        """Apply the events due at ``t`` in their order; record them."""
        by_name = {g.name: g for g in self.groups}
        for event in list(self.events):
            if not platoon_events.due(event, t, by_name, state[0]):
                continue
            if event.kind == "split" and not set(
                self.vehicle_names.index(v) for v in event.vehicles
            ) <= set(by_name[event.platoon].rows.tolist()):
                continue  # its vehicles are not (yet) all in the platoon
            self.events.remove(event)
            if event.kind == "merge":
                into, source = by_name[event.into], by_name[event.source]
                merged, record = platoon_events.merge(
                    into, source, t, self.h, state, self._make
                )
                self.groups = [
                    merged if g is into else g for g in self.groups if g is not source
                ]
                record["offsets"] = {
                    self.vehicle_names[int(i)]: o for i, o in record["offsets"].items()
                }
            else:
                group = by_name[event.platoon]
                rest, made, record = platoon_events.split(
                    group, event, self.vehicle_names, self._make, t
                )
                at = self.groups.index(group)
                self.groups[at : at + 1] = [rest, made]
                self._scenarios[event.new] = self._scenarios[event.platoon]
            self._leaders_avoid()
            self._view_platoons(t)
            by_name = {g.name: g for g in self.groups}
            record["platoons"] = {
                g.name: [self.vehicle_names[i] for i in g.rows] for g in self.groups
            }
            self.fired.append(record)
            for g in self.groups:
                if g.name not in self.names:
                    self.names.append(g.name)
                self.index[g.rows] = self.names.index(g.name)

    def _leaders_avoid(self) -> None:
        """Who may avoid after a merge or split: a leader as its section says."""
        cand = self.avoid_candidates
        cand[:] = ~self.commanded
        for spec, _, mask in self.recoveries:
            for g in self.groups:
                if g.leader >= 0 and mask[g.rows[g.leader]] and not spec.leader_avoids:
                    cand[g.rows[g.leader]] = False

    def strategy(self, ctx: Any) -> tuple[np.ndarray, np.ndarray]:
        """The recovery shift of every vehicle: each platoon's section on its rows.

        ``ctx`` is the loop's :class:`~sandbox.plugins.StrategyContext` of the whole
        fleet; each recovery section is called with its own parameters, ``R`` and
        neighbour index, and ``may_avoid`` narrowed to its platoons' rows.
        """
        shift = np.zeros((self.n, 2))
        active = np.zeros(self.n, dtype=bool)
        for spec, (strategy, neighbours), mask in self.recoveries:
            sub = dataclasses.replace(
                ctx,
                may_avoid=ctx.may_avoid & mask,
                params=dict(spec.params),
                R=spec.R,
                neighbours=neighbours,
                platoon=self.index,
            )
            s, a = strategy(sub)
            shift[mask] = np.asarray(s, dtype=float)[mask]
            active[mask] = np.asarray(a, dtype=bool)[mask]
        return shift, active

    def filter(self, ctx: Any) -> tuple[np.ndarray, np.ndarray]:
        """The filtered commands: each platoon's safety section on its rows.

        ``ctx`` is the loop's :class:`~sandbox.plugins.FilterContext` of the whole
        fleet; a platoon without a filter keeps its commands. Each section has its
        own memory; their counters are summed into ``ctx.stats``.
        """
        v1 = np.array(ctx.v1, dtype=float)
        v2 = np.array(ctx.v2, dtype=float)
        for k, (spec, flt, mask) in enumerate(self.filters):
            if flt is None:
                continue
            sub = dataclasses.replace(
                ctx,
                params=dict(spec.params),
                memory=self._filter_memory[k],
                stats=self.filter_stats[k],
                platoon=self.index,
            )
            out = flt(sub)
            v1[mask] = np.broadcast_to(np.asarray(out[0], dtype=float), (self.n,))[mask]
            v2[mask] = np.broadcast_to(np.asarray(out[1], dtype=float), (self.n,))[mask]
        ctx.stats.update(sum_counters(self.filter_stats))
        return v1, v2


def sum_counters(sections: list[dict[str, Any]]) -> dict[str, Any]:
    """The counters of a world's safety sections as one: numbers summed.

    A value that is not a number (a flag, a list) is the first section's.
    """
    totals: dict[str, Any] = {}
    for stats in sections:
        for key, value in stats.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                totals[key] = totals.get(key, 0) + value
            else:
                totals.setdefault(key, value)
    return totals


def _sections(
    platoons: Any, section: Any, make: Any, n: int
) -> list[tuple[Any, Any, np.ndarray]]:
    """The distinct sections of the platoons: ``(spec, built, rows mask)`` each."""
    out: list[tuple[Any, Any, np.ndarray]] = []
    for p in platoons:
        spec = section(p.scenario)
        for known, _, mask in out:
            if known == spec:
                mask[list(p.rows)] = True
                break
        else:
            mask = np.zeros(n, dtype=bool)
            mask[list(p.rows)] = True
            out.append((spec, make(spec), mask))
    return out
