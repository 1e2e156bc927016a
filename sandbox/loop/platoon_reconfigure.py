"""Slot reassignment and leader handover inside one platoon of several.

:class:`~sandbox.behaviour.reconfigure.Reconfiguration` reads one formation as it is
and returns what changes. For a platoon of a world of several (``platoons:`` with
``reconfigure`` or ``on_leader_failure`` in an entry), :class:`PlatoonView` gives it
the platoon's rows as that formation: the platoon's own reconfiguration reacts to
what the platoon believes failed among its vehicles, on its own slots, and what it
returns is applied to the platoon (its leader, law, offsets, tracked rows, and who of
its rows may avoid). Its records (``reassignments``, ``leader_changes``, ``slots``)
are merged into the run's, slots numbered in the fleet's vehicle order (slot ``k``:
``vehicles[k].offset``). A vehicle of another platoon is never given a slot of this
one.

With ``events:`` a platoon's configuration is formed anew at each merge or split that
changes it: its view is then rebuilt on the new rows and offsets (the old one
retired, its records kept), and slot ``k`` of that platoon is the offset vehicle ``k``
held at the event (``vehicles[k].offset`` before any). Each vehicle's slot timeline
runs on across the views, from the event's time in the new one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.behaviour.reconfigure import FormationState, Reconfiguration


class PlatoonView:
    """One platoon's rows as its reconfiguration sees them (see the module).

    Parameters
    ----------
    group : PlatoonGroup
        The platoon (:class:`sandbox.loop.platoons.PlatoonGroup`).
    scenario : Scenario
        The platoon's own scenario (its ``reconfigure`` and ``on_leader_failure``).
    names : list of str
        The world's vehicle names, in row order.
    commanded : ndarray, shape (n,), bool
        The world's vehicles driven open loop.
    avoid_candidates : ndarray, shape (n,), bool
        Who of the world may avoid (the platoons' own array: the view writes its
        rows).
    h : float [s]
    since : float [s]
        When the platoon's configuration was formed (0, or a merge or split).
    """

    def __init__(
        self,
        group: Any,
        scenario: Any,
        names: list[str],
        commanded: np.ndarray,
        avoid_candidates: np.ndarray,
        h: float,
        since: float = 0.0,
    ) -> None:
        rows = group.rows
        self.group, self.rows, self.since = group, rows, round(since, 9)
        self.h = h
        self.names = tuple(names[i] for i in rows)
        self.commanded = commanded[rows]
        self._avoid = avoid_candidates
        self.reconfiguration = Reconfiguration.build(
            scenario,
            self.names,
            group.offset,
            self.commanded,
            group.leader,
            np.isin(rows, group.track),
            group.law,
        )

    def state(
        self,
        pos: np.ndarray,
        theta: np.ndarray,
        vel: np.ndarray,
        seen: np.ndarray | None,
        believed: np.ndarray | None,
    ) -> FormationState:
        """The platoon's formation now, from its world's rows (``seen``: copies)."""
        g, rows = self.group, self.rows
        return FormationState(
            names=self.names,
            h=self.h,
            pos=pos[rows],
            theta=theta[rows],
            vel=vel[rows],
            seen=None if seen is None else seen[rows],
            believed=None if believed is None else believed[rows],
            offset=g.offset.copy(),
            commanded=self.commanded,
            leader=g.leader,
            tracks_reference=np.isin(rows, g.track),
            avoid_candidates=self._avoid[rows],
            law=g.law,
            law_params=g.params,
            law_memory=g.memory,
            reference=g.reference,
        )

    def react(
        self,
        t: float,
        known: np.ndarray,
        pos: np.ndarray,
        theta: np.ndarray,
        vel: np.ndarray,
        seen: np.ndarray | None,
        believed: np.ndarray | None,
    ) -> bool:
        """React to the world's believed failures ``known`` (n,) at ``t``; apply it.

        Returns whether the world's recovery shift's estimate restarts now.
        """
        if self.reconfiguration is None:
            return False
        state = self.state(pos, theta, vel, seen, believed)
        reform = self.reconfiguration.react(state, t, known[self.rows])
        if reform is None:
            return False
        if reform.re_formed:
            g = self.group
            g.leader = reform.leader
            g.law, g.params, g.memory = reform.law, reform.law_params, reform.law_memory
            g.offset = reform.offset
            g.track = self.rows[reform.tracks_reference]
            self._avoid[self.rows] = reform.avoid_candidates
        return reform.reset_shift

    def records(self) -> dict[str, Any]:
        """The records of this platoon, slots numbered in the fleet's order.

        A platoon's reconfiguration reacts before the period's plan, so a slot is
        held from the period of the reaction (the record's ``t + dt`` less ``dt``).
        """
        rows = self.rows

        def fleet_slot(k: int | None) -> int | None:
            return None if k is None else int(rows[k])

        info = self.reconfiguration.records()
        return {
            "reassignments": [
                {
                    "t": r["t"],
                    "assignment": {
                        n: fleet_slot(k) for n, k in r["assignment"].items()
                    },
                }
                for r in info["reassignments"]
            ],
            "leader_changes": list(info["leader_changes"]),
            "slots": {
                n: [
                    [max(round(t - self.h, 9), self.since), fleet_slot(k)]
                    for t, k in steps
                ]
                for n, steps in info["slots"].items()
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
