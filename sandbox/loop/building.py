"""How the loop is built: K worlds of one structure on stacked arrays, and its stages.

:meth:`Building._build` makes, from the scenarios of one structure, the stacked
fleet, the physics of every world, the law, the strategy, the failures, the
controller and its limits, sensing, detection, safety, the records and the loop
metrics that :class:`~sandbox.loop.simulation.Simulation`'s stages use every period.
:class:`Building` is a part of :class:`~sandbox.loop.simulation.Simulation`, kept
apart for its length.
"""

from __future__ import annotations

import inspect
import time

import numpy as np

from sandbox.behaviour.detection import Detection
from sandbox.behaviour.estimation import platoon_estimate
from sandbox.behaviour.ranges import (
    RangeSensor,
    StackedRanges,
    avoid_field,
)
from sandbox.behaviour.reconfigure import Reconfiguration
from sandbox.behaviour.sensing import StackedBroadcast
from sandbox.geometry.neighbours import BRUTE_FORCE_MAX, NeighbourList, WorldPairs
from sandbox.loop.plan import Plan, structure_key
from sandbox.loop.plan_kernel import law_kernel_of, reference_table, shift_kernel_of
from sandbox.loop.platoon_sections import StackedSections
from sandbox.loop.platoons import Platoons
from sandbox.loop.recording import WorldsRecorder
from sandbox.loop.stacked_law import StackedLaw
from sandbox.loop.state import Fleet, uniform
from sandbox.loop.steering import CarDrive
from sandbox.loop.stepping import WorldsPhysics
from sandbox.loop.tally import LoopTally
from sandbox.loop.worlds import (
    StackedCommands,
    StackedDifference,
    StackedFailures,
    WorldDifference,
    WorldState,
)
from sandbox.model.flatness import Gains
from sandbox.model.kernels import Controller
from sandbox.model.references import TABULATED_REFERENCES
from sandbox.physics.interface import Physics
from sandbox.physics.world import World
from sandbox.plugins.registration import (
    get,
    make_law,
    runnable,
)
from sandbox.run.record import (
    Run,
)
from sandbox.scenario import Scenario


class Building:
    """How :class:`~sandbox.loop.simulation.Simulation` is built."""

    def _build(self, scenarios: list[Scenario], worlds: list[Physics | None]) -> None:
        first = scenarios[0]
        self.scenario = first
        self.K = K = len(scenarios)
        self.h = first.dt
        self.steps = int(round(first.duration / first.dt))
        self.substeps, self.record_every = first.substeps, first.record_every
        physics = [
            w
            if w is not None
            else World(
                sc.vehicles, sc.obstacles, sc.metrics.contact_release, sc.substeps
            )
            for sc, w in zip(scenarios, worlds, strict=True)
        ]
        fleets = [Fleet.from_scenario(sc) for sc in scenarios]
        self.states = [
            WorldState(sc, w, f)
            for sc, w, f in zip(scenarios, physics, fleets, strict=True)
        ]
        if K > 1:
            keys = {structure_key(sc) for sc in scenarios}
            if len(keys) > 1:
                raise ValueError(
                    "Simulation.stacked: the scenarios differ in structure; "
                    "use Simulation.batch, which groups them"
                )
        self.n = n = fleets[0].n
        self.N = N = K * n
        self.fleet = Fleet.stack(fleets)
        self.physics = WorldsPhysics(physics, n, self.substeps)
        self.live = np.ones(K, dtype=bool)
        self._n_live = K  # worlds live (what np.count_nonzero(self.live) counts)
        s0 = self.states[0]
        self.rec = s0.rec
        self.reference = s0.reference
        self._ref_table = None
        if type(self.reference) in TABULATED_REFERENCES:
            times = np.array([k * self.h for k in range(self.steps + 1)])
            self._ref_table = self.reference.evaluate(times)
        self._setup_law(first)
        self._setup_strategy()
        self._setup_limits()
        self.failures = StackedFailures([s.failures for s in self.states], n)
        self.shift_motion = StackedDifference(self.h, K, n)
        for w, state in enumerate(self.states):
            state.shift_motion = WorldDifference(self.shift_motion, w)
        # Stacked flags of which each world's are views (a reconfiguration edits them).
        self.tracks_reference = np.concatenate(
            [s.tracks_reference for s in self.states]
        )
        self._avoid_candidates = np.concatenate(
            [s._avoid_candidates for s in self.states]
        )
        for w, state in enumerate(self.states):
            rows = slice(w * n, (w + 1) * n)
            state.tracks_reference = self.tracks_reference[rows]
            state._avoid_candidates = self._avoid_candidates[rows]
        self._track_rows = np.flatnonzero(self.tracks_reference)
        self._commanded_rows = np.flatnonzero(self.fleet.commanded)
        self._sensing = s0.broadcast is not None
        self._broadcast = (
            StackedBroadcast([s.broadcast for s in self.states], n)
            if self._sensing and K > 1
            else None
        )
        self.seen: np.ndarray | None = None
        # what the law and the recovery see: the copies, or their estimate (braking)
        self.believed: np.ndarray | None = None
        self._estimate = platoon_estimate(first, self.h, self.substeps)
        safety = first.safety
        self._filter = (
            None if safety.filter == "none" else runnable(get("filter", safety.filter))
        )
        self._filter_started = False
        self._filter_batched = safety.filter != "none" and bool(
            get("filter", safety.filter).options.get("batched", False)
        )
        self._filter_memory: dict = {}
        self._failing = np.zeros(N, dtype=bool)
        self.known_failed = np.zeros(N, dtype=bool)
        for state in self.states:
            state.detection = Detection.make(state.scenario, state.names)
        self._detecting = s0.detection is not None
        # A batched detector: one for the rows of all worlds (K > 1).
        self._detection: Detection | None = None
        if self._detecting and K > 1:
            if get("detector", first.detection.method).options.get("batched"):
                self._detection = Detection.stack([s.detection for s in self.states])
        self._schedules = StackedCommands(self.states, n)
        self.k = 0
        self.recorder = WorldsRecorder(self.steps // self.record_every + 1, K, n)
        self._cars = CarDrive.build(
            self.fleet, K, n, self.h, self.steps // self.record_every + 1
        )
        self.tally = LoopTally(K, n, self.h)
        self.plan: Plan | None = None
        self._recorded_target: np.ndarray | None = None
        self._closed = False
        self._runs: dict[int, Run] = {}
        self._stopped = False
        self._wall = time.perf_counter()
        #: Wall time spent planning and acting (law, recovery, controller, filters).
        self._control_time = 0.0
        self._views_at = -1
        self._view_worlds()
        # Several platoons (loop/platoons.py): each platoon's law, recovery and filter
        # on its rows, world by world (attach sets strategy, filter and avoiders).
        for state in self.states:
            state.platoons = Platoons.attach(state)
        self.platoons = self.states[0].platoons
        if self.platoons is not None:
            s0 = self.states[0]
            self.strategy, self._filter = s0.strategy, s0._filter
            self._strategy_per_world = self.K > 1
            self._filter_batched = False
            sections = StackedSections.build(self)  # each section once for all worlds
            if sections is not None:
                self.strategy, self._strategy_per_world = sections.strategy, False
                if self._filter is not None:
                    self._filter, self._filter_batched = sections.filter, True
            if self.K == 1:
                self._avoid_candidates = s0._avoid_candidates
            for state in self.states:
                state.filter = state._filter
        for state in self.states:  # slot reassignment and leader handover on events
            state.reconfiguration = Reconfiguration.build(state)
        self._reconfigurable = np.array(
            [s.reconfiguration is not None for s in self.states]
        )
        self._reconfiguring = bool(self._reconfigurable.any())
        # Without failures, detection, reconfiguration and platoons, what the platoon
        # believes has failed and who may avoid never change: made at the first plan.
        self._may_avoid_fixed = not (
            len(self.failures)
            or self._detecting
            or self._reconfiguring
            or self.states[0].platoons is not None
        )
        self._may_avoid: np.ndarray | None = None
        # What each world's reconfiguration last saw, and the worlds it waits on.
        self._reacted, self._waiting = np.zeros(N, dtype=bool), set()
        # Range sensors (sensors.range; None without; one world, structure_key) and
        # where recovery and the safety filter find the static obstacles.
        sensors = [
            RangeSensor.make(s.scenario, s.world, self.obstacles) for s in self.states
        ]
        self.range_sensor = sensors[0]
        if K > 1 and sensors[0] is not None:  # each world casts in its own world
            self.range_sensor = StackedRanges(sensors, n)
        self._avoid_field = avoid_field(self.range_sensor, self.obstacles, self.rec)
        for w, state in enumerate(self.states):
            state.range_sensor = sensors[w]
        # the plan's law and strategy as C calls where they cover them (plan_kernel)
        self._law_kernel = law_kernel_of(self)
        self._kernel_table = reference_table(self) if self._law_kernel else None
        self._shift_kernel = shift_kernel_of(self)
        self._kernel_strategy = self.strategy  # what the strategy's C call replaces
        if self._sense():
            self._guarded(self._plan)

    def _setup_law(self, first: Scenario) -> None:
        """One law for all worlds, or each world's own (see the module docstring)."""
        spec = first.formation
        self.law_params = dict(spec.params) if spec else {}
        self.law_memory: dict = {}
        self._stacked_law: StackedLaw | None = None
        per_world = False
        if spec is not None:
            plugin = get("law", spec.law)
            reconfigure = first.reconfigure.assign != "none" or (
                first.on_leader_failure != "keep"
            )
            per_world = not plugin.options.get("batched", False)
            if reconfigure and not per_world:  # worlds re-form apart (stacked_law.py)
                built_in = plugin.origin.startswith("built-in")
                per_world = self.K == 1 or not built_in
                if not per_world:
                    self._stacked_law = StackedLaw(self)
        self._law_per_world = per_world
        # A built-in law class reads the leader and the reference only (LawInputs).
        self._law_inputs = (
            spec is not None
            and plugin.origin.startswith("built-in")
            and inspect.isclass(plugin.obj)
        )
        self.leader = first.leader_index
        if self._stacked_law is not None:
            self.law = self._stacked_law.law
            return
        if spec is None or per_world:
            self.law = None if spec is None else self.states[0].law
            if self.K == 1:  # the world's own law: its memory and parameters
                self.law_memory = self.states[0].law_memory
                self.law_params = self.states[0].law_params
            return
        offset = self.fleet.offset.reshape(self.K, self.n, 2)
        self.law = make_law(spec.law, spec.params, offset, self.h)

    def _setup_strategy(self) -> None:
        s0 = self.states[0]
        self.strategy = s0.strategy
        plugin = get("strategy", s0.scenario.recovery.strategy)
        self._strategy_per_world = not plugin.options.get("batched", False)
        # A built-in strategy keeps no context (one serves every period) and moves no
        # vehicle that may not avoid (its shift and flags need no mask).
        self._strategy_built_in = plugin.origin.startswith("built-in")
        self._strategy_ctx = None
        params = dict(s0.strategy_params)
        if "beta" in params:
            betas = [s.strategy_params["beta"] for s in self.states]
            if any(b != betas[0] for b in betas):
                params["beta"] = np.repeat(np.array(betas, dtype=float), self.n)[
                    :, None
                ]
        self.strategy_params = params
        self.obstacles = s0.obstacles
        if self.n <= BRUTE_FORCE_MAX:
            self.neighbours = WorldPairs(self.K, self.n, self.rec.R)
        else:  # one world (structure_key): the Verlet list of a large fleet
            self.neighbours = NeighbourList(self.rec.R)

    def _setup_limits(self) -> None:
        """Gains and limits: scalars when equal over every row, else row arrays."""
        fl = self.fleet
        keys = ("k1", "k2", "k3", "k4", "kp")
        self._gains = Gains(**{k: uniform(getattr(fl.gains, k)) for k in keys})
        self._v1_max = uniform(fl.v1_max)
        self._v2_max = uniform(fl.v2_max)
        self._accel_max = uniform(fl.accel_max)
        # The turn-rate limit of the anti-windup: None when no vehicle has one.
        self._turn_max = None if np.all(np.isinf(fl.v2_max)) else self._v2_max
        self._controller = Controller(
            self._gains,
            self.h,
            self._v1_max,
            self._accel_max,
            self._v2_max,
            self._turn_max,
        )
