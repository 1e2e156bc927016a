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

A reconfiguration reads one formation as it is (:class:`FormationState`: one world's,
or one platoon's of a world with ``platoons:``) and returns what changes
(:class:`Reform`: the offsets, the leader, the law, the tracked rows, who may avoid);
the loop applies it. Reassigning a vehicle changes the offset it tracks (the fleet's
offset and the law's ``delta``); the commands stay within each vehicle's limits
because the flatness controller saturates its speed, acceleration and turn rate
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
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sandbox.plugins.registration import LawContext, get, make_law
from sandbox.scenario import Scenario


@dataclass(frozen=True)
class FormationState:
    """One formation as a reconfiguration reads it: a world's, or a platoon's.

    Attributes
    ----------
    names : tuple of str
        The vehicles' names, in row order.
    h : float [s]
        The control period.
    pos, theta, vel : ndarray, shapes (n, 2), (n,), (n, 2)
        The true positions [m], headings [rad] and velocities [m/s].
    seen : ndarray, shape (n, 3), or None
        The broadcast copies every vehicle agrees on (None: the truth).
    believed : ndarray, shape (n, 3), or None
        What the law sees of the others (the copies, or their estimate).
    offset : ndarray, shape (n, 2) [m]
        The offsets the vehicles track now.
    commanded : ndarray, shape (n,), bool
        The vehicles driven open loop.
    leader : int
        The vehicle that leads (-1: none).
    tracks_reference : ndarray, shape (n,), bool
        The vehicles that track the reference.
    avoid_candidates : ndarray, shape (n,), bool
        The vehicles that may avoid (recovery).
    law : object
        The formation law (``make_law``), evaluated on these rows alone.
    law_params, law_memory : dict
        The law's values and memory.
    reference : object or None
        The built reference (``evaluate(t)``).
    context : dict
        Further fields of the law's context (the range readings).
    """

    names: tuple[str, ...]
    h: float
    pos: np.ndarray
    theta: np.ndarray
    vel: np.ndarray
    seen: np.ndarray | None
    believed: np.ndarray | None
    offset: np.ndarray
    commanded: np.ndarray
    leader: int
    tracks_reference: np.ndarray
    avoid_candidates: np.ndarray
    law: Any
    law_params: dict[str, Any]
    law_memory: dict[str, Any]
    reference: Any
    context: dict[str, Any] = field(default_factory=dict)

    def law_context(
        self,
        t: float,
        offset: np.ndarray,
        memory: dict[str, Any],
        leader: int | None = None,
        params: dict[str, Any] | None = None,
    ) -> LawContext:
        """What the law sees at ``t`` with ``offset`` and ``memory``.

        The followers read the leader's believed pose (the truth without sensing);
        ``leader`` and ``params`` default to the formation's.
        """
        lead = self.leader if leader is None else leader
        seen = self.believed
        if lead < 0:
            leader_pos = leader_theta = None
        elif seen is None:
            leader_pos, leader_theta = self.pos[lead], float(self.theta[lead])
        else:
            leader_pos, leader_theta = seen[lead, :2], float(seen[lead, 2])
        ref = self.reference.evaluate(t) if self.reference is not None else None
        return LawContext(
            t=t,
            dt=self.h,
            pos=self.pos,
            theta=self.theta,
            vel=self.vel,
            offset=offset,
            leader=lead,
            leader_pos=leader_pos,
            leader_theta=leader_theta,
            reference=ref,
            params=self.law_params if params is None else params,
            memory=memory,
            **self.context,
        )

    def positions(self) -> np.ndarray:
        """The positions every vehicle agrees on: the broadcast copies, or the truth."""
        return self.pos if self.seen is None else self.seen[:, :2]


@dataclass(frozen=True)
class Reform:
    """What a reconfiguration changes at an event; the loop applies it.

    Attributes
    ----------
    reset_shift : bool
        Restart the estimate of the recovery shift now (the period after an event).
    offset : ndarray, shape (n, 2) [m], or None
        The new offsets (NaN: no slot); None: unchanged, and so are the fields below.
    leader : int
        The vehicle that leads (-1: none).
    law : object
        The law, re-seeded on the new configuration (or the virtual leader's).
    law_params, law_memory : dict
    tracks_reference, avoid_candidates : ndarray, shape (n,), bool
    """

    reset_shift: bool = False
    offset: np.ndarray | None = None
    leader: int = -1
    law: Any = None
    law_params: dict[str, Any] | None = None
    law_memory: dict[str, Any] | None = None
    tracks_reference: np.ndarray | None = None
    avoid_candidates: np.ndarray | None = None

    @property
    def re_formed(self) -> bool:
        """Whether the configuration changed (a new leader, law or offsets)."""
        return self.offset is not None


class Reconfiguration:
    """Slot assignment and leader handover of one formation, updated on events.

    Build it with :meth:`build` (None when the scenario asks for neither).

    Parameters
    ----------
    scenario : Scenario
        The formation's scenario (its ``reconfigure``, ``on_leader_failure``,
        ``formation`` and ``recovery``).
    names : sequence of str
        The vehicles' names, in row order.
    offset : ndarray, shape (n, 2) [m]
        The offsets at the start: slot ``k`` is row ``k``'s (NaN: no slot).
    commanded : ndarray, shape (n,), bool
        The vehicles driven open loop (they hold no slot).
    leader : int
        The vehicle that leads at the start (-1: none).
    tracks_reference : ndarray, shape (n,), bool
        The vehicles that track the reference at the start.

    Attributes
    ----------
    formation : ndarray, shape (n, 2) [m]
        The slots' offsets, in formation order.
    slot_of : ndarray, shape (n,), int
        The slot each vehicle tracks, -1 for none.
    reassignments, leader_changes : list of dict
        The recorded events (:meth:`records`).
    slots : dict of str to list
        Each vehicle's slots over time: ``[[t, slot or None], ...]`` by name.
    """

    def __init__(
        self,
        scenario: Scenario,
        names: Sequence[str],
        offset: np.ndarray,
        commanded: np.ndarray,
        leader: int,
        tracks_reference: np.ndarray,
    ) -> None:
        sc, n = scenario, len(names)
        self.assign = sc.reconfigure.assign
        self.close_gap = sc.reconfigure.close_gap
        self.on_leader_failure = sc.on_leader_failure
        self.frame = get("law", sc.formation.law).options["frame"]
        self.leader_avoids = sc.recovery.leader_avoids
        self.formation = np.array(offset, dtype=float)
        # A slot is an offset: a vehicle without one (open loop, or left without a
        # slot before a merge or split formed this platoon) holds none.
        self.slot_of = np.where(
            commanded | ~np.isfinite(self.formation).all(axis=1), -1, np.arange(n)
        )
        #: Which slots exist (a finite offset of a vehicle not driven open loop).
        self.slot_exists = self.slot_of >= 0
        #: The slot of the vehicle that tracks the reference (-1: none).
        self.leader_slot = leader if leader >= 0 and tracks_reference[leader] else -1
        #: The slot each failed vehicle held when it failed (kept empty).
        self.held: dict[int, int] = {}
        self.known = np.zeros(n, dtype=bool)
        self._reset_shift = False
        self.reassignments: list[dict[str, Any]] = []
        self.leader_changes: list[dict[str, Any]] = []
        self.slots: dict[str, list[list]] = {
            name: [[0.0, _slot(self.slot_of[i])]] for i, name in enumerate(names)
        }

    @classmethod
    def build(
        cls,
        scenario: Scenario,
        names: Sequence[str],
        offset: np.ndarray,
        commanded: np.ndarray,
        leader: int,
        tracks_reference: np.ndarray,
        law: Any,
    ) -> Reconfiguration | None:
        """The formation's reconfiguration, or None (today's behaviour, untouched).

        None without a law (``law`` None) or with neither ``reconfigure:`` nor
        ``on_leader_failure:``; the other parameters as for the class.
        """
        sc = scenario
        if law is None or (
            sc.reconfigure.assign == "none" and sc.on_leader_failure == "keep"
        ):
            return None
        return cls(scenario, names, offset, commanded, leader, tracks_reference)

    def records(self) -> dict[str, Any]:
        """The run's ``reassignments``, ``leader_changes`` and ``slots``, kept here.

        The lists and the dict are this reconfiguration's own, filled as events
        come (a description may hold them from the start).
        """
        return {
            "reassignments": self.reassignments,
            "leader_changes": self.leader_changes,
            "slots": self.slots,
        }

    # ------------------------------------------------------------------ the event
    @property
    def waiting(self) -> bool:
        """Whether :meth:`react` has work at the next period even without a change.

        The period after an event restarts the estimate of the recovery shift.
        """
        return self._reset_shift

    def react(
        self, state: FormationState, t: float, known: np.ndarray
    ) -> Reform | None:
        """Handle a change of the believed failures at ``t_k``, from ``t_k+1`` on.

        The plan of ``t_k`` is kept (the law has already been evaluated for it); the
        new leader, law and offsets act from the next period, 10 ms later at h =
        0.01 s, with the law's estimators re-seeded at ``t_k`` on the new
        configuration. Nothing happens unless ``known`` differs from the last call's
        or :attr:`waiting` is true, so a loop may skip the call otherwise.

        Parameters
        ----------
        state : FormationState
            The formation now.
        t : float [s]
        known : ndarray, shape (n,), bool
            The vehicles believed failed now.

        Returns
        -------
        Reform or None
            What changes (None: nothing).
        """
        reset = self._reset_shift  # the first target of the new slots: restart there
        self._reset_shift = False
        known = np.asarray(known, dtype=bool)
        if np.array_equal(known, self.known):
            return Reform(reset_shift=True) if reset else None
        for i in np.flatnonzero(known & ~self.known):
            if self.slot_of[i] >= 0 and self.slot_of[i] != self.leader_slot:
                self.held[int(i)] = int(self.slot_of[i])
        for i in np.flatnonzero(~known & self.known):
            self.held.pop(int(i), None)
        self.known = known.copy()
        now = _Now(state)
        changed = False
        lead = state.leader
        if self.on_leader_failure != "keep" and lead >= 0 and known[lead]:
            changed = self._hand_over(state, now, t, lead)
        if self.assign == "hungarian":
            self._reassign(state, now, t)
            changed = True
        if not changed:
            return Reform(reset_shift=True) if reset else None
        offset = self._apply(state, now, t)
        self._record_slots(state, t)
        return Reform(
            reset_shift=reset,
            offset=offset,
            leader=now.leader,
            law=now.law,
            law_params=now.law_params,
            law_memory=now.law_memory,
            tracks_reference=now.tracks_reference,
            avoid_candidates=now.avoid_candidates,
        )

    # ------------------------------------------------------------------ handover
    def _hand_over(self, state: FormationState, now: _Now, t: float, lead: int) -> bool:
        """Replace the failed leader ``lead``; False if no vehicle can take over."""
        if self.on_leader_failure == "virtual":
            if self.frame == "world":
                rotate = False
            elif self.frame in ("reference", "leader_reference"):
                rotate = bool(now.law_params.get("rotate", False))
            else:  # offsets in the leader's frame: turned with the reference
                rotate = True
            now.law_params = {"rotate": rotate}
            now.law = make_law("virtual", now.law_params, now.offset, state.h)
            # The tangent of eq. (15) until the reference moves: the leader's heading.
            now.law._tangent = float(state.theta[lead])
            now.law_memory = {}
            self._set_leader(state, now, -1)
            self.held[lead] = self.leader_slot  # empty unless a gap closes
            self.leader_slot = -1  # the leader's slot is an ordinary one now
            new = None
        else:
            healthy = ~self.known & ~state.commanded
            healthy[lead] = False
            rows = np.flatnonzero(healthy)
            if len(rows) == 0 or state.reference is None:
                return False
            point = state.reference.evaluate(t)[0]
            seen = state.positions()[rows] - point
            new = int(rows[np.argmin(seen[:, 0] ** 2 + seen[:, 1] ** 2)])
            self.held.pop(new, None)
            self.slot_of[new] = self.leader_slot
            self._set_leader(state, now, new)
        self.slot_of[lead] = -1 if new is not None else self.slot_of[lead]
        self.leader_changes.append(
            {
                "t": round(t, 9),
                "from": state.names[lead],
                "to": None if new is None else state.names[new],
                "mode": self.on_leader_failure,
            }
        )
        return True

    def _set_leader(self, state: FormationState, now: _Now, new: int) -> None:
        """Make ``new`` (-1: none) the vehicle that leads and tracks the reference."""
        old = now.leader
        now.tracks_reference[:] = False
        if new >= 0:
            now.tracks_reference[new] = True
        now.avoid_candidates[old] = not state.commanded[old]
        if new >= 0:
            now.avoid_candidates[new] = self.leader_avoids
        now.leader = new

    # ------------------------------------------------------------------ assignment
    def _reassign(self, state: FormationState, now: _Now, t: float) -> None:
        """Healthy vehicles to slots, minimum total squared distance (Hungarian)."""
        n = len(state.names)
        movable = ~self.known & ~state.commanded
        if now.leader >= 0 and now.tracks_reference[now.leader]:
            movable[now.leader] = False
        rows = np.flatnonzero(movable)
        free = [j for j in range(n) if self.slot_exists[j] and j != self.leader_slot]
        if self.close_gap:
            cols = np.array(free[: len(rows)], dtype=np.intp)
        else:
            held = set(self.held.values())
            cols = np.array([j for j in free if j not in held], dtype=np.intp)
        for i in range(n):  # everyone but the leader loses the slot, then assigned
            if i != now.leader or not now.tracks_reference[i]:
                self.slot_of[i] = -1 if not state.commanded[i] else self.slot_of[i]
        if len(rows) and len(cols):
            from scipy.optimize import linear_sum_assignment  # only at an event

            where = self._slot_points(state, now, t)[cols]
            rel = state.positions()[rows, None, :] - where[None, :, :]
            cost = rel[..., 0] ** 2 + rel[..., 1] ** 2  # [m^2]
            r, c = linear_sum_assignment(cost)
            self.slot_of[rows[r]] = cols[c]
        self.reassignments.append(
            {
                "t": round(t, 9),
                "assignment": {
                    name: (int(self.slot_of[i]) if self.slot_of[i] >= 0 else None)
                    for i, name in enumerate(state.names)
                },
            }
        )

    def _slot_points(self, state: FormationState, now: _Now, t: float) -> np.ndarray:
        """Where every formation slot is at ``t``, shape (n, 2) [m].

        The law evaluated on a copy (its memory untouched) with the formation's
        offsets, around the current leader (or the reference, law ``virtual``).
        """
        law = copy.deepcopy(now.law)
        if hasattr(law, "delta"):
            law.delta = self.formation.copy()
        ctx = state.law_context(
            t,
            self.formation.copy(),
            copy.deepcopy(now.law_memory),
            leader=now.leader,
            params=now.law_params,
        )
        slot = np.array(law.targets(ctx)[0], dtype=float)
        if self.leader_slot >= 0 and ctx.reference is not None:
            slot[self.leader_slot] = ctx.reference[0]  # the leader's: the reference
        return slot

    def _record_slots(self, state: FormationState, t: float) -> None:
        """Append the slots that changed, held from the next period ``t + dt``."""
        start = round(t + state.h, 9)
        for i, name in enumerate(state.names):
            slot = _slot(self.slot_of[i])
            if self.slots[name][-1][1] != slot:
                self.slots[name].append([start, slot])

    # ------------------------------------------------------------------ applying
    def _apply(self, state: FormationState, now: _Now, t: float) -> np.ndarray:
        """Offsets from the assignment; the estimators re-seeded on them at ``t``."""
        offset = now.offset.copy()
        has = self.slot_of >= 0
        offset[has] = self.formation[self.slot_of[has]]
        offset[~has & ~state.commanded] = np.nan  # no slot
        law = now.law
        if hasattr(law, "delta"):
            law.delta = offset
        if hasattr(law, "reseed"):
            law.reseed()
        now.law_memory = {}  # the law's memory starts afresh with its estimators
        # Re-seed: the law's differences start from the new configuration at t_k
        # (the next period's velocity is a first difference, never a jump / h).
        law.targets(
            state.law_context(
                t, offset, now.law_memory, leader=now.leader, params=now.law_params
            )
        )
        self._reset_shift = True
        return offset


class _Now:
    """The formation being changed at an event: the state's values, then the new."""

    def __init__(self, state: FormationState) -> None:
        self.offset = state.offset
        self.leader = state.leader
        self.law = state.law
        self.law_params = state.law_params
        self.law_memory = state.law_memory
        self.tracks_reference = state.tracks_reference.copy()
        self.avoid_candidates = state.avoid_candidates.copy()


def _slot(k: int) -> int | None:
    """A slot index as recorded: an int, or None for no slot (-1)."""
    return int(k) if k >= 0 else None
