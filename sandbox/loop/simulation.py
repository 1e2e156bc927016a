"""The fixed-step simulation loop, for one world or K worlds of one structure at once.

Every control period ``h = dt`` runs these stages over the rows of all worlds'
vehicles (``K * n`` rows, world after world; a single run is a loop of one world):

1. **sense**: read every world's poses from the physics; a world whose state is
   non-finite or runaway ends alone as ``diverged``; every world's broadcast
   (``sensing:``) draws from its own random stream
   (:class:`~sandbox.loop.perception.Perception`);
2. **plan**: evaluate the reference and the formation law (each vehicle's slot,
   ``x_ref'``, ``x_ref''``, :class:`~sandbox.loop.formation.Formation`), start the
   failures due now, ask the detector what has failed
   (:class:`~sandbox.loop.detecting.Detecting`), re-form on a change, shift the
   targets by the recovery strategy (eqs. (21)-(27),
   :class:`~sandbox.loop.avoidance.Avoidance`);
3. **act**: advance the flatness controller (eqs. (5)-(6)), filter the commands for
   safety, then apply open-loop schedules, the user's overrides and the failures, in
   that order (:class:`~sandbox.loop.acting.Acting`);
4. **record** a sample every ``record_every`` periods, and the loop metrics;
5. **advance**: write the commands to the physics and step it ``substeps`` times.

Each stage receives what it reads and returns what it changes; the loop's values
(the :class:`~sandbox.loop.layout.Layout` fixed at build, the
:class:`~sandbox.loop.state.Fleet`, the :class:`~sandbox.loop.plan.Plan` of the
period, the worlds' :class:`~sandbox.loop.liveness.Liveness`, the record and the
loop metrics) are changed here only, from what the stages return
(:mod:`sandbox.loop.building` makes them). The built-ins and plug-ins registered
with ``batched=True`` are called once for all worlds; other plug-ins world by world
inside the same pass, only for the live worlds. Each world's numbers are those it
has alone: the functions are elementwise over rows, neighbour pairs never cross
worlds, and every world keeps its own random streams, memories and contact
episodes.

:class:`Simulation` is the public face: built from one scenario it takes and gives
one world's arrays (shape ``(n, 2)``) and one
:class:`~sandbox.loop.observation.Observation`; built with
:meth:`Simulation.stacked` it takes and gives the batch's (``(K, n, 2)`` or a
sequence of K, a list of K observations), for any K. Nothing here draws or computes
metrics.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from sandbox.behaviour.detection import BatchDetection
from sandbox.behaviour.ranges import observation_fields
from sandbox.behaviour.reconfigure import Reconfiguration
from sandbox.behaviour.sensing import Broadcast
from sandbox.errors import PluginRunError
from sandbox.loop import plan as planning
from sandbox.loop.building import LoopParts, build
from sandbox.loop.collector import collector_off, frozen_heap
from sandbox.loop.divergence import RowsView, diverged
from sandbox.loop.ending import make_run, stage_error
from sandbox.loop.observation import Observation, Overrides, override_rows
from sandbox.loop.plan import Plan
from sandbox.loop.platoons import Platoons
from sandbox.loop.recording import LoopRecord
from sandbox.loop.state import Fleet
from sandbox.loop.stepping import LoopPhysics
from sandbox.loop.tally import no_distances
from sandbox.physics.interface import Physics
from sandbox.plugins.registration import LawContext
from sandbox.run.record import (
    STATUS_DIVERGED,
    STATUS_ERROR,
    STATUS_INTERRUPTED,
    Run,
)
from sandbox.scenario import Scenario

#: One kind of override in the loop's rows: the (N, 2) rows and the (N,) mask.
Rows = tuple[np.ndarray, np.ndarray] | None


class Simulation:
    """One run of a scenario; or, built with :meth:`stacked`, K runs stepped together.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario (see :func:`sandbox.load_scenario`).
    world : Physics, optional
        The physics back-end; default a pymunk :class:`~sandbox.physics.world.World` of
        the scenario's vehicles and obstacles.

    Examples
    --------
    >>> from sandbox import load_scenario
    >>> doc = {"duration": 1.0, "reference": {"type": "point", "position": [1, 0]},
    ...        "vehicles": [{"name": "red", "pose": [0, 0, 0]}]}
    >>> run = Simulation(load_scenario(doc)).run()
    >>> run.pose.shape
    (101, 1, 3)

    The same run, one step at a time, with the speed held at 0.2 m/s for 0.5 s:

    >>> sim = Simulation(load_scenario(doc))
    >>> obs = sim.observe()
    >>> while not sim.done:
    ...     obs = sim.step(commands={"red": (0.2, 0.0)} if obs.t < 0.5 else None)
    >>> sim.result().mode[:3, 0].tolist()  # 3: external
    [3, 3, 3]

    Three seeds at once, each run the bytes it has alone:

    >>> runs = Simulation.batch([load_scenario({**doc, "seed": s}) for s in range(3)])
    >>> [r.pose.shape for r in runs]
    [(101, 1, 3), (101, 1, 3), (101, 1, 3)]
    """

    def __init__(self, scenario: Scenario, world: Physics | None = None) -> None:
        with collector_off():  # building makes no cyclic garbage (loop/collector.py)
            self._start(build([scenario], [world]), batch=False)

    @classmethod
    def stacked(
        cls,
        scenarios: Sequence[Scenario],
        worlds: Sequence[Physics | None] | None = None,
    ) -> Simulation:
        """K runs of one structure (:func:`~sandbox.loop.plan.structure_key`) at once.

        The step API then takes and gives the batch's arrays, with a leading world
        axis, for any K (one included): :meth:`step` takes overrides of shape
        ``(K, n, 2)`` or a sequence of K and returns a list of K observations,
        :meth:`observe` a list of K (``world=w``: one), and :meth:`results` one
        :class:`~sandbox.Run` per world.

        Raises
        ------
        ValueError
            The scenarios differ in structure (:meth:`batch` groups them instead).
        """
        sim = cls.__new__(cls)
        scenarios = list(scenarios)
        with collector_off():
            parts = build(
                scenarios, list(worlds) if worlds else [None] * len(scenarios)
            )
            sim._start(parts, batch=True)
        return sim

    @classmethod
    def batch(
        cls,
        scenarios: Sequence[Scenario],
        should_stop: Callable[[], bool] | None = None,
        group_size: int = 128,
    ) -> list[Run] | None:
        """Run scenarios, those of one structure stepped together; one Run each.

        Scenarios are grouped by :func:`~sandbox.loop.plan.structure_key` (never
        refused, never mixed), in groups of at most ``group_size`` worlds; the runs
        come back in the order of ``scenarios``, each byte for byte the run it is
        alone. ``should_stop`` is polled every step; when it returns True the batch
        stops and None is returned.
        """
        scenarios = list(scenarios)
        groups: dict[str, list[int]] = {}
        for k, sc in enumerate(scenarios):
            groups.setdefault(planning.structure_key(sc), []).append(k)
        out: list[Run | None] = [None] * len(scenarios)
        for members in groups.values():
            for start in range(0, len(members), group_size):
                part = members[start : start + group_size]
                sim = cls.stacked([scenarios[k] for k in part])
                runs = sim.run_all(should_stop)
                if runs is None:
                    return None
                for k, run in zip(part, runs, strict=True):
                    out[k] = run
        return out  # type: ignore[return-value]

    # ------------------------------------------------------------------ set-up
    def _start(self, parts: LoopParts, batch: bool) -> None:
        """Take the built parts; sense and plan the first period."""
        self._batch = batch
        self._layout = parts.layout
        #: The fleet's arrays: the state now and the commands of the last period.
        self.fleet: Fleet = parts.fleet
        #: The physics of every world.
        self.physics: LoopPhysics = parts.physics
        #: The record of every world's samples.
        self.recorder: LoopRecord = parts.record
        self._steering = parts.steering
        self._formation = parts.formation
        self._perception = parts.perception
        self._avoidance = parts.avoidance
        self._safety = parts.safety
        self._detecting = parts.detecting
        self._failures = parts.failures
        self._acting = parts.acting
        self._liveness = parts.liveness
        self._tally = parts.tally
        self._shift_motion = parts.shift_motion
        N = parts.layout.N
        #: The plan of the current period (None before the first).
        self.plan: Plan | None = None
        #: The broadcast poses received at ``t_k``, (N, 3) (None without sensing).
        self.seen: np.ndarray | None = None
        #: What the law and the recovery see: ``seen``, or its estimate (braking).
        self.believed: np.ndarray | None = None
        #: What the platoons believe has failed (the oracle: the truth), (N,) bool.
        self.known_failed = np.zeros(N, dtype=bool)
        self._failing = np.zeros(N, dtype=bool)
        #: Whether every row's state is finite and within the bounds.
        self.finite = True
        #: The current step ``k`` (time ``t_k = k h``).
        self.k = 0
        self._contact: np.ndarray | None = None
        self._recorded_target: np.ndarray | None = None
        self._row_names: list[str] | None = None
        self._estimate_shift = parts.layout.scenarios[0].recovery.target_derivatives
        self._distances = getattr(parts.avoidance.neighbours, "distances", no_distances)
        # Without failures, detection, reconfiguration and platoons, what the platoon
        # believes has failed and who may avoid never change: made at the first plan.
        formation = parts.formation
        self._may_avoid_fixed = not (
            len(parts.failures)
            or parts.detecting.on
            or formation.reconfiguring
            or formation.platoons is not None
        )
        self._may_avoid: np.ndarray | None = None
        self._fails = len(parts.failures) > 0  # else no vehicle ever fails
        self._wall = time.perf_counter()
        #: Wall time spent planning and acting (law, recovery, controller, filters).
        self._control_time = 0.0
        if self._sense():
            self._guarded(self._plan)

    # ------------------------------------------------------------------ stages
    def _sense(self) -> bool:
        """Read every live world's state at ``t_k``; False when none is left.

        A diverged world ends alone: its sample is recorded as it is (slots and
        targets NaN, the last commands and modes), its status becomes ``diverged``.
        """
        layout, fleet, live = self._layout, self.fleet, self._liveness
        t = self.k * layout.h
        pos, theta, vel = self.physics.read()
        if live.count < layout.K:  # the ended worlds' rows: a harmless state
            chi = fleet.chi.reshape(layout.K, layout.n, 2)
            chi[~live.live] = 0.0
        fleet.pos, fleet.theta, fleet.vel = pos, theta, vel
        self.finite = diverged(fleet) is None
        if not self.finite:
            for w in live.worlds():
                bad = diverged(RowsView(fleet, layout.rows(w)))
                if bad is None:
                    continue
                live.info[w]["diverged"] = {
                    "t": t,
                    "vehicle": layout.names[w][bad[0]],
                    "reason": bad[1],
                }
                self._end_world(w, STATUS_DIVERGED)
            self.finite = bool(live.live.all()) and diverged(fleet) is None
        if not live.count:
            return False
        perception = self._perception
        if perception.active:
            self.seen, self.believed = perception.update(t, fleet, self.seen)
        return True

    def _plan(self) -> None:
        """What the built-in stack does at ``t_k``: slots, failures, recovery.

        Evaluates the reference and the formation law, starts the failures due now,
        asks the detector what has failed, re-forms, and shifts the targets by the
        recovery strategy (eqs. (21)-(27)). The result is :attr:`plan`, which
        :meth:`observe` shows and :meth:`_act` consumes (with any overrides).
        """
        layout, fleet, live = self._layout, self.fleet, self._liveness
        formation, failed = self._formation, self._plugin_failed
        t = self.k * layout.h
        if formation.platoons is not None:  # merges, splits, each platoon's events
            for w in formation.prepare_platoons(
                t,
                fleet,
                self.seen,
                self.believed,
                self.known_failed,
                live.worlds(),
                live.info,
                lambda w, exc: self._world_failed(w, "platoons", exc),
            ):
                self._shift_motion.reset(w)
        slot, v_ref, a_ref, point = formation.targets(
            t, self.k, fleet, self.believed, live.worlds(), failed
        )
        failing = self._failing
        fs = self._failures
        if self._fails:
            new = fs.start_new(t, live.live, fleet.v2)
            for j in new:
                w = int(fs.world[j])
                if fs.immovable[j]:
                    self.physics.immobilize(w, int(fs.local[j]))
                live.failed_at[w].setdefault(fs.specs[j].vehicle, t)
            failing = fs.active_vehicles(t, live.live)
        # What the platoon believes has failed; everything below reacts to this,
        # never to the truth. The oracle: the truth, known at once.
        known = failing
        if self._detecting.on:
            known = self._detecting.known(
                t, failing, fleet, self.seen, live.worlds(), failed
            )
        self.known_failed = known
        if formation.reconfiguring:  # re-forms when `known` changes
            for w in formation.react(
                t, known, fleet, self.seen, self.believed, live.live, failed
            ):
                self._shift_motion.reset(w)
        if formation.platoons is not None:  # each world's platoons decide
            candidates = formation.platoon_candidates()
        else:
            candidates = formation.avoid_candidates
        if not self._may_avoid_fixed:
            may_avoid = candidates & ~known
        elif self._may_avoid is None:  # the same every period
            may_avoid = self._may_avoid = candidates & ~known
            may_avoid.flags.writeable = False
        else:
            may_avoid = self._may_avoid
        target, shift, active = self._avoidance.targets(
            t, fleet, slot, may_avoid, known, self.believed, live.worlds(), failed
        )
        slot_vel = slot_acc = None  # the law's alone: v_ref, a_ref
        if self._estimate_shift == "estimate":
            K, n, N = layout.K, layout.n, layout.N
            d_shift, dd_shift = self._shift_motion.update(shift.reshape(K, n, 2))
            slot_vel, slot_acc = v_ref, a_ref
            v_ref = v_ref + d_shift.reshape(N, 2)
            a_ref = a_ref + dd_shift.reshape(N, 2)
        self._failing = failing
        self.plan = Plan(
            slot, target, v_ref, a_ref, point, active, failing, slot_vel, slot_acc
        )

    def _act(
        self, commands: Rows, targets: Rows, shifts: Rows
    ) -> tuple[np.ndarray, np.ndarray]:
        """Commands for the period from ``t_k`` (:class:`~sandbox.loop.acting.Acting`).

        Sets ``fleet.v1, v2, failed, mode``; returns ``chi`` and the directions of
        travel for ``t_k+1``.
        """
        fleet, live = self.fleet, self._liveness
        acted = self._acting.commands(
            self.k * self._layout.h,
            fleet,
            self.plan,
            self.known_failed,
            self.seen,
            live.live,
            commands,
            targets,
            shifts,
            self._plugin_failed,
            live.worlds,
        )
        fleet.v1, fleet.v2, fleet.failed = acted.v1, acted.v2, acted.failed
        fleet.steer = acted.steer
        if self._fails:  # else never set: an episode now is healthy
            self.physics.failed[:] = acted.failed  # an episode now is not healthy
        fleet.mode = acted.mode
        if acted.target is not None:
            self._recorded_target = acted.target
        return acted.chi, acted.travel

    def _record(self, plan: Plan) -> None:
        """The loop metrics, and the sample of ``t_k`` every ``record_every`` steps."""
        fleet, layout = self.fleet, self._layout
        contact = self.physics.in_contact()
        self._contact = contact
        self._tally.update(fleet, self.k, self.finite, self._distances, contact, None)
        if self.k % layout.record_every:
            return
        target = self._recorded_target
        steering, index = self._steering, self.recorder.count
        if steering is not None:  # the cars' angles of the same sample
            steering.append(index, fleet.steer)
        self.recorder.append(
            self.k * layout.h,
            fleet.pos,
            fleet.theta,
            fleet.v1,
            fleet.v2,
            fleet.chi,
            plan.slot,
            plan.target if target is None else target,
            fleet.mode,
            fleet.failed,
            plan.point,
            self._liveness.worlds(),
        )
        ranges = self._perception.ranges
        if ranges is not None:
            ranges.record()

    def _advance(self, following: tuple[np.ndarray, np.ndarray]) -> None:
        """Write the commands to the physics and step it to ``t_k+1``.

        ``following``: the controllers' ``chi`` and directions of travel of
        ``t_k+1``.
        """
        fleet, h = self.fleet, self._layout.h
        fleet.chi, fleet.travel = following
        tally = self._tally
        commanded = tally.commanded if tally.commanded_at == self.k else None
        self.physics.advance(
            fleet.theta,
            fleet.v1,
            fleet.v2,
            commanded,
            self.physics.free_of(self._contact),
            self.k * h,
            h,
            first=self.k == 0,
        )
        self.k += 1

    def _step(
        self,
        commands: Rows = None,
        targets: Rows = None,
        should_stop: Callable[[], bool] | None = None,
        shifts: Rows = None,
    ) -> None:
        """One control period: act, record, advance, sense and plan the next.

        A stage that fails (not a plug-in: a defect, or the record's spill on a full
        disk) ends every live world there with status ``error``, its samples up to
        then kept (:meth:`_stage_failed`).
        """
        live = self._liveness
        self._recorded_target = None
        start = time.perf_counter()
        try:
            following = self._act(commands, targets, shifts)
        except PluginRunError as exc:  # a batched plug-in: every world ends
            for w in live.worlds():
                self._plugin_failed(w, exc)
            live.closed = True
            return
        except Exception as exc:  # a defect: the run ends, its outputs kept
            self._stage_failed("act", exc)
            return
        self._control_time += time.perf_counter() - start
        try:
            self._record(self.plan)
        except Exception as exc:  # a defect: the run ends, its outputs kept
            self._stage_failed("record", exc, last=False)
            return
        if self.recorder.on_disk:  # a spill that failed ends its world
            self._spill_failed()
        if not live.count:
            live.closed = True
            return
        if should_stop is not None and should_stop():
            live.stopped = True
            for w in live.worlds():
                live.info[w]["interrupted"] = {"t": self.k * self._layout.h}
                self._end_world(w, STATUS_INTERRUPTED, last=False)
            return
        try:
            self._advance(following)
        except Exception as exc:
            self._stage_failed("physics", exc, last=False)
            return
        try:
            sensed = self._sense()
        except Exception as exc:
            self._stage_failed("sense", exc, last=False)
            return
        if sensed:
            start = time.perf_counter()
            self._guarded(self._plan)
            self._control_time += time.perf_counter() - start
        else:
            live.closed = True

    def _guarded(self, stage: Callable[[], None]) -> None:
        """Run the plan over all worlds; a failure there ends every world.

        A plug-in that fails ends them as :meth:`_plugin_failed` says, anything else
        as :meth:`_stage_failed` does.
        """
        try:
            stage()
        except PluginRunError as exc:
            for w in self._liveness.worlds():
                self._plugin_failed(w, exc)
        except Exception as exc:  # a defect: the run ends, its outputs kept
            self._stage_failed("plan", exc)

    def _stage(self, name: str, stage: Callable[[Any], None], arg: Any) -> bool:
        """``stage(arg)``; False when it failed (every world ended, status error)."""
        try:
            stage(arg)
        except Exception as exc:  # a defect: the run ends, its outputs kept
            self._stage_failed(name, exc, last=False)
            return False
        return True

    def _stage_failed(self, stage: str, exc: Exception, last: bool = True) -> None:
        """Every live world ends now with status ``error``: ``stage`` raised ``exc``.

        ``last``: record the sample of now first, with the plan undefined (a stage
        before the record's); else the run ends at the last sample recorded.
        """
        live = self._liveness
        for w in live.worlds():
            self._world_failed(w, stage, exc, last)
        live.closed = True

    def _world_failed(
        self, w: int, stage: str, exc: Exception | str, last: bool = True
    ) -> None:
        """World ``w`` ends now with status ``error``: a stage of the loop failed.

        ``info["error"]`` names the stage and says what failed
        (:func:`~sandbox.loop.ending.stage_error`).
        """
        t = self.k * self._layout.h
        self._liveness.info[w]["error"] = stage_error(t, stage, exc)
        self._end_world(w, STATUS_ERROR, last)

    def _spill_failed(self) -> None:
        """End the live worlds whose record's spill failed (a full disk)."""
        for w in self._liveness.worlds():
            why = self.recorder.failure(w)
            if why is not None:
                self._world_failed(w, "record", why, last=False)

    def _loop(
        self,
        progress: Callable[[int, int], None] | None,
        should_stop: Callable[[], bool] | None,
    ) -> bool:
        """Steps until done; True when ``should_stop`` stopped them."""
        steps = self._layout.steps
        report_every = max(1, steps // 100)
        with frozen_heap():
            while not self.done:
                k = self.k
                self._step(should_stop=should_stop)
                if self._liveness.stopped:
                    return True
                if progress is not None and k % report_every == 0 and k < self.k:
                    progress(k, steps)
        return False

    # ------------------------------------------------------------------ endings
    def _plugin_failed(self, w: int, exc: PluginRunError) -> None:
        """End world ``w`` with status ``error``: a plug-in raised or returned NaN.

        The sample of the time it happened is recorded as a diverged state's is (the
        plan undefined, the last commands), and ``info["error"]`` names the plug-in.
        """
        self._liveness.info[w]["error"] = {
            "t": self.k * self._layout.h,
            "plugin": exc.plugin,
            "message": exc.message,
        }
        self._end_world(w, STATUS_ERROR)

    def _end_world(self, w: int, status: str, last: bool = True) -> None:
        """World ``w`` ends now with ``status``; its run is made at once.

        ``last``: record its sample of now first, with the plan undefined.
        """
        live, fleet, layout = self._liveness, self.fleet, self._layout
        if not live.live[w]:
            return
        live.status[w] = status
        if last:
            if self._steering is not None:
                self._steering.append(self.recorder.count, fleet.steer, w)
            nan = np.full((layout.N, 2), np.nan)
            arrays = self.recorder.append_last(
                w,
                self.k * layout.h,
                fleet.pos,
                fleet.theta,
                fleet.v1,
                fleet.v2,
                fleet.chi,
                nan,
                nan,
                fleet.mode,
                fleet.failed,
                np.full(2, np.nan),
            )
            self._tally.update(
                fleet,
                self.k,
                self.finite,
                self._distances,
                self.physics.in_contact(),
                np.array([w]),
            )
        else:
            arrays = self.recorder.arrays(w)
        self.physics.stop(w)
        live.end(w, self._make_run(w, arrays, status), undefined=last)

    def _finish_all(self) -> None:
        """End the live worlds at ``t_k``: the last sample, the controller's commands.

        Before the duration the worlds end ``interrupted``.
        """
        live, layout = self._liveness, self._layout
        worlds = live.worlds()
        if not worlds:
            live.closed = True
            return
        for w in worlds:
            if self.k < layout.steps:
                live.status[w] = STATUS_INTERRUPTED
                live.info[w]["interrupted"] = {"t": self.k * layout.h}
        self._recorded_target = None
        try:
            self._act(None, None, None)
        except PluginRunError as exc:
            for w in live.worlds():
                self._plugin_failed(w, exc)
        except Exception as exc:  # a defect: the run ends, its outputs kept
            self._stage_failed("act", exc)
        else:
            if self._stage("record", self._record, self.plan):
                self._spill_failed()
        for w in live.worlds():
            status = live.status[w]
            live.end(w, self._make_run(w, self.recorder.arrays(w), status), False)
        live.closed = True

    def _make_run(self, w: int, arrays: dict, status: str) -> Run:
        """World ``w``'s run (:func:`~sandbox.loop.ending.make_run`).

        A record whose spill failed as it was closed ends the run with status
        ``error`` too (its samples written before are the run's).
        """
        layout, live, safety = self._layout, self._liveness, self._safety
        why = self.recorder.failure(w)
        if why is not None and status != STATUS_ERROR:
            status = live.status[w] = STATUS_ERROR
            live.info[w]["error"] = stage_error(self.k * layout.h, "record", why)
        ranges = self._perception.ranges
        if self._steering is not None:  # a world with cars: their angles
            arrays = {**arrays, **self._steering.arrays(w, len(arrays["t"]))}
        detection = self._detecting.detection
        return make_run(
            layout,
            w,
            live.info[w],
            status,
            arrays,
            failed_at=live.failed_at[w],
            detection=None if detection is None else detection.summary(w),
            loop_metrics=self._tally.result(w),
            wall_time=(time.perf_counter() - self._wall) / layout.K,
            control_time=self._control_time / layout.K,
            safety=None if safety.filter is None else safety.world_stats[w],
            steps=self.k,
            diameter=self.fleet.diameter[layout.rows(w)].copy(),
            leader=int(self._formation.leaders[w]),
            events=list(self.physics.worlds[w].events),
            ranges={} if ranges is None else ranges.part(w).arrays(),
        )

    # ------------------------------------------------------------------ the API
    @property
    def K(self) -> int:
        """The number of worlds stepped together (1 for a single run)."""
        return self._layout.K

    @property
    def n(self) -> int:
        """The number of vehicles of each world."""
        return self._layout.n

    @property
    def N(self) -> int:
        """The number of rows of the loop's arrays, ``K n``."""
        return self._layout.N

    @property
    def h(self) -> float:
        """The control period ``h = dt`` [s]."""
        return self._layout.h

    @property
    def steps(self) -> int:
        """The control periods of the whole duration."""
        return self._layout.steps

    @property
    def scenario(self) -> Scenario:
        """The scenario (of the first world of a batch)."""
        return self._layout.scenarios[0]

    @property
    def t(self) -> float:
        """Current simulated time ``t_k = k h`` [s]."""
        return self.k * self._layout.h

    @property
    def done(self) -> bool:
        """Whether the run has reached its duration, diverged or been stopped.

        Of a batch: whether every world has ended.
        """
        live = self._liveness
        return live.closed or self.k >= self._layout.steps or not live.count

    @property
    def live(self) -> np.ndarray:
        """Which worlds are still stepped, shape (K,), bool."""
        return self._liveness.live

    @property
    def names(self) -> list[str]:
        """Vehicle names, in row order (of the first world of a batch)."""
        return list(self._layout.names[0])

    @property
    def world(self) -> Physics:
        """The physics of the run (of the first world of a batch)."""
        return self.physics.worlds[0]

    @property
    def status(self) -> str:
        """The run's status: ``ok``, ``diverged``, ``error``, ``interrupted``.

        Of a batch: the first world's (:attr:`statuses`: every world's).
        """
        return self._liveness.status[0]

    @property
    def statuses(self) -> list[str]:
        """Every world's status, in world order (a list of one for a single run)."""
        return list(self._liveness.status)

    @property
    def info(self) -> dict:
        """The run's description, ``Run.info`` in the making (of the first world)."""
        return self._liveness.info[0]

    @property
    def failed_at(self) -> dict[str, float]:
        """When each failed vehicle failed [s] (of the first world of a batch)."""
        return self._liveness.failed_at[0]

    @property
    def detection(self) -> BatchDetection | None:
        """The detector of every world, None for the oracle.

        Its ``memory`` is what a detector registered with ``batched=True`` keeps
        for the rows of every world (any other detector's: the first world's;
        ``memories`` holds each world's); ``events[w]`` are world ``w``'s detections.
        """
        return self._detecting.detection

    @property
    def reconfiguration(self) -> Reconfiguration | None:
        """The run's reconfiguration, None: slots kept (of the first world)."""
        return self._formation.reconfigurations[0]

    @property
    def broadcast(self) -> Broadcast | None:
        """The broadcast of every world's rows (``sensing:``), None without sensing.

        Each world draws from its own random stream; ``seen``, ``fresh`` and
        ``sigma`` have a row per vehicle of every world.
        """
        return self._perception.broadcast

    @property
    def platoons(self) -> Platoons | None:
        """The run's platoons (``platoons:``; of the first world), None: one platoon."""
        platoons = self._formation.platoons
        return None if platoons is None else platoons[0]

    @property
    def leader(self) -> int:
        """The vehicle that leads now, -1 for none (of the first world of a batch)."""
        return int(self._formation.leaders[0])

    @property
    def law(self) -> Any:
        """The formation law (None without ``formation:``).

        The one law of every world, or the first world's own where each world's
        law is evaluated on its rows (a plug-in without ``batched=True``).
        """
        formation = self._formation
        return formation.laws[0] if formation.per_world else formation.law

    @property
    def law_params(self) -> dict:
        """The formation law's values (of the first world's own law, where each has)."""
        formation = self._formation
        return formation.params[0] if formation.per_world else formation.law_params

    @property
    def law_memory(self) -> dict:
        """The formation law's memory (of the first world's own law, where each has)."""
        formation = self._formation
        return formation.memory[0] if formation.per_world else formation.law_memory

    @property
    def strategy(self) -> Any:
        """The recovery strategy as the loop calls it.

        Replacing it (a wrapper, a spy) makes the loop call the replacement, on the
        numpy path (the strategy's C call computes the built-in's only).
        """
        return self._avoidance.strategy

    @strategy.setter
    def strategy(self, value: Any) -> None:
        self._avoidance.strategy = value

    def law_context(
        self,
        t: float,
        ref: tuple | None,
        offset: np.ndarray | None = None,
        memory: dict | None = None,
    ) -> LawContext:
        """What the law of the run (of the first world) sees at ``t``.

        Parameters
        ----------
        t : float [s]
        ref : tuple of ndarray or None
            The reference's ``(p, p', p'')`` at ``t`` (None: no reference).
        offset : ndarray, shape (n, 2) [m], optional
            The offsets (default: the fleet's).
        memory : dict, optional
            The law's memory (default: the first world's law's).
        """
        return self._formation.world_context(
            0, t, ref, self.fleet, self.believed, offset, memory
        )

    def observe(self, world: int | None = None) -> Observation | list[Observation]:
        """The world now, and what the built-in stack plans for this period.

        Parameters
        ----------
        world : int, optional
            One world of a batch. Default: the run's observation, or of a batch
            (:meth:`stacked`) a list of every world's.

        Returns
        -------
        Observation, or list of Observation (one per world)
        """
        if world is None:
            if self._batch:
                return [self._observe(w) for w in range(self._layout.K)]
            world = 0
        return self._observe(world)

    def _observe(self, world: int) -> Observation:
        """World ``world``'s :class:`~sandbox.loop.observation.Observation` now."""
        layout, live = self._layout, self._liveness
        fleet, plan, rows = self.fleet, self.plan, layout.rows(world)
        ended = not live.live[world] or live.closed
        if live.undefined[world]:  # ended with its plan undefined
            nan = np.full((layout.n, 2), np.nan)
            slot, target, failing = nan, nan.copy(), fleet.failed[rows].copy()
            slot_vel, slot_acc = nan.copy(), nan.copy()
        else:
            slot = np.array(plan.slot[rows], dtype=float)
            target = np.array(plan.target[rows], dtype=float)
            failing = plan.failing[rows].copy()
            none = np.isnan(slot)  # no slot: no motion of it either
            slot_vel, slot_acc = (
                np.where(none, np.nan, a[rows]) for a in plan.slot_motion()
            )
        ranges = self._perception.ranges
        platoons = self._formation.platoons
        scenario = layout.scenarios[world]
        return Observation(
            t=self.k * layout.h,
            names=layout.names[world],
            pose=np.concatenate((fleet.pos[rows], fleet.theta[rows, None]), axis=1),
            vel=fleet.vel[rows].copy(),
            chi=fleet.chi[rows].copy(),
            slot=slot,
            slot_vel=slot_vel,
            slot_acc=slot_acc,
            target=target,
            mode=fleet.mode[rows].copy() if ended else plan.mode(layout.N)[rows],
            failed=failing,
            **observation_fields(
                None if ranges is None else ranges.part(world),
                self._perception.obstacles,
                scenario,
                fleet.pos[rows],
            ),
            platoon=None if platoons is None else platoons[world].of_vehicles(),
        )

    def step(
        self,
        commands: Overrides | Sequence[Overrides] = None,
        targets: Overrides | Sequence[Overrides] = None,
        shifts: Overrides | Sequence[Overrides] = None,
        observe: bool = True,
    ) -> Observation | list[Observation] | None:
        """Advance one control period ``h = dt``, with optional overrides.

        Parameters
        ----------
        commands : mapping of str to (v1, v2), or ndarray (n, 2), optional
            Commands [m/s, rad/s] replacing the controller's for the named vehicles
            this period, within the vehicle's ``v1_max``, ``v2_max`` and (on v1)
            ``max_accel``. Failures still act on top of them.
        targets : mapping of str to (x1, x2), or ndarray (n, 2), optional
            Points [m] the controller tracks this period instead of the planned
            target, as set-points (no feed-forward velocity); recovery does not shift
            them. An array takes NaN rows for "no override".
        shifts : mapping of str to (dx1, dx2), or ndarray (n, 2), optional
            Displacements [m] added to the planned target (slot plus recovery) this
            period, the law's feed-forward motion kept: a zero shift drives as the
            built-in stack does. ``targets`` win where both are given.
        observe : bool
            Whether to return the observation (False: None, the arrays untouched
            in :attr:`fleet` and :attr:`plan`).

        Returns
        -------
        Observation, or list of Observation (one per world)
            At the next step ``t_k+1``.

        Raises
        ------
        RuntimeError
            When the run is :attr:`done`.
        ValueError
            An unknown vehicle name or a malformed value.

        Notes
        -----
        Built with :meth:`stacked` (K worlds, any K) each override is an array
        ``(K, n, 2)`` or a sequence of K of the above (None for none), and a list of
        K observations is returned.
        """
        if self.done:
            raise RuntimeError(
                f"the run is over (status {self.status!r} at t = {self.t:g} s); "
                "call result()"
            )
        cmd = self._override_rows(commands, "commands")
        tgt = self._override_rows(targets, "targets")
        shf = self._override_rows(shifts, "shifts")
        self._step(cmd, tgt, shifts=shf)
        if not observe:
            return None
        return self.observe()

    def _override_rows(self, values: Any, what: str) -> Rows:
        """The ``(N, 2)`` rows and ``(N,)`` mask of one kind of override."""
        layout = self._layout
        if not self._batch or values is None:
            return override_rows(values, layout.names[0], what)
        K, n, N = layout.K, layout.n, layout.N
        if isinstance(values, np.ndarray):
            if values.shape != (K, n, 2):
                raise ValueError(
                    f"{what}: expected an array of shape ({K}, {n}, 2) or "
                    f"a sequence of {K} overrides, got shape {values.shape}"
                )
            names = self._row_names
            if names is None:  # every row named by its world, for the errors
                names = [f"world {w} {v}" for w in range(K) for v in layout.names[w]]
                self._row_names = names
            return override_rows(values.reshape(N, 2), names, what)
        if len(values) != K:
            raise ValueError(f"{what}: expected {K} overrides, got {len(values)}")
        rows, mask = np.full((N, 2), np.nan), np.zeros(N, dtype=bool)
        for w, part in enumerate(values):
            got = override_rows(part, layout.names[w], what)
            if got is not None:
                rows[layout.rows(w)], mask[layout.rows(w)] = got
        return (rows, mask) if mask.any() else None

    def run(
        self,
        progress: Callable[[int, int], None] | None = None,
        should_stop: Callable[[], bool] | None = None,
    ) -> Run:
        """Simulate the whole scenario and return the recorded run.

        The loop of :meth:`step` without overrides, then :meth:`result`.

        Parameters
        ----------
        progress : callable, optional
            Called as ``progress(step, steps)`` about a hundred times over the run.
        should_stop : callable, optional
            Polled every step; when it returns True the run stops with status
            ``interrupted`` (the samples so far are kept).
        """
        self._loop(progress, should_stop)
        return self.result()

    def run_all(
        self, should_stop: Callable[[], bool] | None = None
    ) -> list[Run] | None:
        """Simulate every world to its end; the runs in order (None if stopped)."""
        stopped = self._loop(None, should_stop)
        return None if stopped else self.results()

    def result(self, world: int = 0) -> Run:
        """The recorded run so far (the whole run once :attr:`done`).

        The sample of the last time is recorded with the controller's own commands.
        Called before the run is done, the run ends here with status ``interrupted``.
        Further calls return the same :class:`~sandbox.run.record.Run`.

        Parameters
        ----------
        world : int
            The world of a batch (0: the run's).
        """
        runs = self._liveness.runs
        if world not in runs:
            self._finish_all()
        return runs[world]

    def results(self) -> list[Run]:
        """One :class:`~sandbox.run.record.Run` per world (see :meth:`result`)."""
        return [self.result(w) for w in range(self._layout.K)]


def simulate(scenario: Scenario, **kwargs: Any) -> Run:
    """Run a scenario; return its :class:`~sandbox.Run` (:meth:`Simulation.run`)."""
    return Simulation(scenario).run(**kwargs)
