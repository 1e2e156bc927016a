"""What each world of the loop keeps of its own, and the stacked schedules of K worlds.

The loop (:class:`~sandbox.loop.simulation.Simulation`) steps K worlds of one structure
on stacked arrays of ``K * n`` rows, world after world. What differs from world to
world and is not a row of those arrays lives in a :class:`WorldState`: the scenario,
names, status and description, the failure schedule, the broadcast and its random
stream, the detector, the reconfiguration, the safety filter's memory, and the law
itself when it is evaluated world by world. A stage that is not evaluated on the
stacked arrays (a plug-in without ``batched=True``, the detector, the reconfiguration,
the safety filter) is given the world's :class:`WorldState`, which carries the names a
single run's loop had (``fleet``, ``leader``, ``law``, ``seen``, ``world``, ...), with
``fleet`` viewing the world's rows of the stacked arrays.

:class:`StackedFailures` are the failure schedules of K worlds as one,
:class:`StackedCommands` their open-loop command schedules, and
:class:`StackedDifference` the backward differences of the recovery shift with a
history per world; the neighbour pairs of K worlds (never across worlds) are
:class:`~sandbox.geometry.neighbours.WorldPairs`.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Sequence
from dataclasses import asdict
from typing import Any

import numpy as np

from sandbox.behaviour.ranges import context_fields
from sandbox.behaviour.sensing import make_broadcast
from sandbox.errors import PluginRunError
from sandbox.geometry.neighbours import NeighbourList
from sandbox.loop.run_info import run_description
from sandbox.loop.state import Fleet, uniform
from sandbox.model.failures import (
    FailureSchedule,
    rule_of,
    ruled_commands,
    within_drive,
    within_drives,
)
from sandbox.model.obstacle_field import ObstacleField
from sandbox.physics.interface import Physics
from sandbox.plugins.registration import (
    FailureContext,
    LawContext,
    get,
    make_law,
    runnable,
)
from sandbox.run.record import STATUS_OK
from sandbox.scenario import Scenario


class WorldState:
    """One world of the loop: what it keeps of its own (see the module docstring).

    Parameters
    ----------
    scenario : Scenario
    world : Physics
        The world's physics.
    fleet : Fleet
        The world's fleet at ``t_0``; the loop re-points its arrays at the world's
        rows of the stacked ones before a world-by-world stage (:meth:`view`).
    """

    def __init__(self, scenario: Scenario, world: Physics, fleet: Fleet) -> None:
        sc = scenario
        self.scenario = sc
        self.world = world
        self.fleet = fleet
        self.h = sc.dt
        self.names = [v.name for v in sc.vehicles]
        self.leader = sc.leader_index
        self.reference = sc.reference.build() if sc.reference else None
        spec = sc.formation
        self.law = (
            make_law(spec.law, spec.params, fleet.offset, self.h) if spec else None
        )
        self.law_params = dict(spec.params) if spec else {}
        self.law_memory: dict = {}
        self.strategy = runnable(get("strategy", sc.recovery.strategy))
        self.strategy_params = dict(sc.recovery.params)
        self.rec = sc.recovery
        self.obstacles = ObstacleField(sc.obstacles)
        self.failures = FailureSchedule(sc.failures, self.names)
        self.broadcast = make_broadcast(sc.sensing, self.h, sc.seed)
        self.sensing = asdict(sc.sensing)
        #: The broadcast poses received at t_k, shape (n, 3), or None without sensing.
        self.seen: np.ndarray | None = None
        #: What the law and the recovery see of the others: ``seen``, or its estimate
        #: under the braking barrier (``Simulation.believed``).
        self.believed: np.ndarray | None = None
        self.known_failed = np.zeros(fleet.n, dtype=bool)
        # The limits as a single run of the world sees them (scalars when uniform).
        self.v1_max = uniform(fleet.v1_max)
        self.v2_max = uniform(fleet.v2_max)
        self.accel_max = uniform(fleet.accel_max)
        n = fleet.n
        tracks = np.zeros(n, dtype=bool)
        if self.law is None:
            tracks[:] = True
        elif get("law", spec.law).options["needs_leader"] and self.leader >= 0:
            tracks[self.leader] = True
        tracks &= ~fleet.commanded
        self.tracks_reference = tracks
        self._track_rows = np.flatnonzero(tracks)
        self._avoid_candidates = ~fleet.commanded
        if not self.rec.leader_avoids and self.leader >= 0:
            self._avoid_candidates[self.leader] = False
        self.status = STATUS_OK
        self.info = run_description(sc, self.reference)
        self.failed_at: dict[str, float] = {}
        self.filter_memory: dict = {}
        self.filter_stats: dict = {}
        self.neighbours = NeighbourList(self.rec.R)
        #: Set by the loop: the world's recovery-shift history, resettable alone.
        self.shift_motion: Any = None
        self.detection: Any = None
        self.reconfiguration: Any = None
        #: The world's range sensor, platoons and their filter (None: none).
        self.range_sensor: Any = None
        self.platoons: Any = None
        self.filter: Any = None
        self.schedules = {
            i: np.array(v.drive.schedule, dtype=float)
            for i, v in enumerate(sc.vehicles)
            if v.drive.type == "commands"
        }

    def law_context(
        self,
        t: float,
        ref: tuple[np.ndarray, ...] | None,
        offset: np.ndarray | None = None,
        memory: dict | None = None,
    ) -> LawContext:
        """What the world's formation law sees at ``t`` (the reference ``ref``).

        The followers read the leader's broadcast pose (the truth without sensing).
        ``offset`` and ``memory`` default to the fleet's offsets and the law's memory;
        a reconfiguration passes others to try or re-seed the law.
        """
        extra = context_fields(self.range_sensor)
        return law_context_of(self, t, ref, offset, memory, **extra)


def law_context_of(
    owner: Any,
    t: float,
    ref: tuple[np.ndarray, ...] | None,
    offset: np.ndarray | None = None,
    memory: dict | None = None,
    **extra: Any,
) -> LawContext:
    """The law context of ``owner``'s rows (a world, or one platoon of one).

    ``owner`` has ``fleet``, ``leader``, ``believed``, ``h``, ``law_params`` and
    ``law_memory``; the followers read the leader's pose as ``believed`` gives it
    (the broadcast copy, or its estimate under the braking barrier; the truth
    without sensing); ``extra`` are further fields of the context.
    """
    fleet, lead, seen = owner.fleet, owner.leader, owner.believed
    if lead < 0:
        leader_pos = leader_theta = None
    elif seen is None:
        leader_pos, leader_theta = fleet.pos[lead], float(fleet.theta[lead])
    else:
        leader_pos, leader_theta = seen[lead, :2], float(seen[lead, 2])
    return LawContext(
        t=t,
        dt=owner.h,
        pos=fleet.pos,
        theta=fleet.theta,
        vel=fleet.vel,
        offset=fleet.offset if offset is None else offset,
        leader=lead,
        leader_pos=leader_pos,
        leader_theta=leader_theta,
        reference=ref,
        params=owner.law_params,
        memory=owner.law_memory if memory is None else memory,
        **extra,
    )


#: From this many active failures on, the built-in kinds are applied at once.
RULED_FROM = 4


class StackedFailures:
    """The failure schedules of K worlds as one, a row per failure (world by world).

    The same onsets, the same commands and the same acceleration limit as
    :class:`~sandbox.model.failures.FailureSchedule` of each world alone: the
    built-in kinds of every world at once by their elementwise rules
    (:func:`~sandbox.model.failures.ruled_commands`), a plug-in kind's function
    failure after failure (and all of them when one vehicle has two at once).
    """

    def __init__(self, schedules: Sequence[FailureSchedule], n: int) -> None:
        world, vehicle, local, funcs, kinds, specs = [], [], [], [], [], []
        for w, fs in enumerate(schedules):
            for k, spec in enumerate(fs.specs):
                world.append(w)
                local.append(int(fs.vehicle[k]))
                vehicle.append(w * n + int(fs.vehicle[k]))
                kinds.append(fs.kinds[k])
                funcs.append(fs.funcs[k])
                specs.append(spec)
        self.world = np.array(world, dtype=np.intp)
        self.vehicle = np.array(vehicle, dtype=np.intp)
        self.local = np.array(local, dtype=np.intp)
        self.kinds, self.funcs, self.specs = kinds, funcs, specs
        self.start = np.array([s.at for s in specs], dtype=float)
        self.end = np.array(
            [s.until if s.until is not None else np.inf for s in specs], dtype=float
        )
        self.started = np.zeros(len(specs), dtype=bool)
        self.v2_onset = np.zeros(len(specs))
        self.params = [dict(s.params) for s in specs]
        self.controlled = np.array(
            [k.options["controlled_speed"] for k in kinds], dtype=bool
        )
        self.immovable = np.array([k.options["immovable"] for k in kinds], dtype=bool)
        self.N = len(schedules) * n
        # The built-in kinds' elementwise rules (rule 0: the function is called).
        rules = [rule_of(f, p) for f, p in zip(funcs, self.params, strict=True)]
        self.rule = np.array([r[0] for r in rules], dtype=np.intp)
        self.v1_param = np.array([r[1] for r in rules], dtype=float)
        self.v2_param = np.array([r[2] for r in rules], dtype=float)
        # One failure a vehicle at most: every set of active failures is one a vehicle.
        self._one_each = len(np.unique(self.vehicle)) == len(self.vehicle)
        # The onsets and ends in order: between two of them the schedule is the same.
        self._bounds = sorted({*self.start.tolist(), *self.end.tolist()})
        self._on_at = -1
        self._on = np.zeros(len(specs), dtype=bool)
        self._waiting = len(specs)  # failures not started yet
        #: No vehicle of any world (read-only: the flags of a period without failures).
        self._none = np.zeros(self.N, dtype=bool)
        self._none.flags.writeable = False

    def __len__(self) -> int:
        return len(self.specs)

    def active(self, t: float, live: np.ndarray) -> np.ndarray:
        """Active failures of the live worlds at ``t`` [s] (one flag per failure)."""
        u = t + 1e-12
        at = bisect_right(self._bounds, u)  # the same flags between two bounds
        if at != self._on_at:
            self._on = (self.start <= u) & (u < self.end)
            self._on_at = at
        return self._on & live[self.world]

    def active_vehicles(self, t: float, live: np.ndarray) -> np.ndarray:
        """Rows with an active failure at ``t`` [s], shape (N,) bool."""
        out = np.zeros(self.N, dtype=bool)
        out[self.vehicle[self.active(t, live)]] = True
        return out

    def start_new(self, t: float, live: np.ndarray, last_v2: np.ndarray) -> np.ndarray:
        """The failures that start at ``t`` (each reported once), their onset noted."""
        if not self._waiting:
            return np.zeros(0, dtype=np.intp)
        new = (self.active(t, live) & ~self.started).nonzero()[0]
        self._waiting -= len(new)
        self.started[new] = True
        self.v2_onset[new] = last_v2[self.vehicle[new]]
        return new

    def apply(
        self,
        t: float,
        live: np.ndarray,
        v1: np.ndarray,
        v2: np.ndarray,
        last_v1: np.ndarray,
        accel_step: float | np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list]:
        """Every world's active failures applied: commands, failed and frozen rows.

        Also the ``(world, PluginRunError)`` of each world whose failure plug-in
        raised (that world's other failures are skipped; the caller ends it).
        """
        N = self.N
        errors: list[tuple[int, PluginRunError]] = []
        if not len(self.specs):  # no vehicle ever fails: shared read-only flags
            return v1, v2, self._none, self._none, errors
        failed = np.zeros(N, dtype=bool)
        frozen = np.zeros(N, dtype=bool)
        v1, v2 = v1.copy(), v2.copy()
        broken: set[int] = set()
        active = self.active(t, live).nonzero()[0]
        rows = self.vehicle[active]
        # Built-in kinds only, one a vehicle, enough of them to pay the numpy calls:
        # at once; else one after the other (the same numbers either way).
        if (
            len(active) >= RULED_FROM
            and self.rule[active].all()
            and (self._one_each or len(np.unique(rows)) == len(rows))
        ):
            self._apply_rules(active, v1, v2, last_v1, accel_step, failed, frozen)
            return v1, v2, failed, frozen, errors
        for k in active:
            w = int(self.world[k])
            if w in broken:
                continue
            i, spec = self.vehicle[k], self.specs[k]
            ctx = FailureContext(
                t=t,
                since=t - spec.at,
                vehicle=spec.vehicle,
                index=int(self.local[k]),
                v1=float(v1[i]),
                v2=float(v2[i]),
                v2_onset=float(self.v2_onset[k]),
                params=dict(self.params[k]),
            )
            try:
                v1[i], v2[i] = self.funcs[k](ctx)
            except PluginRunError as exc:
                broken.add(w)
                errors.append((w, exc))
                continue
            if not self.immovable[k]:  # within the drive's max_accel, as alone
                step = float(accel_step if np.ndim(accel_step) == 0 else accel_step[i])
                v1[i] = within_drive(float(v1[i]), float(last_v1[i]), step)
            failed[i] = True
            frozen[i] |= not self.controlled[k]
        return v1, v2, failed, frozen, errors

    def _apply_rules(self, ruled, v1, v2, last_v1, accel_step, failed, frozen) -> None:
        """The built-in failures ``ruled`` at once, each on its own vehicle."""
        i = self.vehicle[ruled]
        out_v1, out_v2 = ruled_commands(
            self.rule[ruled],
            self.v1_param[ruled],
            self.v2_param[ruled],
            v1[i],
            self.v2_onset[ruled],
        )
        step = np.broadcast_to(accel_step, (self.N,))[i]
        movable = ~self.immovable[ruled]  # within the drive's max_accel, as alone
        v1[i] = np.where(movable, within_drives(out_v1, last_v1[i], step), out_v1)
        v2[i] = out_v2
        failed[i] = True
        frozen[i] |= ~self.controlled[ruled]


class StackedDifference:
    """Backward differences (eqs. (18)-(19)) of K worlds' rows, a history per world.

    Each row gives the numbers :class:`~sandbox.model.laws.BackwardDifference` gives
    alone; :meth:`reset` forgets one world's history (a reconfiguration).
    """

    def __init__(self, h: float, K: int, n: int) -> None:
        self.h, self.n = h, n
        self.count = np.zeros(K, dtype=np.int64)
        self.prev_x: np.ndarray | None = None
        self.prev_v: np.ndarray | None = None

    def update(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Feed the rows' values at this step; return ``(x', x'')``."""
        x = np.array(x, dtype=float)
        count = np.repeat(self.count, self.n)[:, None]
        if self.prev_x is None:
            v = np.zeros_like(x)
            a = np.zeros_like(x)
        else:
            v = np.where(count == 0, 0.0, (x - self.prev_x) / self.h)
            a = np.where(count >= 2, (v - self.prev_v) / self.h, 0.0)
        self.prev_x, self.prev_v = x, v
        self.count += 1
        return v, a

    def reset(self, w: int) -> None:
        """Forget world ``w``'s history (its next update starts again from zero)."""
        self.count[w] = 0


class WorldDifference:
    """One world's handle on a :class:`StackedDifference` (``reset()`` only)."""

    def __init__(self, stacked: StackedDifference, w: int) -> None:
        self._stacked, self._w = stacked, w

    def reset(self) -> None:
        """Forget this world's history."""
        self._stacked.reset(self._w)


class StackedCommands:
    """The open-loop command schedules of K worlds (``drive: {type: commands}``).

    A schedule's row ``(t_k, v1, v2)`` holds from ``t_k`` until its next row (zero
    before its first). The rows in force of every schedule of every world are looked
    up at once, and only when ``t`` passes a row time of some schedule; in between
    the same commands are written again.

    Parameters
    ----------
    states : sequence of WorldState
        The worlds, each with its ``schedules`` (vehicle index to table).
    n : int
        Vehicles per world.
    """

    def __init__(self, states: Sequence[WorldState], n: int) -> None:
        rows, tables = [], []
        for w, state in enumerate(states):
            for i, table in state.schedules.items():
                rows.append(w * n + i)
                tables.append(np.asarray(table, dtype=float).reshape(-1, 3))
        #: The stacked row of each schedule's vehicle.
        self.rows = np.array(rows, dtype=np.intp)
        self._length = np.array([len(tab) for tab in tables], dtype=np.intp)
        self._start = (np.cumsum(self._length) - self._length).astype(np.intp)
        # every table's rows one after the other, and a row of zeros at the end
        table = np.concatenate([*tables, np.zeros((1, 3))])
        self._times, self._v1, self._v2 = table[:, 0], table[:, 1], table[:, 2]
        #: How many rows of each schedule are in force (have started) so far.
        self._started = np.zeros(len(rows), dtype=np.intp)
        self._next = float(self._times[self._start].min()) if rows else np.inf
        self._v1_now = np.zeros(len(rows))
        self._v2_now = np.zeros(len(rows))

    def __len__(self) -> int:
        return len(self.rows)

    def apply(self, t: float, v1: np.ndarray, v2: np.ndarray) -> None:
        """Write the rows in force at ``t`` into the scheduled vehicles' commands."""
        now = t + 1e-12
        if self._next <= now:  # some schedule passes a row: look them up again
            length, start = self._length, self._start
            while True:
                more = self._started < length
                at = start + np.minimum(self._started, length - 1)
                due = more & (self._times[at] <= now)
                if not due.any():
                    break
                self._started += due
            more = self._started < length
            upcoming = self._times[start + np.minimum(self._started, length - 1)]
            self._next = float(upcoming[more].min()) if more.any() else np.inf
            held = self._started > 0
            at = start + np.maximum(self._started - 1, 0)
            self._v1_now = np.where(held, self._v1[at], 0.0)
            self._v2_now = np.where(held, self._v2[at], 0.0)
        v1[self.rows] = self._v1_now
        v2[self.rows] = self._v2_now
