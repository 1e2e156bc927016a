"""Slot reassignment and leader handover inside one platoon of several.

:class:`~sandbox.behaviour.reconfigure.Reconfiguration` reads and changes a
simulation's leader, law, offsets and tracked rows. For a platoon of a world of
several (``platoons:`` with ``reconfigure`` or ``on_leader_failure`` in an entry),
:class:`PlatoonView` is that simulation restricted to the platoon's rows: the
platoon's own reconfiguration reacts to what the platoon believes failed among its
vehicles, on its own slots, and the changes are copied back to the platoon
(:meth:`PlatoonView.sync`). Its records (``reassignments``, ``leader_changes``,
``slots``) are merged into the run's, slots numbered in the fleet's vehicle order (slot
``k``: ``vehicles[k].offset``). A vehicle of another platoon is never given a slot of
this one.

With ``events:`` a platoon's configuration is formed anew at each merge or split that
changes it: its view is then rebuilt on the new rows and offsets (the old one
retired, its records kept), and slot ``k`` of that platoon is the offset vehicle ``k``
held at the event (``vehicles[k].offset`` before any). Each vehicle's slot timeline
runs on across the views, from the event's time in the new one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.behaviour.reconfigure import Reconfiguration
from sandbox.loop.worlds import law_context_of
from sandbox.plugins.registration import LawContext


class _FleetView:
    """The fleet's arrays of one platoon's rows (``offset`` is the platoon's own)."""

    def __init__(self, fleet: Any, rows: np.ndarray, offset: np.ndarray) -> None:
        self._fleet, self._rows = fleet, rows
        self.offset = offset.copy()
        self.commanded = fleet.commanded[rows]
        self.n = len(rows)

    @property
    def pos(self) -> np.ndarray:
        return self._fleet.pos[self._rows]

    @property
    def theta(self) -> np.ndarray:
        return self._fleet.theta[self._rows]

    @property
    def vel(self) -> np.ndarray:
        return self._fleet.vel[self._rows]


class PlatoonView:
    """A simulation as one platoon's reconfiguration sees it (see the module).

    Parameters
    ----------
    sim : Simulation
        The world's simulation.
    group : _One
        The platoon (:class:`sandbox.loop.platoons._One`).
    scenario : Scenario
        The platoon's own scenario (its ``reconfigure`` and ``on_leader_failure``).
    since : float [s]
        When the platoon's configuration was formed (0, or a merge or split).
    """

    def __init__(self, sim: Any, group: Any, scenario: Any, since: float = 0.0) -> None:
        rows = group.rows
        self._sim, self._group, self.rows = sim, group, rows
        self.group, self.since = group, round(since, 9)
        self.scenario = scenario
        self.h = sim.h
        self.names = [sim.names[i] for i in rows]
        self.fleet = _FleetView(sim.fleet, rows, group.offset)
        self.leader = group.leader
        self.law, self.law_params, self.law_memory = (
            group.law,
            group.params,
            group.memory,
        )
        self.reference = group.reference
        self.tracks_reference = np.isin(rows, group.track)
        self._track_rows = np.flatnonzero(self.tracks_reference)
        self._avoid_candidates = sim._avoid_candidates[rows].copy()
        self.rec = scenario.recovery
        self.shift_motion = sim.shift_motion
        self.info: dict[str, Any] = {}
        self.reconfiguration = Reconfiguration.build(self)

    @property
    def seen(self) -> np.ndarray | None:
        """The broadcast poses of the platoon's rows (None: the truth)."""
        seen = self._sim.seen
        return None if seen is None else seen[self.rows]

    @property
    def believed(self) -> np.ndarray | None:
        """What the platoon's law sees of its rows: ``seen``, or its estimate."""
        believed = self._sim.believed
        return None if believed is None else believed[self.rows]

    def law_context(
        self,
        t: float,
        ref: Any,
        offset: np.ndarray | None = None,
        memory: dict | None = None,
    ) -> LawContext:
        """What the platoon's law sees at ``t`` (as ``Simulation.law_context``)."""
        return law_context_of(self, t, ref, offset, memory)

    def react(self, t: float, known: np.ndarray) -> None:
        """React to the fleet's believed failures ``known`` (n,) at ``t``; sync."""
        if self.reconfiguration is None:
            return
        self.reconfiguration.react(self, t, known[self.rows])
        self.sync()

    def sync(self) -> None:
        """Copy the leader, law, offsets and tracked rows back to the platoon."""
        g, sim = self._group, self._sim
        g.leader = self.leader
        g.law, g.params, g.memory = self.law, self.law_params, self.law_memory
        g.offset = self.fleet.offset
        g.track = self.rows[self.tracks_reference]
        sim._avoid_candidates[self.rows] = self._avoid_candidates

    def records(self) -> dict[str, Any]:
        """The records of this platoon, slots numbered in the fleet's order.

        A platoon's reconfiguration reacts before the period's plan, so a slot is
        held from the period of the reaction (the record's ``t + dt`` less ``dt``).
        """
        rows = self.rows

        def fleet_slot(k: int | None) -> int | None:
            return None if k is None else int(rows[k])

        info = self.info
        return {
            "reassignments": [
                {
                    "t": r["t"],
                    "assignment": {
                        n: fleet_slot(k) for n, k in r["assignment"].items()
                    },
                }
                for r in info.get("reassignments", [])
            ],
            "leader_changes": list(info.get("leader_changes", [])),
            "slots": {
                n: [
                    [max(round(t - self.h, 9), self.since), fleet_slot(k)]
                    for t, k in steps
                ]
                for n, steps in info.get("slots", {}).items()
            },
        }


def merged_records(
    views: list[PlatoonView], names: list[str], rows_of: list[np.ndarray]
) -> dict[str, Any]:
    """The run's ``reassignments``, ``leader_changes`` and ``slots`` of all platoons.

    A vehicle of a platoon without reconfiguration holds its own slot throughout; the
    views are in the order they were built (a vehicle's timeline runs on from a
    retired view into the next, an entry kept only where its slot changes).
    """
    out: dict[str, Any] = {"reassignments": [], "leader_changes": [], "slots": {}}
    for view in views:
        rec = view.records()
        out["reassignments"] += rec["reassignments"]
        out["leader_changes"] += rec["leader_changes"]
        for name, steps in rec["slots"].items():
            timeline = out["slots"].setdefault(name, [])
            for t, k in steps:
                while timeline and timeline[-1][0] >= t:
                    timeline.pop()  # superseded by a view formed at or before t
                if not timeline or timeline[-1][1] != k:
                    timeline.append([t, k])
    out["reassignments"].sort(key=lambda r: r["t"])
    out["leader_changes"].sort(key=lambda r: r["t"])
    for rows in rows_of:
        for i in rows:
            timeline = out["slots"].setdefault(names[int(i)], [[0.0, int(i)]])
            if timeline[0][0] > 0:  # joined a reconfiguring platoon at an event
                timeline.insert(0, [0.0, int(i)])
    out["slots"] = {n: out["slots"][n] for n in names}
    return out
