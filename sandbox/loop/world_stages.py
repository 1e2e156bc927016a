"""The stages the loop runs world by world, each on its world's rows.

What is not a function of the stacked rows of all worlds: a formation law or a
strategy registered without ``batched=True`` (and a plug-in law while its world can
re-form), a detector or a safety filter without it, and a reconfiguration's events.
Each is called with the world's
:class:`~sandbox.loop.worlds.WorldState` (its fleet viewing the world's rows) or a
context of those rows, inside the one pass of the loop; a plug-in that fails there
ends its world alone. :class:`WorldStages` is a part of
:class:`~sandbox.loop.simulation.Simulation`, kept apart for its length.
"""

from __future__ import annotations

import numpy as np

from sandbox.behaviour.ranges import avoid_field, context_fields
from sandbox.errors import PluginRunError
from sandbox.loop.platoon_targets import platoon_targets
from sandbox.plugins.registration import FilterContext, StrategyContext


class WorldStages:
    """The world-by-world stages of :class:`~sandbox.loop.simulation.Simulation`."""

    # ------------------------------------------------------------------ views
    def _view_worlds(self) -> None:
        """Point each world's fleet (and seen poses) at its rows of the stacked arrays.

        Done once per period before the first world-by-world stage; a stage may
        replace a world's arrays (a reconfiguration sets new offsets).
        """
        if self._views_at == self.k and self.K > 1:
            return
        self._views_at = self.k
        fl, n = self.fleet, self.n
        if self.K == 1:
            s = self.states[0]
            s.fleet, s.seen, s.known_failed = fl, self.seen, self.known_failed
            s.believed = self.believed
            return
        for w, s in enumerate(self.states):
            rows = slice(w * n, (w + 1) * n)
            f = s.fleet
            f.pos, f.theta, f.vel, f.chi = (
                fl.pos[rows],
                fl.theta[rows],
                fl.vel[rows],
                fl.chi[rows],
            )
            f.v1, f.v2, f.mode, f.failed = (
                fl.v1[rows],
                fl.v2[rows],
                fl.mode[rows],
                fl.failed[rows],
            )
            s.seen = None if self.seen is None else self.seen[rows]
            s.believed = None if self.believed is None else self.believed[rows]
            s.known_failed = self.known_failed[rows]

    def _rows(self, w: int) -> slice:
        return slice(w * self.n, (w + 1) * self.n)

    def _live_worlds(self) -> list[int]:
        """The live worlds in order (a new list; remade only after a world ends)."""
        count = self._n_live
        cached = getattr(self, "_live_cache", None)
        if cached is None or len(cached) != count:
            cached = self._live_cache = [int(w) for w in self.live.nonzero()[0]]
        return list(cached)

    def _platoon_targets(self, t: float) -> tuple[np.ndarray, ...]:
        """Each world's platoons' slots, ``x_ref'``, ``x_ref''`` and points.

        Each live world's merges, splits and reconfigurations first, world by world;
        then the laws of all worlds' platoons together (loop/platoon_targets.py).
        """
        fl = self.fleet
        worlds = []
        for w in self._live_worlds():
            s, rows = self.states[w], self._rows(w)
            s.platoons.prepare(t, fl.pos[rows], fl.theta[rows], fl.vel[rows])
            worlds.append((w, s.platoons))
        return platoon_targets(
            worlds, t, fl.pos, fl.theta, fl.vel, self.believed, self.n, self.K
        )

    def _world_law_targets(self, t: float, ref: tuple | None) -> list[np.ndarray]:
        """Each world's own law on its rows (plug-in laws, a single re-forming run)."""
        self._view_worlds()
        out = [np.zeros((self.N, 2)) for _ in range(3)]
        for w in self._live_worlds():
            s, rows = self.states[w], self._rows(w)
            try:
                parts = s.law.targets(s.law_context(t, ref))
            except PluginRunError as exc:
                self._plugin_failed(w, exc)
                continue
            for a, part in zip(out, parts, strict=True):
                a[rows] = part
        return out

    def _world_strategy(self, t, slot, may_avoid, known) -> tuple[np.ndarray, ...]:
        """A strategy without ``batched=True``, called world by world."""
        self._view_worlds()
        shift, active = np.zeros((self.N, 2)), np.zeros(self.N, dtype=bool)
        for w in self._live_worlds():
            s, rows = self.states[w], self._rows(w)
            f = s.fleet
            ctx = StrategyContext(
                t=t,
                dt=self.h,
                pos=f.pos,
                theta=f.theta,
                vel=f.vel,
                slot=slot[rows],
                diameter=self.fleet.diameter[rows],
                may_avoid=may_avoid[rows],
                failed=known[rows],
                params=s.strategy_params,
                R=s.rec.R,
                obstacle_field=avoid_field(s.range_sensor, s.obstacles, s.rec),
                neighbours=s.neighbours,
                seen_pos=None if s.believed is None else s.believed[:, :2],
                **context_fields(s.range_sensor),
            )
            try:
                out = s.strategy(ctx)
            except PluginRunError as exc:
                self._plugin_failed(w, exc)
                continue
            shift[rows], active[rows] = out[0], out[1]
        return shift, active

    def _detect_batched(self, t: float, failing: np.ndarray) -> np.ndarray:
        """One call of a batched detector on the rows of all worlds."""
        fl, n = self.fleet, self.n
        if self.seen is None:  # the true poses: np.column_stack's, in two copies
            seen, fresh = np.empty((len(fl.theta), 3)), None
            seen[:, :2], seen[:, 2] = fl.pos, fl.theta
        elif self._broadcast is not None:  # every world's, stacked
            seen, fresh = self.seen, self._broadcast.fresh
        else:
            seen = self.seen
            parts = [getattr(s.broadcast, "fresh", None) for s in self.states]
            fresh = np.concatenate(
                [np.ones(n, dtype=bool) if f is None else f for f in parts]
            )
        contact = self.physics.in_contact()
        return self._detection.update_rows(t, self.h, fl, seen, fresh, contact, failing)

    def _detect(self, t: float, failing: np.ndarray) -> np.ndarray:
        """Each world's detector: what its platoon believes has failed."""
        if self._detection is not None:
            return self._detect_batched(t, failing)
        self._view_worlds()
        known = np.zeros(self.N, dtype=bool)
        for w in self._live_worlds():
            s, rows = self.states[w], self._rows(w)
            try:
                known[rows] = s.detection.update(s, t, failing[rows])
            except PluginRunError as exc:
                self._plugin_failed(w, exc)
        return known

    def _reconfigure(self, t: float, known: np.ndarray) -> None:
        """Each world's reconfiguration reacts to what its platoon believes.

        Only the worlds with something to do are called: those whose belief changed
        since their last call and those waiting for the period after an event
        (:attr:`~sandbox.behaviour.reconfigure.Reconfiguration.waiting`). A world
        that re-formed hands its new leader and estimators to the stacked law.
        """
        K, n, stacked = self.K, self.n, self._stacked_law
        due = (known != self._reacted).reshape(K, n).any(axis=1)
        due[list(self._waiting)] = True
        due &= self.live & self._reconfigurable
        if not due.any():
            return
        self._view_worlds()
        self._waiting = set()
        for w in map(int, np.flatnonzero(due)):
            s, rows = self.states[w], self._rows(w)
            s.known_failed = known[rows]
            if stacked is not None:
                stacked.before_event(w, s)
            try:
                re_formed = s.reconfiguration.react(s, t, known[rows])
            except PluginRunError as exc:
                self._plugin_failed(w, exc)
                re_formed = False
            self.fleet.offset[rows] = s.fleet.offset
            self._reacted[rows] = known[rows]
            if s.reconfiguration.waiting:
                self._waiting.add(w)
            if re_formed and stacked is not None:
                stacked.after_event(w, s)
        self._track_rows = np.flatnonzero(self.tracks_reference)
        if self.K == 1:
            self.leader = self.states[0].leader
            self.law, self.law_params = self.states[0].law, self.states[0].law_params

    def _safety(
        self, t: float, v1: np.ndarray, v2: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The safety filter's commands for the period (``safety:``), world by world.

        A filter registered with ``batched=True`` is called once for a loop of K > 1
        worlds instead (:meth:`_safety_batched`).
        """
        started = self._filter_started
        self._filter_started = True
        if self.K > 1 and self._filter_batched:
            return self._safety_batched(t, v1, v2, started)
        self._view_worlds()
        fl = self.fleet
        v1_out, v2_out = v1.copy(), v2.copy()
        for w in self._live_worlds():
            s, rows = self.states[w], self._rows(w)
            f = s.fleet
            ctx = FilterContext(
                t=t,
                dt=self.h,
                pos=f.pos,
                theta=f.theta,
                vel=f.vel,
                v1=v1[rows],
                v2=v2[rows],
                diameter=fl.diameter[rows],
                params=dict(s.scenario.safety.params),
                v1_prev=fl.v1[rows] if started else None,
                v2_prev=fl.v2[rows] if started else None,
                v1_max=s.v1_max,
                v2_max=s.v2_max,
                accel_max=s.accel_max,
                known_failed=self.known_failed[rows],
                commanded=fl.commanded[rows],
                obstacle_field=avoid_field(s.range_sensor, s.obstacles, s.rec),
                seen=None if self.seen is None else self.seen[rows],
                sensing=None if s.broadcast is None else s.sensing,
                memory=s.filter_memory,
                stats=s.filter_stats,
                slot=self.plan.slot[rows],
                substeps=self.substeps,
                **context_fields(s.range_sensor),
            )
            try:
                out = (s.filter or self._filter)(ctx)
            except PluginRunError as exc:
                self._plugin_failed(w, exc)
                continue
            n = self.n
            v1_out[rows] = np.broadcast_to(np.asarray(out[0], dtype=float), (n,))
            v2_out[rows] = np.broadcast_to(np.asarray(out[1], dtype=float), (n,))
        return v1_out, v2_out

    def _safety_batched(
        self, t: float, v1: np.ndarray, v2: np.ndarray, started: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """One call of a batched filter on the rows of all worlds."""
        fl, s0 = self.fleet, self.states[0]
        ctx = FilterContext(
            t=t,
            dt=self.h,
            pos=fl.pos,
            theta=fl.theta,
            vel=fl.vel,
            v1=v1,
            v2=v2,
            diameter=fl.diameter,
            params=dict(s0.scenario.safety.params),
            v1_prev=fl.v1 if started else None,
            v2_prev=fl.v2 if started else None,
            v1_max=self._v1_max,
            v2_max=self._v2_max,
            accel_max=self._accel_max,
            known_failed=self.known_failed,
            commanded=fl.commanded,
            obstacle_field=self._avoid_field,
            seen=self.seen,
            sensing=None if s0.broadcast is None else s0.sensing,
            memory=self._filter_memory,
            worlds=self.K,
            world_stats=[s.filter_stats for s in self.states],
            slot=self.plan.slot,
            substeps=self.substeps,
            **context_fields(self.range_sensor),
        )
        out = self._filter(ctx)  # a PluginRunError ends every world (_guarded)
        return _rows_of(out[0], self.N), _rows_of(out[1], self.N)


def _rows_of(value: object, n: int) -> np.ndarray:
    """A filter's command as a new float array of ``n`` rows (a scalar broadcast).

    An array of ``n`` floats is copied as it is (what the broadcast gives it, without
    its cost).
    """
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (n,):
        return value.copy()
    return np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()
