"""The fixed-step simulation loop, for one world or K worlds of one structure at once.

Every control period ``h = dt`` runs these stages over the stacked arrays of all
worlds' vehicles (``K * n`` rows, world after world; a single run is K = 1):

1. **sense** (:meth:`Simulation._sense`): read every world's poses from the physics;
   a world whose state is non-finite or runaway ends alone as ``diverged``; each
   world's broadcast (``sensing:``) draws from its own random stream;
2. **plan** (:meth:`Simulation._plan`): evaluate the reference and the formation law
   (each vehicle's slot, ``x_ref'``, ``x_ref''``), start the failures due now, ask
   the detector what has failed, re-form on a change, shift the targets by the
   recovery strategy (eqs. (21)-(27));
3. **act** (:meth:`Simulation._act`): advance the flatness controller (eqs. (5)-(6)),
   filter the commands for safety, then apply open-loop schedules, the user's
   overrides and the failures, in that order;
4. **record** a sample every ``record_every`` periods, and the loop metrics;
5. **advance**: write the commands to the physics and step it ``substeps`` times.

The built-ins (laws, strategies, failure kinds, command schedules, filter,
detectors, sensing, range sensors) and plug-ins registered with ``batched=True`` are
called once for all worlds; a built-in law stays one call while the worlds re-form
apart, each with its own leader and estimators (:mod:`sandbox.loop.stacked_law`). A
reconfiguration's event and other plug-ins run world by world inside the same loop
(:mod:`sandbox.loop.world_stages`), only for the worlds concerned. Each world's
numbers are those it has alone: the functions are elementwise over rows, neighbour
pairs never cross worlds, and every world keeps its own random streams, memories and
contact episodes.

:meth:`Simulation.step` runs one period with optional overrides and returns an
:class:`~sandbox.loop.observation.Observation`; :meth:`Simulation.run` is the loop of
steps without overrides; :meth:`Simulation.batch` runs many scenarios, stacking those
of one structure. The physics is reached only through
:class:`~sandbox.loop.stepping.WorldsPhysics`. Nothing here draws or computes metrics.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from sandbox.behaviour.ranges import (
    context_fields,
)
from sandbox.errors import PluginRunError
from sandbox.loop.building import Building
from sandbox.loop.collector import collector_off, frozen_heap
from sandbox.loop.divergence import RowsView, diverged
from sandbox.loop.ending import Ending
from sandbox.loop.plan import Plan, structure_key
from sandbox.loop.stacked_law import stacked_law_context, stacked_law_inputs
from sandbox.loop.step_api import StepAPI
from sandbox.loop.world_stages import WorldStages
from sandbox.model.dynamics import CLIP
from sandbox.model.law_kernel import overwrite_rows
from sandbox.model.laws import LawInputs, spread
from sandbox.physics.interface import Physics
from sandbox.plugins.registration import (
    LawContext,
    StrategyContext,
)
from sandbox.run.record import (
    MODE_EXTERNAL,
    MODE_FAILED,
    STATUS_DIVERGED,
    STATUS_INTERRUPTED,
    Run,
)
from sandbox.scenario import Scenario


class Simulation(Building, StepAPI, Ending, WorldStages):
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
            self._build([scenario], [world])

    @classmethod
    def stacked(
        cls,
        scenarios: Sequence[Scenario],
        worlds: Sequence[Physics | None] | None = None,
    ) -> Simulation:
        """K runs of one structure (:func:`~sandbox.loop.plan.structure_key`) at once.

        The step API then takes and gives one world at a time (``world=w``) or
        arrays with a leading world axis; :meth:`results` returns one
        :class:`~sandbox.Run` per world.

        Raises
        ------
        ValueError
            The scenarios differ in structure (:meth:`batch` groups them instead).
        """
        sim = cls.__new__(cls)
        scenarios = list(scenarios)
        with collector_off():
            sim._build(scenarios, list(worlds) if worlds else [None] * len(scenarios))
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
            groups.setdefault(structure_key(sc), []).append(k)
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
    # ------------------------------------------------------------------ stages
    def _sense(self) -> bool:
        """Read every live world's state at ``t_k``; False when none is left.

        A diverged world ends alone: its sample is recorded as it is (slots and
        targets NaN, the last commands and modes), its status becomes ``diverged``.
        """
        fleet, t = self.fleet, self.k * self.h
        pos, theta, vel = self.physics.read()
        if self.K > 1 and not self.live.all():
            chi = fleet.chi.reshape(self.K, self.n, 2)
            chi[~self.live] = 0.0
        fleet.pos, fleet.theta, fleet.vel = pos, theta, vel
        self.finite = diverged(fleet) is None
        if not self.finite:
            for w in self._live_worlds():
                bad = diverged(RowsView(fleet, self._rows(w)))
                if bad is None:
                    continue
                state = self.states[w]
                state.info["diverged"] = {
                    "t": t,
                    "vehicle": state.names[bad[0]],
                    "reason": bad[1],
                }
                self._end_world(w, STATUS_DIVERGED)
            self.finite = self.live.all() and diverged(fleet) is None
        if not self._n_live:
            return False
        if self._broadcast is not None:  # every world's copies, each its own draws
            self.seen = self._broadcast.update(pos, theta).copy()
        elif self._sensing:
            seen = np.zeros((self.N, 3)) if self.seen is None else self.seen.copy()
            for w in self._live_worlds():
                rows = self._rows(w)
                seen[rows] = self.states[w].broadcast.update(pos[rows], theta[rows])
            self.seen = seen
        self.believed = self.seen
        if self._estimate is not None:  # the detector and the filter keep the copies
            self.believed = self._estimate.update(self.seen, fleet.v1, fleet.v2)
        if self.range_sensor is not None:
            self.range_sensor.update(t, fleet.pos, fleet.theta)
        self._views_at = -1  # the worlds' views see this period's arrays and copies
        return True

    def _targets(self, t: float) -> tuple[np.ndarray, ...]:
        """Slots, reference point, and the law's ``x_ref'``, ``x_ref''`` at ``t``."""
        if self.platoons is not None:  # each platoon's own reference and law
            fl = self.fleet
            self._view_worlds()  # a platoon's reconfiguration reads its world's rows
            if self.K == 1:
                return self.platoons.targets(t, fl.pos, fl.theta, fl.vel, self.believed)
            return self._platoon_targets(t)
        K, n, N = self.K, self.n, self.N
        if self._law_kernel is not None:  # the law's period in one C call
            triple = self._kernel_targets()
            if triple is not None:
                return triple
        if self._ref_table is not None:
            k, (p, dp, ddp) = self.k, self._ref_table
            ref = (p[k], dp[k], ddp[k])
        elif self.reference is not None:
            ref = self.reference.evaluate(t)
        else:
            ref = None
        if self.law is None:
            triple = [np.zeros((N, 2)), np.zeros((N, 2)), np.zeros((N, 2))]
        elif self._law_per_world:
            triple = self._world_law_targets(t, ref)
        elif self._stacked_law is not None:
            triple = self._stacked_law.targets(self, t, ref)
        else:
            slot, v_ref, a_ref = self.law.targets(self._law_context(t, ref))
            if self._law_inputs:  # a built-in law class: (K, n, 2) float64 arrays
                triple = [slot.reshape(N, 2), v_ref.reshape(N, 2), a_ref.reshape(N, 2)]
            else:
                shape = (K, n, 2)
                triple = [
                    _world_rows(slot, shape),
                    _world_rows(v_ref, shape),
                    _world_rows(a_ref, shape),
                ]
        # the reference-tracking rows and the commanded ones (copies where any)
        slot, v_ref, a_ref = overwrite_rows(
            triple, ref, self._track_rows, self._commanded_rows
        )
        point = ref[0] if ref is not None else np.full(2, np.nan)
        return slot, v_ref, a_ref, point

    def _kernel_targets(self) -> tuple[np.ndarray, ...] | None:
        """:meth:`_targets` by the law's C call (plan_kernel.py); None: use numpy.

        Not for a law replaced since, or whose ``targets`` was (a spy, a wrapper).
        """
        law = self.law
        if law is not self._law_kernel.law or "targets" in law.__dict__:
            return None
        k, table, believed = self.k, self._kernel_table, self.believed
        if believed is None:
            pose, theta = self.fleet.pos, self.fleet.theta
        else:
            pose, theta = believed, None
        try:
            slot, v_ref, a_ref = self._law_kernel.targets(
                pose, theta, table, k, self._track_rows, self._commanded_rows
            )
        except (BufferError, TypeError, ValueError):  # not such arrays: numpy
            return None
        point = self._ref_table[0][k] if table is not None else np.full(2, np.nan)
        return slot, v_ref, a_ref, point

    def _law_context(self, t: float, ref: tuple | None) -> LawContext | LawInputs:
        """What the one law of all worlds sees: arrays with a leading world axis.

        A built-in law class gets the part it reads (its leader and the reference).
        """
        if self._law_inputs:
            return stacked_law_inputs(self, ref, self.leader)
        return stacked_law_context(
            self, t, ref, self.leader, self.law_params, self.law_memory
        )

    def _plan(self) -> None:
        """What the built-in stack does at ``t_k``: slots, failures, recovery.

        Evaluates the reference and the formation law, starts the failures due now,
        asks the detector what has failed, re-forms, and shifts the targets by the
        recovery strategy (eqs. (21)-(27)). The result is :attr:`plan`, which
        :meth:`observe` shows and :meth:`_act` consumes (with any overrides).
        """
        fleet, t = self.fleet, self.k * self.h
        slot, v_ref, a_ref, point = self._targets(t)
        failing = self._failing
        fs = self.failures
        if len(fs):
            new = fs.start_new(t, self.live, fleet.v2)
            for j in new:
                w = int(fs.world[j])
                if fs.immovable[j]:
                    self.physics.immobilize(w, int(fs.local[j]))
                self.states[w].failed_at.setdefault(fs.specs[j].vehicle, t)
            failing = fs.active_vehicles(t, self.live)
        # What the platoon believes has failed; everything below reacts to this,
        # never to the truth. The oracle: the truth, known at once.
        known = failing
        if self._detecting:
            known = self._detect(t, failing)
        self.known_failed = known
        if self._reconfiguring:  # re-forms when `known` changes
            self._reconfigure(t, known)
        if self.platoons is not None and self.K > 1:  # each world's platoons decide
            for w, s in enumerate(self.states):
                self._avoid_candidates[self._rows(w)] = s.platoons.avoid_candidates
        if not self._may_avoid_fixed:
            may_avoid = self._avoid_candidates & ~known
        elif self._may_avoid is None:  # the same every period (building.py)
            may_avoid = self._may_avoid = self._avoid_candidates & ~known
            may_avoid.flags.writeable = False
        else:
            may_avoid = self._may_avoid
        shifted = None
        if self._shift_kernel is not None:  # eqs. (22)-(27) in one C call
            shifted = self._kernel_shift(slot, may_avoid)
        if shifted is not None:
            target, shift, active = shifted
        else:
            shift, active = self._shift(t, slot, may_avoid, known)
            target = slot + shift  # eq. (22) / (26)
        if self.rec.target_derivatives == "estimate":
            d_shift, dd_shift = self.shift_motion.update(shift)
            v_ref = v_ref + d_shift
            a_ref = a_ref + dd_shift
        self._failing = failing
        if self.K > 1:
            point = spread(point, (self.K, 2))
        if self.K == 1 and not self.live[0]:
            return  # a plug-in failed: the plan stays undefined
        self.plan = Plan(slot, target, v_ref, a_ref, point, active, failing)

    def _shift(self, t, slot, may_avoid, known) -> tuple[np.ndarray, np.ndarray]:
        """The strategy's shift and avoiding vehicles of ``t`` (numpy, plug-ins)."""
        if self._strategy_per_world:
            shift, active = self._world_strategy(t, slot, may_avoid, known)
        else:
            shift, active = self.strategy(
                self._strategy_context(t, slot, may_avoid, known)
            )
        # a strategy never moves a vehicle that may not avoid (where every vehicle
        # may, a float (N, 2) shift is kept as it is: the same values; a built-in
        # one's stacked shift and flags are masked already)
        if self._strategy_per_world or not self._strategy_built_in:
            if not (
                type(shift) is np.ndarray
                and shift.dtype == np.float64
                and shift.shape == (self.N, 2)
                and np.count_nonzero(may_avoid) == self.N
            ):
                shift = np.where(may_avoid[:, None], shift, 0.0)
            active = np.asarray(active, dtype=bool) & may_avoid
        return shift, active

    def _kernel_shift(self, slot, may_avoid) -> tuple[np.ndarray, ...] | None:
        """Targets, shift, active by the strategy's C call; None: use numpy.

        Not for a strategy replaced since the loop was built.
        """
        if self.strategy is not self._kernel_strategy:
            return None
        try:
            return self._shift_kernel.shifted(
                self.fleet.pos, self.believed, may_avoid, slot
            )
        except (BufferError, TypeError, ValueError):  # not such arrays: numpy
            return None

    def _strategy_context(self, t, slot, may_avoid, known) -> StrategyContext:
        """The strategy's context of ``t``: a new one, or a built-in's one, updated.

        A built-in strategy reads its context during its call only, so one context
        serves it every period, its fields of the period set anew.
        """
        fl = self.fleet
        ctx = self._strategy_ctx
        if ctx is not None:
            ctx.t, ctx.slot, ctx.may_avoid, ctx.failed = t, slot, may_avoid, known
            ctx.pos, ctx.theta, ctx.vel = fl.pos, fl.theta, fl.vel
            ctx.obstacle_field, ctx.neighbours = self._avoid_field, self.neighbours
            ctx.params, ctx.R = self.strategy_params, self.rec.R
            ctx.seen_pos = None if self.believed is None else self.believed[:, :2]
            if self.range_sensor is not None:
                ctx.ranges = self.range_sensor.ranges
                ctx.beam_angles = self.range_sensor.beam_angles
            return ctx
        ctx = StrategyContext(
            t=t,
            dt=self.h,
            pos=fl.pos,
            theta=fl.theta,
            vel=fl.vel,
            slot=slot,
            diameter=fl.diameter,
            may_avoid=may_avoid,
            failed=known,
            params=self.strategy_params,
            R=self.rec.R,
            obstacle_field=self._avoid_field,
            neighbours=self.neighbours,
            seen_pos=None if self.believed is None else self.believed[:, :2],
            **context_fields(self.range_sensor),
        )
        if self._strategy_built_in:
            self._strategy_ctx = ctx
        return ctx

    def _act(
        self,
        commands: tuple[np.ndarray, np.ndarray] | None,
        targets: tuple[np.ndarray, np.ndarray] | None,
        shifts: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """Commands for the period from ``t_k``: controller, overrides, failures.

        Advances the flatness controller (eqs. (5)-(6)) for every vehicle towards the
        planned targets (or the overridden ones), filters them for safety, applies the
        open-loop schedules, the user's command overrides (within the vehicle's
        limits) and the failures, in that order. Sets ``fleet.v1, v2, failed, mode``;
        returns ``chi`` for ``t_k+1``.
        """
        fleet, plan, h, t = self.fleet, self.plan, self.h, self.k * self.h
        target, v_ref, a_ref = plan.target, plan.v_ref, plan.a_ref
        external = None
        if shifts is not None:
            # Moves the planned target; the law's feed-forward motion is kept.
            rows, external = shifts
            target = np.where(external[:, None], target + rows, target)
        if targets is not None:
            # A set-point: the given point, with no feed-forward motion.
            rows, mask = targets
            external = mask if external is None else external | mask
            target = np.where(mask[:, None], rows, target)
            v_ref = np.where(mask[:, None], 0.0, v_ref)
            a_ref = np.where(mask[:, None], 0.0, a_ref)
        chi_next, v1, v2 = self._controller.step(
            fleet.pos, fleet.chi, fleet.theta, target, v_ref, a_ref
        )
        cars = self._cars
        if cars is not None:  # the cars' rows by their own anti-windup (steering.py)
            cars.control(fleet, target, v_ref, a_ref, chi_next, v1, v2)
        if self._filter is not None:  # after the controller, before the failures
            v1, v2 = self._safety(t, v1, v2)
        # Vehicles not driven by the controller this period.
        passive = fleet.commanded
        if self._schedules:
            if external is not None:  # an override of the target drives the vehicle
                v1c, v2c = v1.copy(), v2.copy()
                self._schedules.apply(t, v1, v2)
                v1[external], v2[external] = v1c[external], v2c[external]
                passive = passive & ~external
            else:
                self._schedules.apply(t, v1, v2)
        if commands is not None:
            rows, mask = commands
            v1 = np.where(mask, self._command_limits(rows[:, 0]), v1)
            v2 = np.where(mask, CLIP(rows[:, 1], -self._v2_max, self._v2_max), v2)
            passive = passive | mask
            external = mask if external is None else external | mask
        if cars is not None:  # what a car executes: its steering's turn rate
            v2, steer = cars.steer(v1, v2, fleet.steer)
        if self._detection is not None:  # what the controllers ask for, broadcast
            intended = np.empty((len(v1), 2))  # np.column_stack's, in two copies
            intended[:, 0], intended[:, 1] = v1, v2
            self._detection.intended = intended
        elif self._detecting:
            for w in self._live_worlds():
                rows = self._rows(w)
                self.states[w].detection.intended = np.column_stack(
                    (v1[rows], v2[rows])
                )
        # The drive executes a failure within its acceleration limit (a crash aside).
        v1, v2, failed, frozen, errors = self.failures.apply(
            t, self.live, v1, v2, fleet.v1, self._accel_max * h
        )
        for w, exc in errors:  # a failure plug-in failed: its world ends now
            self._plugin_failed(w, exc)
        if cars is not None:  # a failure's commands steered too
            if len(self.failures):
                v2, steer = cars.steer(v1, v2, fleet.steer, steer, failed)
            fleet.steer = steer
        if self._detecting:
            # A failed controller does not know: it keeps its own state until the
            # failure ends (then it resumes from the applied velocity).
            frozen = frozen & ~self.failures.active_vehicles(t + h, self.live)
        # chi follows the applied velocity of passive vehicles, so that the law resumes
        # without a jump when the failure or the override ends.
        if len(self.failures):  # else no vehicle is frozen
            passive = frozen | passive
        if (passive is not fleet.commanded or len(self._commanded_rows)) and (
            np.count_nonzero(passive)
        ):
            rows = passive.nonzero()[0]
            theta, speed = fleet.theta[rows], v1[rows]
            chi_next[rows, 0] = speed * np.cos(theta)
            chi_next[rows, 1] = speed * np.sin(theta)
        fleet.v1, fleet.v2, fleet.failed = v1, v2, failed
        if len(self.failures):  # else never set: an episode now is healthy
            self.physics.failed[:] = failed  # an episode starting now is not healthy
        mode = plan.active.astype(np.int8)  # MODE_FORMATION 0, MODE_AVOID 1
        if external is not None:
            mode[external] = MODE_EXTERNAL
        if len(self.failures):  # else no vehicle has failed
            mode[failed] = MODE_FAILED
        fleet.mode = mode
        if external is not None:
            self._recorded_target = target
        return chi_next

    def _command_limits(self, v1: np.ndarray) -> np.ndarray:
        """User speeds within ``v1_max`` and, from the last speed, ``max_accel``."""
        v1 = np.clip(v1, -self._v1_max, self._v1_max)
        step = self._accel_max * self.h
        return np.clip(v1, self.fleet.v1 - step, self.fleet.v1 + step)

    def _record(self, plan: Plan) -> None:
        """The loop metrics, and the sample of ``t_k`` every ``record_every`` steps."""
        fleet = self.fleet
        contact = self.physics.in_contact()
        self._contact = contact
        self.tally.update(self, contact, None)
        if self.k % self.record_every:
            return
        target = self._recorded_target
        self.recorder.append(
            self.k * self.h,
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
            self._live_worlds(),
        )
        if self._cars is not None:
            self._cars.record(self.recorder.count - 1, fleet.steer)
        if self.range_sensor is not None:
            self.range_sensor.record()

    def _advance(self, chi_next: np.ndarray) -> None:
        """Write the commands to the physics and step it to ``t_k+1``."""
        fleet, h = self.fleet, self.h
        fleet.chi = chi_next
        tally = self.tally
        commanded = tally.commanded if tally.commanded_at == self.k else None
        contact = self._contact
        self.physics.advance(
            fleet.theta,
            fleet.v1,
            fleet.v2,
            commanded,
            self.physics.free_of(contact),
            self.k * h,
            h,
            first=self.k == 0,
        )
        self.k += 1

    def _step(
        self,
        commands: tuple[np.ndarray, np.ndarray] | None = None,
        targets: tuple[np.ndarray, np.ndarray] | None = None,
        should_stop: Callable[[], bool] | None = None,
        shifts: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """One control period: act, record, advance, sense and plan the next."""
        self._recorded_target = None
        start = time.perf_counter()
        try:
            chi_next = self._act(commands, targets, shifts)
        except PluginRunError as exc:  # a batched plug-in: every world ends
            for w in self._live_worlds():
                self._plugin_failed(w, exc)
            self._closed = True
            return
        self._control_time += time.perf_counter() - start
        self._record(self.plan)
        if not self._n_live:
            self._closed = True
            return
        if should_stop is not None and should_stop():
            self._stopped = True
            for w in self._live_worlds():
                self.states[w].info["interrupted"] = {"t": self.k * self.h}
                self._end_world(w, STATUS_INTERRUPTED, last=False)
            return
        self._advance(chi_next)
        if self._sense():
            start = time.perf_counter()
            self._guarded(self._plan)
            self._control_time += time.perf_counter() - start
        else:
            self._closed = True

    def _guarded(self, stage: Callable[[], None]) -> None:
        """Run a stage over all worlds; a plug-in that fails there ends every world."""
        try:
            stage()
        except PluginRunError as exc:
            for w in self._live_worlds():
                self._plugin_failed(w, exc)

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

    def _loop(self, progress, should_stop) -> bool:
        """Steps until done; True when ``should_stop`` stopped them."""
        report_every = max(1, self.steps // 100)
        with frozen_heap():
            while not self.done:
                k = self.k
                self._step(should_stop=should_stop)
                if self._stopped:
                    return True
                if progress is not None and k % report_every == 0 and k < self.k:
                    progress(k, self.steps)
        return False


def _world_rows(a: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """A law's array of every world, shape (K, n, 2) or broadcasting to it, as rows.

    Float64, shape (K n, 2): a view where it is float64 of the shape, else a new
    array of its values.
    """
    a = np.asarray(a, dtype=float)
    return (a if a.shape == shape else spread(a, shape)).reshape(-1, 2)


def simulate(scenario: Scenario, **kwargs) -> Run:
    """Run a scenario; return its :class:`~sandbox.Run` (:meth:`Simulation.run`)."""
    return Simulation(scenario).run(**kwargs)
