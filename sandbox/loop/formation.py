"""The formation of K worlds: each vehicle's slot, who leads, who tracks, who avoids.

:class:`Formation` is the plan's first part (eqs. (7)-(20)): every period it
evaluates the reference and the formation law of every world into each vehicle's
slot, ``x_ref'`` and ``x_ref''`` (:meth:`Formation.targets`), and at a change of what
a world's platoon believes has failed it lets the world's reconfiguration re-form it
(:meth:`Formation.react`, :mod:`sandbox.behaviour.reconfigure`), applying what the
reconfiguration returns. How a law is evaluated is chosen when the loop is built:

- **one law of all worlds** on arrays with a leading world axis: a built-in law
  class (which reads only its leader's pose and the reference,
  :class:`~sandbox.model.laws.LawInputs`; its period in one C call where
  :mod:`sandbox.loop.plan_kernel` covers it) or a plug-in registered with
  ``batched=True``; a built-in law of worlds that re-form apart keeps one law too,
  a leader and an estimator history per world (:mod:`sandbox.loop.reforming`);
- **each world's own law** on its rows: a plug-in without ``batched=True``, and a
  batched plug-in while its worlds can re-form (the loop knows no plug-in's state);
- **each world's platoons** (``platoons:``, :mod:`sandbox.loop.platoons`);
- **none**: no ``formation:``, every vehicle tracks the reference.

Then the reference-tracking rows take the reference and the open-loop rows a NaN
slot. A plug-in that fails ends its world alone (``failed(w, exc)``).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from sandbox.behaviour.reconfigure import FormationState, Reconfiguration, Reform
from sandbox.errors import PluginRunError
from sandbox.loop.layout import Layout
from sandbox.loop.liveness import Failed
from sandbox.loop.platoon_targets import platoon_targets
from sandbox.loop.platoons import Platoons
from sandbox.loop.reference_rows import ReferenceRows
from sandbox.loop.reforming import ReformingLaw, law_context, leader_pose
from sandbox.loop.state import Fleet
from sandbox.model.law_kernel import overwrite_rows
from sandbox.model.laws import LawInputs, spread
from sandbox.model.references import TABULATED_REFERENCES
from sandbox.plugins.registration import LawContext, get, make_law


class Formation:
    """The formation of a loop's K worlds (see the module docstring).

    Parameters
    ----------
    layout : Layout
    fleet : Fleet
        The fleet at the start (its offsets: the laws' ``delta``, a view).
    context : callable
        ``context(w)``: the further fields of a law's context, the range readings
        (``w`` None: of every world's rows).
    """

    def __init__(self, layout: Layout, fleet: Fleet, context: Callable) -> None:
        self._layout = layout
        self._context = context
        K, n, h = layout.K, layout.n, layout.h
        scenarios = layout.scenarios
        first = scenarios[0]
        spec = first.formation
        #: The worlds' reference (one: their structure), None without one.
        self.reference = first.reference.build() if first.reference else None
        #: The reference row by row, evaluated a chunk at a time (tabulated types).
        self.rows: ReferenceRows | None = None
        if type(self.reference) in TABULATED_REFERENCES:
            self.rows = ReferenceRows(self.reference, h, layout.steps, K)
        #: Each world's leader (-1: none), as its reconfiguration last set it.
        self.leaders = np.array([sc.leader_index for sc in scenarios], dtype=np.intp)
        plugin = get("law", spec.law) if spec is not None else None
        built_in = plugin is not None and plugin.origin.startswith("built-in")
        reforming = spec is not None and (
            first.reconfigure.assign != "none" or first.on_leader_failure != "keep"
        )
        batched = plugin is not None and bool(plugin.options.get("batched", False))
        #: A built-in law class: it reads its leader and the reference only.
        self.inputs = built_in and inspect.isclass(plugin.obj)
        #: Whether each world's own law is evaluated on its rows (module docstring):
        #: worlds that re-form apart share one law only where it is a built-in law
        #: class, whose state the loop knows (:mod:`sandbox.loop.reforming`).
        self.per_world = plugin is not None and (
            not batched or (reforming and not self.inputs)
        )
        offset = fleet.offset
        # Each world's own law, on its rows alone: evaluated world by world, or what
        # its reconfiguration acts on.
        self.laws = [
            make_law(spec.law, spec.params, offset[layout.rows(w)].copy(), h)
            if spec is not None
            else None
            for w in range(K)
        ]
        self.params = [dict(spec.params) if spec else {} for _ in range(K)]
        self.memory: list[dict] = [{} for _ in range(K)]
        #: The one law of every world (None: none, or each world's own).
        self.law: Any = None
        #: The one law of worlds that re-form apart (:mod:`sandbox.loop.reforming`).
        self.reforming: ReformingLaw | None = None
        #: The one law's values and memory.
        self.law_params = dict(spec.params) if spec else {}
        self.law_memory: dict = {}
        if spec is not None and not self.per_world:
            shape = offset.reshape(K, n, 2)  # a view: events write the fleet's rows
            if reforming:  # built-in and batched here
                self.reforming = ReformingLaw(spec, shape, h, self.leaders, self.laws)
                self.law = self.reforming.law
            else:
                self.law = make_law(spec.law, spec.params, shape, h)
        # Who tracks the reference (the leader, or everyone without a law) and who
        # may avoid (not open loop, not a leader that does not avoid), each row.
        tracks, avoid = [], []
        for w, sc in enumerate(scenarios):
            commanded = fleet.commanded[layout.rows(w)]
            lead = sc.leader_index
            mine = np.zeros(n, dtype=bool)
            if spec is None:
                mine[:] = True
            elif plugin.options["needs_leader"] and lead >= 0:
                mine[lead] = True
            tracks.append(mine & ~commanded)
            free = ~commanded
            if not sc.recovery.leader_avoids and lead >= 0:
                free[lead] = False
            avoid.append(free)
        self.tracks_reference = np.concatenate(tracks)
        self.track_rows = np.flatnonzero(self.tracks_reference)
        self.commanded_rows = np.flatnonzero(fleet.commanded)
        self.avoid_candidates = np.concatenate(avoid)
        #: Each world's platoons (``platoons:``), None with one platoon.
        self.platoons: list[Platoons] | None = None
        if first.platoons:
            self.platoons = [
                Platoons(sc, offset[layout.rows(w)], fleet.commanded[layout.rows(w)], h)
                for w, sc in enumerate(scenarios)
            ]
        #: Each world's reconfiguration (None: its slots are kept).
        self.reconfigurations: list[Reconfiguration | None] = [
            Reconfiguration.build(
                sc,
                layout.names[w],
                offset[layout.rows(w)],
                fleet.commanded[layout.rows(w)],
                int(self.leaders[w]),
                self.tracks_reference[layout.rows(w)],
                self.laws[w],
            )
            for w, sc in enumerate(scenarios)
        ]
        self.reconfigurable = np.array(
            [r is not None for r in self.reconfigurations], dtype=bool
        )
        self.reconfiguring = bool(self.reconfigurable.any())
        # What each world's reconfiguration last saw, and the worlds it waits on.
        self._reacted = np.zeros(layout.N, dtype=bool)
        self._waiting: set[int] = set()
        #: The law's period in one C call (plan_kernel.py; set by the loop's build),
        #: and the reference's rows as it reads them.
        self.kernel: Any = None
        self.kernel_table: Callable[[tuple], Any] = tuple
        self._kernel_rows: tuple[int, Any] = (-1, None)

    # ------------------------------------------------------------------ the law
    def targets(
        self,
        t: float,
        k: int,
        fleet: Fleet,
        believed: np.ndarray | None,
        live: Sequence[int],
        failed: Failed,
    ) -> tuple[np.ndarray, ...]:
        """Slots, ``x_ref'``, ``x_ref''`` (N, 2) and each world's point (K, 2).

        Parameters
        ----------
        t : float [s]
            The time of period ``k``.
        k : int
        fleet : Fleet
        believed : ndarray, shape (N, 3), or None
            What the law sees of the leader (None: the truth).
        live : list of int
            The live worlds.
        failed : callable
            ``failed(w, exc)`` ends world ``w`` (its plug-in failed).
        """
        layout = self._layout
        K = layout.K
        if self.platoons is not None:  # each platoon's own reference and law
            return self._platoon_targets(t, fleet, believed, live)
        if self.kernel is not None:  # the law's period in one C call
            triple = self._kernel_targets(k, fleet, believed)
            if triple is not None:
                return triple
        if self.rows is not None:
            ref = self.rows.row(k)
        elif self.reference is not None:
            ref = self.reference.evaluate(t)
        else:
            ref = None
        if self.law is None and not self.per_world:
            N = layout.N
            triple = [np.zeros((N, 2)), np.zeros((N, 2)), np.zeros((N, 2))]
        elif self.per_world:
            triple = self._world_targets(t, ref, fleet, believed, live, failed)
        elif self.reforming is not None:
            triple = self.reforming.targets(
                layout, fleet.pos, fleet.theta, believed, ref
            )
        else:
            slot, v_ref, a_ref = self.law.targets(
                self._one_context(t, ref, fleet, believed)
            )
            if self.inputs:  # a built-in law class: (K, n, 2) float64 arrays
                N = layout.N
                triple = [slot.reshape(N, 2), v_ref.reshape(N, 2), a_ref.reshape(N, 2)]
            else:
                shape = (K, layout.n, 2)
                triple = [
                    world_rows(slot, shape),
                    world_rows(v_ref, shape),
                    world_rows(a_ref, shape),
                ]
        # the reference-tracking rows and the commanded ones (copies where any)
        slot, v_ref, a_ref = overwrite_rows(
            triple, ref, self.track_rows, self.commanded_rows
        )
        if self.rows is not None:  # the chunk's points of every world (a view)
            return slot, v_ref, a_ref, self.rows.points(k)
        point = ref[0] if ref is not None else np.full(2, np.nan)
        return slot, v_ref, a_ref, spread(point, (K, 2))

    def _kernel_targets(
        self, k: int, fleet: Fleet, believed: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        """:meth:`targets` by the law's C call (plan_kernel.py); None: use numpy.

        Not for a law replaced since, or whose ``targets`` was (a spy, a wrapper).
        """
        law = self.law
        if law is not self.kernel.law or "targets" in law.__dict__:
            return None
        if believed is None:
            pose, theta = fleet.pos, fleet.theta
        else:
            pose, theta = believed, None
        table, row = None, k
        if self.rows is not None:
            chunk, row = self.rows.chunk(k)
            start = self.rows.start
            if self._kernel_rows[0] != start:  # the chunk as the C call reads it
                self._kernel_rows = (start, self.kernel_table(chunk))
            table = self._kernel_rows[1]
        try:
            slot, v_ref, a_ref = self.kernel.targets(
                pose, theta, table, row, self.track_rows, self.commanded_rows
            )
        except (BufferError, TypeError, ValueError):  # not such arrays: numpy
            return None
        if table is None:
            return slot, v_ref, a_ref, spread(np.full(2, np.nan), (self._layout.K, 2))
        return slot, v_ref, a_ref, self.rows.points_of(row)

    def _one_context(
        self, t: float, ref: tuple | None, fleet: Fleet, believed: np.ndarray | None
    ) -> LawContext | LawInputs:
        """What the one law of all worlds sees: arrays with a leading world axis.

        A built-in law class gets the part it reads (its leader and the reference).
        """
        layout, lead = self._layout, int(self.leaders[0])
        if self.inputs:
            _, leader_pos, leader_theta = leader_pose(
                layout, fleet.pos, fleet.theta, believed, lead
            )
            return LawInputs(leader_pos, leader_theta, ref)
        return law_context(
            layout,
            t,
            fleet.pos,
            fleet.theta,
            fleet.vel,
            fleet.offset,
            believed,
            ref,
            lead,
            self.law_params,
            self.law_memory,
            **self._context(None),
        )

    def _world_targets(
        self,
        t: float,
        ref: tuple | None,
        fleet: Fleet,
        believed: np.ndarray | None,
        live: Sequence[int],
        failed: Failed,
    ) -> list[np.ndarray]:
        """Each world's own law on its rows (a plug-in's, see the module docstring)."""
        layout = self._layout
        out = [np.zeros((layout.N, 2)) for _ in range(3)]
        for w in live:
            rows = layout.rows(w)
            ctx = self.world_context(w, t, ref, fleet, believed)
            try:
                parts = self.laws[w].targets(ctx)
            except PluginRunError as exc:
                failed(w, exc)
                continue
            for a, part in zip(out, parts, strict=True):
                a[rows] = part
        return out

    def world_context(
        self,
        w: int,
        t: float,
        ref: tuple | None,
        fleet: Fleet,
        believed: np.ndarray | None,
        offset: np.ndarray | None = None,
        memory: dict | None = None,
    ) -> LawContext:
        """What world ``w``'s own law sees at ``t`` (the reference ``ref``).

        The followers read the leader's believed pose (the truth without sensing).
        ``offset`` and ``memory`` default to the world's offsets and law memory.
        """
        rows = self._layout.rows(w)
        lead = int(self.leaders[w])
        seen = None if believed is None else believed[rows]
        pos, theta = fleet.pos[rows], fleet.theta[rows]
        if lead < 0:
            leader_pos = leader_theta = None
        elif seen is None:
            leader_pos, leader_theta = pos[lead], float(theta[lead])
        else:
            leader_pos, leader_theta = seen[lead, :2], float(seen[lead, 2])
        return LawContext(
            t=t,
            dt=self._layout.h,
            pos=pos,
            theta=theta,
            vel=fleet.vel[rows],
            offset=fleet.offset[rows] if offset is None else offset,
            leader=lead,
            leader_pos=leader_pos,
            leader_theta=leader_theta,
            reference=ref,
            params=self.params[w],
            memory=self.memory[w] if memory is None else memory,
            **self._context(w),
        )

    def _platoon_targets(
        self, t: float, fleet: Fleet, believed: np.ndarray | None, live: Sequence[int]
    ) -> tuple[np.ndarray, ...]:
        """Each world's platoons' slots, ``x_ref'``, ``x_ref''`` and points.

        Each live world's merges, splits and reconfigurations first (prepared by
        :meth:`prepare_platoons`); then the laws of all worlds' platoons together
        (loop/platoon_targets.py).
        """
        layout = self._layout
        worlds = [(w, self.platoons[w]) for w in live]
        return platoon_targets(
            worlds,
            t,
            fleet.pos,
            fleet.theta,
            fleet.vel,
            believed,
            layout.n,
            layout.K,
        )

    # ------------------------------------------------------------------ events
    def _state(
        self,
        w: int,
        fleet: Fleet,
        seen: np.ndarray | None,
        believed: np.ndarray | None,
        law: Any,
    ) -> FormationState:
        """World ``w``'s formation as its reconfiguration reads it."""
        rows = self._layout.rows(w)
        return FormationState(
            names=self._layout.names[w],
            h=self._layout.h,
            pos=fleet.pos[rows],
            theta=fleet.theta[rows],
            vel=fleet.vel[rows],
            seen=None if seen is None else seen[rows],
            believed=None if believed is None else believed[rows],
            offset=fleet.offset[rows].copy(),
            commanded=fleet.commanded[rows],
            leader=int(self.leaders[w]),
            tracks_reference=self.tracks_reference[rows],
            avoid_candidates=self.avoid_candidates[rows],
            law=law,
            law_params=self.params[w],
            law_memory=self.memory[w],
            reference=self.reference,
            context=self._context(w),
        )

    def react(
        self,
        t: float,
        known: np.ndarray,
        fleet: Fleet,
        seen: np.ndarray | None,
        believed: np.ndarray | None,
        live: np.ndarray,
        failed: Failed,
    ) -> list[int]:
        """Each world's reconfiguration reacts to what its platoon believes.

        Only the worlds with something to do are called: those whose belief changed
        since their last call and those waiting for the period after an event
        (:attr:`~sandbox.behaviour.reconfigure.Reconfiguration.waiting`). What a
        reconfiguration returns is applied here (its new offsets written into
        ``fleet.offset``); a world that re-formed hands its new leader and
        estimators to the one law. Returns the worlds whose recovery shift's
        estimate restarts now.
        """
        layout = self._layout
        K, n = layout.K, layout.n
        due = (known != self._reacted).reshape(K, n).any(axis=1)
        due[list(self._waiting)] = True
        due &= live & self.reconfigurable
        if not due.any():
            return []
        self._waiting = set()
        restart = []
        for w in map(int, np.flatnonzero(due)):
            rows = layout.rows(w)
            reconfiguration = self.reconfigurations[w]
            law = self.laws[w]
            if self.reforming is not None:
                law = self.reforming.before_event(w)
            state = self._state(w, fleet, seen, believed, law)
            try:
                reform = reconfiguration.react(state, t, known[rows])
            except PluginRunError as exc:  # the world ends as it was
                failed(w, exc)
                reform = None
            self._reacted[rows] = known[rows]
            if reconfiguration.waiting:
                self._waiting.add(w)
            if reform is None:
                continue
            if reform.reset_shift:
                restart.append(w)
            if reform.re_formed:
                self._apply(w, reform, fleet)
        self.track_rows = np.flatnonzero(self.tracks_reference)
        return restart

    def _apply(self, w: int, reform: Reform, fleet: Fleet) -> None:
        """World ``w`` takes the configuration its reconfiguration made."""
        rows = self._layout.rows(w)
        fleet.offset[rows] = reform.offset
        self.tracks_reference[rows] = reform.tracks_reference
        self.avoid_candidates[rows] = reform.avoid_candidates
        self.laws[w] = reform.law
        self.params[w] = reform.law_params
        self.memory[w] = reform.law_memory
        if self.reforming is not None:
            self.reforming.after_event(w, reform.law, reform.leader)
        self.leaders[w] = reform.leader

    # ------------------------------------------------------------------ platoons
    def prepare_platoons(
        self,
        t: float,
        fleet: Fleet,
        seen: np.ndarray | None,
        believed: np.ndarray | None,
        known: np.ndarray,
        live: Sequence[int],
        info: list[dict],
    ) -> list[int]:
        """Each live world's platoons: the merges, splits and reconfigurations of ``t``.

        Their records are written into the worlds' descriptions ``info``; who may
        avoid is taken from each world's platoons. Returns the worlds whose recovery
        shift's estimate restarts now.
        """
        layout = self._layout
        restart = []
        for w in live:
            rows = layout.rows(w)
            platoons = self.platoons[w]
            change = platoons.prepare(
                t,
                fleet.pos[rows],
                fleet.theta[rows],
                fleet.vel[rows],
                None if seen is None else seen[rows],
                None if believed is None else believed[rows],
                known[rows],
            )
            if change.records is not None:
                info[w].update(change.records)
            if change.reset_shift:
                restart.append(w)
        return restart

    def platoon_candidates(self) -> np.ndarray:
        """Who may avoid in every world, as its platoons decide (their leaders)."""
        n = self._layout.n
        for w, platoons in enumerate(self.platoons):
            self.avoid_candidates[w * n : (w + 1) * n] = platoons.avoid_candidates
        return self.avoid_candidates


def world_rows(a: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """A law's array of every world, shape (K, n, 2) or broadcasting to it, as rows.

    Float64, shape (K n, 2): a view where it is float64 of the shape, else a new
    array of its values.
    """
    a = np.asarray(a, dtype=float)
    return (a if a.shape == shape else spread(a, shape)).reshape(-1, 2)
