"""The fixed-step simulation loop, step-wise: sense, plan, act, record, advance.

Every control period ``h = dt`` runs these stages over whole-fleet arrays:

1. **sense** (:meth:`Simulation._sense`): read all vehicles' poses from the physics in
   one bulk call; a non-finite or runaway state ends the run as ``diverged``;
2. **plan** (:meth:`Simulation._plan`): evaluate the reference and the formation law
   (each vehicle's slot, ``x_ref'``, ``x_ref''``), start the failures due now, shift
   the targets by the recovery strategy (eqs. (21)-(27));
3. **act** (:meth:`Simulation._act`): advance the flatness controller (eqs. (5)-(6))
   for the whole fleet, then apply open-loop schedules, the user's overrides and the
   failures;
4. **record** a sample every ``record_every`` periods;
5. **advance**: write the commands to the physics and step it ``substeps`` times.

:meth:`Simulation.step` runs one period with optional overrides and returns an
:class:`~sandbox.loop.observation.Observation`; :meth:`Simulation.run` is the loop of
steps without overrides, and :meth:`Simulation.result` the recorded
:class:`~sandbox.Run`. The physics is reached only through the
:class:`~sandbox.physics.Physics` interface. Nothing here draws or computes metrics.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from sandbox.behaviour.detection import Detection
from sandbox.behaviour.reconfigure import Reconfiguration
from sandbox.behaviour.sensing import make_broadcast
from sandbox.errors import PluginRunError
from sandbox.geometry.neighbours import NeighbourList
from sandbox.loop.divergence import diverged
from sandbox.loop.observation import Observation, Overrides, override_rows
from sandbox.loop.platoons import Platoons
from sandbox.loop.run_info import run_description
from sandbox.loop.state import Fleet
from sandbox.model.failures import FailureSchedule
from sandbox.model.flatness import (
    Gains,
    advance_extension,
    extension_rate,
    flat_inputs,
)
from sandbox.model.laws import BackwardDifference
from sandbox.model.obstacle_field import ObstacleField
from sandbox.physics.interface import Physics
from sandbox.physics.world import World
from sandbox.plugins.registration import (
    FilterContext,
    LawContext,
    StrategyContext,
    get,
    make_law,
    runnable,
)
from sandbox.run.metrics import LoopMetrics
from sandbox.run.record import (
    MODE_AVOID,
    MODE_EXTERNAL,
    MODE_FAILED,
    MODE_FORMATION,
    STATUS_DIVERGED,
    STATUS_ERROR,
    STATUS_INTERRUPTED,
    STATUS_OK,
    Run,
)
from sandbox.run.recorder import Recorder
from sandbox.scenario import Scenario


class Simulation:
    """One run of a scenario.

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
    """

    def __init__(self, scenario: Scenario, world: Physics | None = None) -> None:
        self.scenario = scenario
        self.h = scenario.dt
        self.steps = int(round(scenario.duration / scenario.dt))
        self.fleet = Fleet.from_scenario(scenario)
        self.world: Physics = (
            world
            if world is not None
            else World(
                scenario.vehicles,
                scenario.obstacles,
                scenario.metrics.contact_release,
                scenario.substeps,
            )
        )
        self.names = [v.name for v in scenario.vehicles]
        self.leader = scenario.leader_index
        self.reference = scenario.reference.build() if scenario.reference else None
        law_spec = scenario.formation
        self.law = (
            make_law(law_spec.law, law_spec.params, self.fleet.offset, self.h)
            if law_spec
            else None
        )
        self.law_params = dict(law_spec.params) if law_spec else {}
        self.law_memory: dict = {}
        self.strategy = runnable(get("strategy", scenario.recovery.strategy))
        self.strategy_params = dict(scenario.recovery.params)
        self.obstacles = ObstacleField(scenario.obstacles)
        self.failures = FailureSchedule(scenario.failures, self.names)
        self.shift_motion = BackwardDifference(self.h)
        # The safety filter (safety:); None with filter none: not called at all.
        safety = scenario.safety
        self._filter = (
            None if safety.filter == "none" else runnable(get("filter", safety.filter))
        )
        self._filter_memory: dict = {}
        self._filter_stats: dict = {}
        self._filter_started = False
        # What the vehicles see of each other (None: the truth; behaviour.sensing).
        self.broadcast = make_broadcast(scenario.sensing, self.h, scenario.seed)
        self._sensing = asdict(scenario.sensing)
        #: The broadcast poses received at t_k, shape (n, 3), or None without sensing.
        self.seen: np.ndarray | None = None
        n = self.fleet.n
        # Vehicles that track the reference itself (eq. (6)) rather than a slot.
        self.tracks_reference = np.zeros(n, dtype=bool)
        if self.law is None:
            self.tracks_reference[:] = True
        elif get("law", law_spec.law).options["needs_leader"] and self.leader >= 0:
            self.tracks_reference[self.leader] = True
        self.tracks_reference &= ~self.fleet.commanded
        self._schedules = {
            i: np.array(v.drive.schedule, dtype=float)
            for i, v in enumerate(scenario.vehicles)
            if v.drive.type == "commands"
        }
        self._track_rows = np.flatnonzero(self.tracks_reference)
        self._commanded_rows = np.flatnonzero(self.fleet.commanded)
        # Every time at which some schedule changes row, and the rows in force now.
        self._schedule_rows = np.array(list(self._schedules), dtype=np.intp)
        self._schedule_changes = np.unique(
            np.concatenate([tab[:, 0] for tab in self._schedules.values()] or [[]])
        )
        self._scheduled = np.zeros((len(self._schedules), 2))
        self._next_change = 0
        # Parameters shared by the whole fleet are used as scalars on the hot path (the
        # same values, broadcast, without streaming (n,) arrays through every step).
        fl = self.fleet
        keys = ("k1", "k2", "k3", "k4", "kp")
        self._gains = Gains(**{k: _uniform(getattr(fl.gains, k)) for k in keys})
        self._v1_max = _uniform(fl.v1_max)
        self._v2_max = _uniform(fl.v2_max)
        self._accel_max = _uniform(fl.accel_max)
        # The turn-rate limit of the anti-windup: None when no vehicle has one.
        self._turn_max = None if np.all(np.isinf(fl.v2_max)) else self._v2_max
        # The loop's state: step index, record, status, and what recovery needs.
        self.rec = scenario.recovery
        self._avoid_candidates = ~fl.commanded
        if not self.rec.leader_avoids and self.leader >= 0:
            self._avoid_candidates[self.leader] = False
        self._neighbours = NeighbourList(self.rec.R)
        self._has_failures = len(self.failures.specs) > 0
        self._failing = np.zeros(n, dtype=bool)
        #: The vehicles the platoon believes failed at t_k, shape (n,) bool.
        self.known_failed = np.zeros(n, dtype=bool)
        # How it learns of failures: None = the oracle (the truth, at once).
        self.detection = Detection.make(scenario, self.names)
        self.k = 0
        self.status = STATUS_OK
        self.info = run_description(scenario, self.reference)
        self.failed_at: dict[str, float] = {}
        self.recorder = Recorder(self.steps // scenario.record_every + 1, n)
        self.tally = LoopMetrics(n, self.h)  # effort, closest approach, motor check
        self.plan: Plan | None = None
        self._recorded_target: np.ndarray | None = None
        self._closed = False
        self._run: Run | None = None
        self._wall = time.perf_counter()
        #: Wall time spent planning and acting (law, recovery, controller, filters).
        self._control_time = 0.0
        # Platoons hook (loop/platoons.py): with platoons:, each platoon's law,
        # recovery and filter on its rows (it sets strategy, _filter,
        # _avoid_candidates); None with one platoon.
        self.platoons = Platoons.attach(self)
        # Slot reassignment and leader handover on events (None: keep every slot).
        self.reconfiguration = Reconfiguration.build(self)
        if self._sense():
            self._guarded(self._plan)

    # ------------------------------------------------------------------ helpers
    def _scheduled_commands(self, t: float, v1: np.ndarray, v2: np.ndarray) -> None:
        """Overwrite the open-loop vehicles' commands with their schedules at ``t``.

        A row ``(t_k, v1, v2)`` holds from ``t_k`` until the next row (zero before the
        first). The rows in force are looked up only when ``t`` passes a row time of
        some schedule, so a step costs two array writes however many such vehicles.
        """
        changes, now = self._schedule_changes, t + 1e-12
        if self._next_change < len(changes) and changes[self._next_change] <= now:
            self._next_change = int(np.searchsorted(changes, now, side="right"))
            for k, table in enumerate(self._schedules.values()):
                row = np.searchsorted(table[:, 0], now, side="right") - 1
                self._scheduled[k] = (table[row, 1], table[row, 2]) if row >= 0 else 0.0
        v1[self._schedule_rows] = self._scheduled[:, 0]
        v2[self._schedule_rows] = self._scheduled[:, 1]

    def law_context(
        self,
        t: float,
        ref: tuple[np.ndarray, ...] | None,
        offset: np.ndarray | None = None,
        memory: dict | None = None,
    ) -> LawContext:
        """What the formation law sees at ``t``, the reference ``ref`` evaluated there.

        The followers read the leader's broadcast pose (the truth without sensing).
        ``offset`` and ``memory`` default to the fleet's offsets and the law's memory;
        a reconfiguration passes others to try or re-seed the law.
        """
        fleet, lead, seen = self.fleet, self.leader, self.seen
        if lead < 0:
            leader_pos = leader_theta = None
        elif seen is None:
            leader_pos, leader_theta = fleet.pos[lead], float(fleet.theta[lead])
        else:
            leader_pos, leader_theta = seen[lead, :2], float(seen[lead, 2])
        return LawContext(
            t=t,
            dt=self.h,
            pos=fleet.pos,
            theta=fleet.theta,
            vel=fleet.vel,
            offset=fleet.offset if offset is None else offset,
            leader=lead,
            leader_pos=leader_pos,
            leader_theta=leader_theta,
            reference=ref,
            params=self.law_params,
            memory=self.law_memory if memory is None else memory,
        )

    def _targets(self, t: float) -> tuple[np.ndarray, ...]:
        """Slots, reference point, and the law's ``x_ref'``, ``x_ref''`` at ``t``."""
        if self.platoons is not None:  # platoons hook: each platoon's own law
            fl = self.fleet
            return self.platoons.targets(t, fl.pos, fl.theta, fl.vel, self.seen)
        n = self.fleet.n
        ref = self.reference.evaluate(t) if self.reference is not None else None
        if self.law is not None:
            triple = self.law.targets(self.law_context(t, ref))
        else:
            triple = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2))
        tr, cmd = self._track_rows, self._commanded_rows
        if (ref is not None and len(tr)) or len(cmd):
            # Copies: the law may keep (or broadcast) what it returned.
            slot, v_ref, a_ref = (np.array(a, dtype=float) for a in triple)
            if ref is not None:
                slot[tr], v_ref[tr], a_ref[tr] = ref[0], ref[1], ref[2]
            slot[cmd] = np.nan
        else:  # nothing to overwrite: read-only use downstream, no copies needed
            slot, v_ref, a_ref = (np.asarray(a, dtype=float) for a in triple)
        point = ref[0] if ref is not None else np.full(2, np.nan)
        return slot, v_ref, a_ref, point

    # ------------------------------------------------------------------ stages
    def _sense(self) -> bool:
        """Read the fleet state from the physics at ``t_k``; False if it diverged.

        A diverged state ends the run: its sample is recorded as it is (slots and
        targets NaN, the last commands and modes) and the status becomes ``diverged``.
        """
        fleet, t = self.fleet, self.k * self.h
        state = self.world.read_state()
        fleet.pos, fleet.theta, fleet.vel = state.pos, state.theta, state.vel
        bad = diverged(fleet)
        if bad is None:
            if self.broadcast is not None:
                self.seen = self.broadcast.update(fleet.pos, fleet.theta)
            return True
        n = fleet.n
        self.status = STATUS_DIVERGED
        self.info["diverged"] = {
            "t": t,
            "vehicle": self.names[bad[0]],
            "reason": bad[1],
        }
        self.plan = Plan.undefined(n, failed=fleet.failed)
        self._record(self.plan, fleet.mode, fleet.failed, always=True)
        self._finish()
        return False

    def _plan(self) -> None:
        """What the built-in stack would do at ``t_k``: slots, failures, recovery.

        Evaluates the reference and the formation law (slots and the law's
        ``x_ref'``, ``x_ref''``), starts the failures due now, and shifts the targets
        by the recovery strategy (eqs. (21)-(27)). The result is :attr:`plan`, which
        :meth:`observe` shows and :meth:`_act` consumes (with any overrides).
        """
        fleet, t, n, rec = self.fleet, self.k * self.h, self.fleet.n, self.rec
        slot, v_ref, a_ref, point = self._targets(t)
        failing = self._failing
        if self._has_failures:
            new = self.failures.start_new(t, fleet.v2)
            for i in self.failures.immovable(new):
                self.world.immobilize(i)
            for j in new:
                self.failed_at.setdefault(self.failures.specs[j].vehicle, t)
            failing = np.zeros(n, dtype=bool)
            failing[self.failures.vehicle[self.failures.active(t)]] = True
        # What the platoon believes has failed; everything below reacts to this,
        # never to the truth. The oracle: the truth, known at once.
        known = failing
        if self.detection is not None:  # else what the detector has found
            known = self.detection.update(self, t, failing)
        self.known_failed = known
        if self.reconfiguration is not None:  # re-forms when `known` changes
            self.reconfiguration.react(self, t, known)
        may_avoid = self._avoid_candidates & ~known
        shift, active = self.strategy(
            StrategyContext(
                t=t,
                dt=self.h,
                pos=fleet.pos,
                theta=fleet.theta,
                vel=fleet.vel,
                slot=slot,
                diameter=fleet.diameter,
                may_avoid=may_avoid,
                failed=known,
                params=self.strategy_params,
                R=rec.R,
                obstacle_field=self.obstacles,
                neighbours=self._neighbours,
                seen_pos=None if self.seen is None else self.seen[:, :2],
            )
        )
        # a strategy never moves a vehicle that may not avoid
        shift = np.where(may_avoid[:, None], shift, 0.0)
        active = np.asarray(active, dtype=bool) & may_avoid
        target = slot + shift  # eq. (22) / (26)
        if rec.target_derivatives == "estimate":
            d_shift, dd_shift = self.shift_motion.update(shift)
            v_ref = v_ref + d_shift
            a_ref = a_ref + dd_shift
        self._failing = failing
        self.plan = Plan(slot, target, v_ref, a_ref, point, active, failing)

    def _act(
        self,
        commands: tuple[np.ndarray, np.ndarray] | None,
        targets: tuple[np.ndarray, np.ndarray] | None,
        shifts: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """Commands for the period from ``t_k``: controller, overrides, failures.

        Advances the flatness controller (eqs. (5)-(6)) for the whole fleet towards
        the planned targets (or the overridden ones), applies the open-loop schedules,
        the user's command overrides (within the vehicle's limits) and the failures, in
        that order. Sets ``fleet.v1, v2, failed, mode``; returns ``chi`` for ``t_k+1``.
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
        aim = np.where(np.isnan(target), fleet.pos, target)

        gains = self._gains
        chi_dot = extension_rate(fleet.pos, fleet.chi, aim, v_ref, a_ref, gains)
        aim = None
        if self._turn_max is None:
            chi_next, chi_dot = advance_extension(
                fleet.chi, chi_dot, h, self._v1_max, self._accel_max
            )
        else:  # the turn-rate limit of the anti-windup
            chi_next, chi_dot, aim = advance_extension(
                fleet.chi,
                chi_dot,
                h,
                self._v1_max,
                self._accel_max,
                fleet.theta,
                self._turn_max,
            )
        v1, v2 = flat_inputs(fleet.theta, fleet.chi, chi_dot, gains.kp, aim)
        v2 = np.clip(v2, -self._v2_max, self._v2_max)
        if self._filter is not None:  # after the controller, before the failures
            v1, v2 = self._safety(t, v1, v2)
        # Vehicles not driven by the controller this period.
        passive = fleet.commanded
        if self._schedules:
            if external is not None:  # an override of the target drives the vehicle
                v1c, v2c = v1.copy(), v2.copy()
                self._scheduled_commands(t, v1, v2)
                v1[external], v2[external] = v1c[external], v2c[external]
                passive = passive & ~external
            else:
                self._scheduled_commands(t, v1, v2)
        if commands is not None:
            rows, mask = commands
            v1 = np.where(mask, self._command_limits(rows[:, 0]), v1)
            v2 = np.where(mask, np.clip(rows[:, 1], -self._v2_max, self._v2_max), v2)
            passive = passive | mask
            external = mask if external is None else external | mask
        if self.detection is not None:  # what the controllers ask for, broadcast
            self.detection.intended = np.column_stack((v1, v2))
        # The drive executes a failure within its acceleration limit (a crash aside).
        v1, v2, failed, frozen = self.failures.apply(
            t, v1, v2, fleet.v1, self._accel_max * h
        )
        if self.detection is not None:
            # A failed controller does not know: it keeps its own state until the
            # failure ends (then it resumes from the applied velocity).
            frozen = frozen & ~self.failures.active_vehicles(t + h)
        # chi follows the applied velocity of passive vehicles, so that the law resumes
        # without a jump when the failure or the override ends.
        passive = frozen | passive
        if np.any(passive):
            heading = np.stack((np.cos(fleet.theta), np.sin(fleet.theta)), -1)
            chi_next[passive] = v1[passive, None] * heading[passive]

        fleet.v1, fleet.v2, fleet.failed = v1, v2, failed
        self.world.failed = failed  # an episode starting now is not healthy
        mode = np.full(fleet.n, MODE_FORMATION, dtype=np.int8)
        mode[plan.active] = MODE_AVOID
        if external is not None:
            mode[external] = MODE_EXTERNAL
        mode[failed] = MODE_FAILED
        fleet.mode = mode
        if external is not None:
            self._recorded_target = target
        return chi_next

    def _safety(
        self, t: float, v1: np.ndarray, v2: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The safety filter's commands for the period (``safety:``)."""
        fleet, started = self.fleet, self._filter_started
        self._filter_started = True
        out = self._filter(
            FilterContext(
                t=t,
                dt=self.h,
                pos=fleet.pos,
                theta=fleet.theta,
                vel=fleet.vel,
                v1=v1,
                v2=v2,
                diameter=fleet.diameter,
                params=dict(self.scenario.safety.params),
                v1_prev=fleet.v1 if started else None,
                v2_prev=fleet.v2 if started else None,
                v1_max=self._v1_max,
                v2_max=self._v2_max,
                accel_max=self._accel_max,
                known_failed=self.known_failed,
                commanded=fleet.commanded,
                obstacle_field=self.obstacles,
                seen=self.seen,
                sensing=None if self.broadcast is None else self._sensing,
                memory=self._filter_memory,
                stats=self._filter_stats,
            )
        )
        n = fleet.n
        return (
            np.broadcast_to(np.asarray(out[0], dtype=float), (n,)).copy(),
            np.broadcast_to(np.asarray(out[1], dtype=float), (n,)).copy(),
        )

    def _command_limits(self, v1: np.ndarray) -> np.ndarray:
        """User speeds within ``v1_max`` and, from the last speed, ``max_accel``."""
        v1 = np.clip(v1, -self._v1_max, self._v1_max)
        step = self._accel_max * self.h
        return np.clip(v1, self.fleet.v1 - step, self.fleet.v1 + step)

    def _record(
        self, plan: Plan, mode: np.ndarray, failed: np.ndarray, always: bool = False
    ) -> None:
        """Append the sample of ``t_k`` (every ``record_every`` steps, or now)."""
        fleet = self.fleet
        contact = getattr(self.world, "in_contact", None)
        self.tally.update(
            fleet.pos,
            fleet.theta,
            fleet.vel,
            fleet.v1,
            fleet.v2,
            None if contact is None else contact(),
        )
        if self.k % self.scenario.record_every and not always:
            return
        target = self._recorded_target
        self.recorder.append(
            self.k * self.h,
            _pose(fleet),
            _cmd(fleet),
            fleet.chi,
            plan.slot,
            plan.target if target is None else target,
            mode,
            failed,
            plan.point,
        )

    def _advance(self, chi_next: np.ndarray) -> None:
        """Write the commands to the physics and step it to ``t_k+1``."""
        fleet, h = self.fleet, self.h
        fleet.chi = chi_next
        self.world.write_commands(fleet.theta, fleet.v1, fleet.v2, h)
        self.world.step(h, self.scenario.substeps, self.k * h)
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
        except PluginRunError as exc:
            self._plugin_failed(exc)
            return
        self._control_time += time.perf_counter() - start
        self._record(self.plan, self.fleet.mode, self.fleet.failed)
        if should_stop is not None and should_stop():
            self.status = STATUS_INTERRUPTED
            self.info["interrupted"] = {"t": self.k * self.h}
            self._finish()
            return
        self._advance(chi_next)
        if self._sense():
            start = time.perf_counter()
            self._guarded(self._plan)
            self._control_time += time.perf_counter() - start

    def _guarded(self, stage: Callable[[], None]) -> None:
        """Run a stage that calls plug-ins; one that fails ends the run."""
        try:
            stage()
        except PluginRunError as exc:
            self._plugin_failed(exc)

    def _plugin_failed(self, exc: PluginRunError) -> None:
        """End the run with status ``error``: a plug-in raised or returned NaN.

        The sample of the time it happened is recorded as a diverged state's is (the
        plan undefined, the last commands), and ``info["error"]`` names the plug-in.
        """
        fleet = self.fleet
        self.status = STATUS_ERROR
        self.info["error"] = {
            "t": self.k * self.h,
            "plugin": exc.plugin,
            "message": exc.message,
        }
        self.plan = Plan.undefined(fleet.n, failed=fleet.failed)
        self._record(self.plan, fleet.mode, fleet.failed, always=True)
        self._finish()

    def _finish(self) -> None:
        self._closed = True

    # ------------------------------------------------------------------ the API
    @property
    def t(self) -> float:
        """Current simulated time ``t_k = k h`` [s]."""
        return self.k * self.h

    @property
    def done(self) -> bool:
        """Whether the run has reached its duration, diverged or been stopped."""
        return self._closed or self.k >= self.steps

    def observe(self) -> Observation:
        """The fleet now, and what the built-in stack plans for this period (copies)."""
        fleet, plan = self.fleet, self.plan
        return Observation(
            t=self.k * self.h,
            names=tuple(self.names),
            pose=_pose(fleet),
            vel=fleet.vel.copy(),
            chi=fleet.chi.copy(),
            slot=np.array(plan.slot, dtype=float),
            target=np.array(plan.target, dtype=float),
            mode=plan.mode(fleet.n) if not self._closed else fleet.mode.copy(),
            failed=plan.failing.copy(),
            platoon=None if self.platoons is None else self.platoons.of_vehicles(),
        )

    def step(
        self,
        commands: Overrides = None,
        targets: Overrides = None,
        shifts: Overrides = None,
    ) -> Observation:
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

        Returns
        -------
        Observation
            At the next step ``t_k+1``.

        Raises
        ------
        RuntimeError
            When the run is :attr:`done`.
        ValueError
            An unknown vehicle name or a malformed value.
        """
        if self.done:
            raise RuntimeError(
                f"the run is over (status {self.status!r} at t = {self.t:g} s); "
                "call result()"
            )
        cmd = override_rows(commands, self.names, "commands")
        tgt = override_rows(targets, self.names, "targets")
        shf = override_rows(shifts, self.names, "shifts")
        self._step(cmd, tgt, shifts=shf)
        return self.observe()

    def result(self) -> Run:
        """The recorded run so far (the whole run once :attr:`done`).

        The sample of the last time is recorded with the controller's own commands.
        Called before the run is done, the run ends here with status ``interrupted``.
        Further calls return the same :class:`~sandbox.run.record.Run`.
        """
        if self._run is not None:
            return self._run
        if not self._closed:
            if self.k < self.steps:
                self.status = STATUS_INTERRUPTED
                self.info["interrupted"] = {"t": self.k * self.h}
            self._recorded_target = None
            try:
                self._act(None, None)
            except PluginRunError as exc:
                self._plugin_failed(exc)
            else:
                self._record(self.plan, self.fleet.mode, self.fleet.failed)
                self._finish()
        sc, info = self.scenario, self.info
        info["failed_at"] = self.failed_at
        if self.detection is not None:
            info["detection"] = self.detection.summary()
        info["loop_metrics"] = self.tally.result()
        info["wall_time"] = time.perf_counter() - self._wall
        info["control_time"] = self._control_time
        if self._filter is not None:
            info["safety"] = {
                "filter": sc.safety.filter,
                "infeasible_steps": 0,
                "active_steps": 0,
                **self._filter_stats,
            }
        info["steps"] = self.k
        self._run = Run(
            names=list(self.names),
            colors=[v.color for v in sc.vehicles],
            diameter=self.fleet.diameter.copy(),
            leader=self.leader,
            events=list(self.world.events),
            status=self.status,
            info=info,
            scenario=sc,
            **self.recorder.arrays(),
        )
        return self._run

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
        report_every = max(1, self.steps // 100)
        while not self.done:
            k = self.k
            self._step(should_stop=should_stop)
            if progress is not None and k % report_every == 0 and k < self.k:
                progress(k, self.steps)
        return self.result()


@dataclass
class Plan:
    """What the built-in stack plans for one period, arrays indexed by vehicle.

    Attributes
    ----------
    slot, target : ndarray, shape (n, 2) [m]
        Formation slots, and the slots shifted by recovery; NaN where undefined.
    v_ref, a_ref : ndarray, shape (n, 2) [m/s], [m/s^2]
        The law's ``x_ref'``, ``x_ref''`` (plus the shift's, when estimated).
    point : ndarray, shape (2,) [m]
        The reference point (NaN without a reference).
    active : ndarray, shape (n,), bool
        Vehicles whose target recovery shifts.
    failing : ndarray, shape (n,), bool
        Vehicles with an active failure.
    """

    slot: np.ndarray
    target: np.ndarray
    v_ref: np.ndarray
    a_ref: np.ndarray
    point: np.ndarray
    active: np.ndarray
    failing: np.ndarray

    @classmethod
    def undefined(cls, n: int, failed: np.ndarray) -> Plan:
        """The plan of a diverged state: nothing defined."""
        nan = np.full((n, 2), np.nan)
        return cls(
            nan, nan, nan, nan, np.full(2, np.nan), np.zeros(n, bool), failed.copy()
        )

    def mode(self, n: int) -> np.ndarray:
        """Planned ``run.MODE_*`` codes, shape (n,), int8."""
        mode = np.full(n, MODE_FORMATION, dtype=np.int8)
        mode[self.active] = MODE_AVOID
        mode[self.failing] = MODE_FAILED
        return mode


def _pose(fleet: Fleet) -> np.ndarray:
    return np.concatenate((fleet.pos, fleet.theta[:, None]), axis=1)


def _cmd(fleet: Fleet) -> np.ndarray:
    return np.stack((fleet.v1, fleet.v2), axis=1)


def _uniform(values: np.ndarray) -> float | np.ndarray:
    """``values[0]`` as a scalar when every entry equals it, else ``values`` itself."""
    first = values[0]
    return float(first) if np.all(values == first) else values


def simulate(scenario: Scenario, **kwargs) -> Run:
    """Run a scenario; return its :class:`~sandbox.Run` (:meth:`Simulation.run`)."""
    return Simulation(scenario).run(**kwargs)
