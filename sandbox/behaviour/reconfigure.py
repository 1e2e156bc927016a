"""Reconfiguration and leader handover: which slot each healthy vehicle tracks.

The formation's *slots* are the vehicles' offsets in the order the scenario lists the
vehicles (slot ``k`` is ``vehicles[k].offset``: the formation order). In v0.1 vehicle
``k`` tracks slot ``k`` for ever, failed or not. This module changes that, on events
only: whenever :attr:`~sandbox.loop.simulation.Simulation.known_failed` (what the
platoon *believes* has failed, the oracle or a detector) changes, a vehicle newly
believed failed or a fault cleared, it

1. hands the lead over if the leader is believed failed (``on_leader_failure``):

   - ``keep``: nothing changes (the followers keep following the failed leader);
   - ``virtual``: the formation follows the reference itself, the virtual leader of
     section 3.4 (eq. (13)): the law becomes ``virtual``, its offsets turned with the
     reference's tangent (eqs. (14)-(15)) unless the law was a world-frame one;
   - ``elect``: the healthy vehicle nearest the leader's slot (the reference point at
     that time) leads; ties go to the vehicle listed first. Every vehicle evaluates
     the rule on the same broadcast poses, so all agree. The new leader tracks the
     reference (eq. (6)); its old slot is freed;

2. with ``reconfigure: {assign: hungarian}``, reassigns the healthy vehicles (all
   but the leader, whose slot is its own) to slots by minimum total squared distance
   from their positions to the slots' positions now
   (:func:`scipy.optimize.linear_sum_assignment`); the candidate slots are, with
   ``close_gap: true``, the formation's first slots, one per healthy vehicle (a column
   closes up), else every slot but those the failed vehicles held (their slots stay
   empty);

3. re-seeds the law's estimators
   (:meth:`~sandbox.model.laws.FormationLaw.reseed`): the backward
   differences of eqs. (8)-(9) and (18)-(19) would read the jump of the leader or of
   a slot as a velocity and an acceleration (1 m in h = 0.01 s: 100 m/s and 1e4
   m/s^2), so they restart from the new configuration at the event; a law's memory
   (``LawContext.memory``) and the estimate of the recovery shift restart too.

The new configuration acts from the period after the event (the plan of the event's
period is already made): 10 ms later at h = 0.01 s.

A vehicle without a slot (a failed one whose slot went to another, or that lost the
lead) has a NaN slot: it is recorded as having none. A failed vehicle stays an obstacle
to everyone: recovery avoids every vehicle believed failed. Nothing happens between
events, so an assignment never chatters. A vehicle whose fault clears is reassigned
with the others at that event; the lead is not handed back.

Reassigning a vehicle changes the offset it tracks (``Fleet.offset`` and the law's
``delta``); the commands stay within each vehicle's limits because the flatness
controller saturates its speed, acceleration and turn rate
(:func:`~sandbox.model.flatness.advance_extension`). The events are recorded in the
run's ``info`` as ``reassignments`` (``{t, assignment}``, the slot of each vehicle,
null for none) and ``leader_changes`` (``{t, from, to, mode}``, ``to`` null for the
virtual leader); ``metrics.json`` lists them. Each vehicle's slots over time are
recorded too, as ``slots``: ``{vehicle: [[t, slot], ...]}``, the slot it holds from
``t`` on (null: none), starting at 0 with the formation order and with an entry only
where it changes; ``t`` is the first period of the new configuration, the event's
``t + dt``. :attr:`sandbox.run.record.Run.slot_index` gives it per recorded sample.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox.plugins.registration import get, make_law

if TYPE_CHECKING:
    from sandbox.loop.simulation import Simulation


class Reconfiguration:
    """Slot assignment and leader handover of one run, updated on events.

    Build it with :meth:`build` (None when the scenario asks for neither).

    Parameters
    ----------
    sim : Simulation
        The run; its leader, law and offsets are changed in place at events.

    Attributes
    ----------
    formation : ndarray, shape (n, 2) [m]
        The slots' offsets, in formation order.
    slot_of : ndarray, shape (n,), int
        The slot each vehicle tracks, -1 for none.
    reassignments, leader_changes : list of dict
        The recorded events (also in ``sim.info``).
    """

    def __init__(self, sim: Simulation) -> None:
        sc, fleet, n = sim.scenario, sim.fleet, sim.fleet.n
        self.assign = sc.reconfigure.assign
        self.close_gap = sc.reconfigure.close_gap
        self.on_leader_failure = sc.on_leader_failure
        self.formation = fleet.offset.copy()
        # A slot is an offset: a vehicle without one (open loop, or left without a
        # slot before a merge or split formed this platoon) holds none.
        self.slot_of = np.where(
            fleet.commanded | ~np.isfinite(self.formation).all(axis=1), -1, np.arange(n)
        )
        #: Which slots exist (a finite offset of a vehicle not driven open loop).
        self.slot_exists = self.slot_of >= 0
        lead = sim.leader
        #: The slot of the vehicle that tracks the reference (-1: none).
        self.leader_slot = lead if lead >= 0 and sim.tracks_reference[lead] else -1
        #: The slot each failed vehicle held when it failed (kept empty).
        self.held: dict[int, int] = {}
        self.known = np.zeros(n, dtype=bool)
        self._reset_shift = False
        self.reassignments: list[dict[str, Any]] = []
        self.leader_changes: list[dict[str, Any]] = []
        sim.info["reassignments"] = self.reassignments
        sim.info["leader_changes"] = self.leader_changes
        #: Each vehicle's slots over time: ``[[t, slot or None], ...]`` by name.
        self.slots: dict[str, list[list]] = {
            name: [[0.0, _slot(self.slot_of[i])]] for i, name in enumerate(sim.names)
        }
        sim.info["slots"] = self.slots

    @classmethod
    def build(cls, sim: Simulation) -> Reconfiguration | None:
        """The run's reconfiguration, or None (today's behaviour, untouched)."""
        sc = sim.scenario
        if sim.law is None or (
            sc.reconfigure.assign == "none" and sc.on_leader_failure == "keep"
        ):
            return None
        return cls(sim)

    # ------------------------------------------------------------------ the event
    @property
    def waiting(self) -> bool:
        """Whether :meth:`react` has work at the next period even without a change.

        The period after an event restarts the estimate of the recovery shift.
        """
        return self._reset_shift

    def react(self, sim: Simulation, t: float, known: np.ndarray) -> bool:
        """Handle a change of the believed failures at ``t_k``, from ``t_k+1`` on.

        The plan of ``t_k`` is kept (the law has already been evaluated for it); the
        new leader, law and offsets act from the next period, 10 ms later at h =
        0.01 s, with the law's estimators re-seeded at ``t_k`` on the new
        configuration. Nothing happens unless ``known`` differs from the last call's
        or :attr:`waiting` is true, so a loop may skip the call otherwise.

        Parameters
        ----------
        sim : Simulation
        t : float [s]
        known : ndarray, shape (n,), bool
            The vehicles believed failed now.

        Returns
        -------
        bool
            Whether the configuration changed (a new leader, law or offsets).
        """
        if self._reset_shift:  # the first target of the new slots: restart there
            sim.shift_motion.reset()
            self._reset_shift = False
        known = np.asarray(known, dtype=bool)
        if np.array_equal(known, self.known):
            return False
        for i in np.flatnonzero(known & ~self.known):
            if self.slot_of[i] >= 0 and self.slot_of[i] != self.leader_slot:
                self.held[int(i)] = int(self.slot_of[i])
        for i in np.flatnonzero(~known & self.known):
            self.held.pop(int(i), None)
        self.known = known.copy()
        lead = sim.leader
        changed = False
        if self.on_leader_failure != "keep" and lead >= 0 and known[lead]:
            changed = self._hand_over(sim, t, lead)
        if self.assign == "hungarian":
            self._reassign(sim, t)
            changed = True
        if changed:
            self._apply(sim, t)
            self._record_slots(sim, t)
        return changed

    # ------------------------------------------------------------------ handover
    def _hand_over(self, sim: Simulation, t: float, lead: int) -> bool:
        """Replace the failed leader ``lead``; False if no vehicle can take over."""
        fleet = sim.fleet
        if self.on_leader_failure == "virtual":
            sc = sim.scenario
            frame = get("law", sc.formation.law).options["frame"]
            if frame == "world":
                rotate = False
            elif frame in ("reference", "leader_reference"):
                rotate = bool(sim.law_params.get("rotate", False))
            else:  # offsets in the leader's frame: turned with the reference
                rotate = True
            sim.law_params = {"rotate": rotate}
            sim.law = make_law("virtual", sim.law_params, fleet.offset, sim.h)
            # The tangent of eq. (15) until the reference moves: the leader's heading.
            sim.law._tangent = float(fleet.theta[lead])
            sim.law_memory = {}
            self._set_leader(sim, -1)
            self.held[lead] = self.leader_slot  # empty unless a gap closes
            self.leader_slot = -1  # the leader's slot is an ordinary one now
            new = None
        else:
            healthy = ~self.known & ~fleet.commanded
            healthy[lead] = False
            rows = np.flatnonzero(healthy)
            if len(rows) == 0 or sim.reference is None:
                return False
            point = sim.reference.evaluate(t)[0]
            seen = _positions(sim)[rows] - point
            new = int(rows[np.argmin(seen[:, 0] ** 2 + seen[:, 1] ** 2)])
            self.held.pop(new, None)
            self.slot_of[new] = self.leader_slot
            self._set_leader(sim, new)
        self.slot_of[lead] = -1 if new is not None else self.slot_of[lead]
        self.leader_changes.append(
            {
                "t": round(t, 9),
                "from": sim.names[lead],
                "to": None if new is None else sim.names[new],
                "mode": self.on_leader_failure,
            }
        )
        return True

    @staticmethod
    def _set_leader(sim: Simulation, new: int) -> None:
        """Make ``new`` (-1: none) the vehicle that leads and tracks the reference."""
        old, fleet = sim.leader, sim.fleet
        sim.tracks_reference[:] = False
        if new >= 0:
            sim.tracks_reference[new] = True
        sim._track_rows = np.flatnonzero(sim.tracks_reference)
        sim._avoid_candidates[old] = not fleet.commanded[old]
        if new >= 0:
            sim._avoid_candidates[new] = sim.rec.leader_avoids
        sim.leader = new

    # ------------------------------------------------------------------ assignment
    def _reassign(self, sim: Simulation, t: float) -> None:
        """Healthy vehicles to slots, minimum total squared distance (Hungarian)."""
        fleet, n = sim.fleet, sim.fleet.n
        movable = ~self.known & ~fleet.commanded
        if sim.leader >= 0 and sim.tracks_reference[sim.leader]:
            movable[sim.leader] = False
        rows = np.flatnonzero(movable)
        free = [j for j in range(n) if self.slot_exists[j] and j != self.leader_slot]
        if self.close_gap:
            cols = np.array(free[: len(rows)], dtype=np.intp)
        else:
            held = set(self.held.values())
            cols = np.array([j for j in free if j not in held], dtype=np.intp)
        for i in range(n):  # everyone but the leader loses the slot, then assigned
            if i != sim.leader or not sim.tracks_reference[i]:
                self.slot_of[i] = -1 if not fleet.commanded[i] else self.slot_of[i]
        if len(rows) and len(cols):
            from scipy.optimize import linear_sum_assignment  # only at an event

            where = self.slot_points(sim, t)[cols]
            rel = _positions(sim)[rows, None, :] - where[None, :, :]
            cost = rel[..., 0] ** 2 + rel[..., 1] ** 2  # [m^2]
            r, c = linear_sum_assignment(cost)
            self.slot_of[rows[r]] = cols[c]
        self.reassignments.append(
            {
                "t": round(t, 9),
                "assignment": {
                    name: (int(self.slot_of[i]) if self.slot_of[i] >= 0 else None)
                    for i, name in enumerate(sim.names)
                },
            }
        )

    def slot_points(self, sim: Simulation, t: float) -> np.ndarray:
        """Where every formation slot is at ``t``, shape (n, 2) [m].

        The law evaluated on a copy (its memory untouched) with the formation's
        offsets, around the current leader (or the reference, law ``virtual``).
        """
        law = copy.deepcopy(sim.law)
        if hasattr(law, "delta"):
            law.delta = self.formation.copy()
        ctx = _law_context(sim, t, self.formation.copy(), copy.deepcopy(sim.law_memory))
        slot = np.array(law.targets(ctx)[0], dtype=float)
        if self.leader_slot >= 0 and ctx.reference is not None:
            slot[self.leader_slot] = ctx.reference[0]  # the leader's: the reference
        return slot

    def _record_slots(self, sim: Simulation, t: float) -> None:
        """Append the slots that changed, held from the next period ``t + dt``."""
        start = round(t + sim.h, 9)
        for i, name in enumerate(sim.names):
            slot = _slot(self.slot_of[i])
            if self.slots[name][-1][1] != slot:
                self.slots[name].append([start, slot])

    # ------------------------------------------------------------------ applying
    def _apply(self, sim: Simulation, t: float) -> None:
        """Offsets from the assignment; the estimators re-seeded on them at ``t``."""
        fleet = sim.fleet
        offset = fleet.offset.copy()
        has = self.slot_of >= 0
        offset[has] = self.formation[self.slot_of[has]]
        offset[~has & ~fleet.commanded] = np.nan  # no slot
        fleet.offset = offset
        if hasattr(sim.law, "delta"):
            sim.law.delta = offset
        if hasattr(sim.law, "reseed"):
            sim.law.reseed()
        sim.law_memory.clear()
        # Re-seed: the law's differences start from the new configuration at t_k
        # (the next period's velocity is a first difference, never a jump / h).
        sim.law.targets(_law_context(sim, t, offset, sim.law_memory))
        self._reset_shift = True


def _law_context(sim: Simulation, t: float, offset: np.ndarray, memory: dict):
    """What the law sees at ``t`` with ``offset`` and ``memory``."""
    ref = sim.reference.evaluate(t) if sim.reference is not None else None
    return sim.law_context(t, ref, offset, memory)


def _slot(k: int) -> int | None:
    """A slot index as recorded: an int, or None for no slot (-1)."""
    return int(k) if k >= 0 else None


def _positions(sim: Simulation) -> np.ndarray:
    """The positions every vehicle agrees on: the broadcast copies, else the truth."""
    return sim.fleet.pos if sim.seen is None else sim.seen[:, :2]
