"""The fixed-step simulation loop: physics, law, recovery, failures, controller.

Every control period ``h = dt``:

1. read all vehicles' poses from the physics (one bulk call);
2. evaluate the reference and the formation law: each vehicle's slot, ``x_ref'``,
``x_ref''``;
3. shift the targets by the recovery strategy (eqs. (21)-(27));
4. advance the flatness controller (eqs. (5)-(6)) for the whole fleet at once;
5. apply failures and open-loop command schedules;
6. record a sample every ``record_every`` periods;
7. write the commands to the control bodies and step the physics ``substeps`` times.

A run returns a :class:`~sandbox.run.Run`; nothing here draws or computes metrics.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from sandbox.control.flatness import (
    Gains,
    advance_extension,
    extension_rate,
    flat_inputs,
)
from sandbox.control.formation import LAWS, BackwardDifference, LawInputs
from sandbox.failures import FailureSchedule
from sandbox.recovery import NeighbourList, ObstacleField, avoidance_shift
from sandbox.run import (
    MODE_AVOID,
    MODE_FAILED,
    MODE_FORMATION,
    STATUS_DIVERGED,
    STATUS_INTERRUPTED,
    STATUS_OK,
    Recorder,
    Run,
)
from sandbox.scenario import Scenario
from sandbox.state import Fleet
from sandbox.world import World

#: A state beyond these bounds is reported as ``diverged`` [m], [m/s].
DIVERGED_POSITION = 1e6
DIVERGED_SPEED = 1e3
#: Samples of the reference path kept for drawing.
REFERENCE_PATH_SAMPLES = 400


class Simulation:
    """One run of a scenario.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario (see :func:`sandbox.load_scenario`).

    Examples
    --------
    >>> from sandbox import load_scenario
    >>> sim = Simulation(load_scenario({"duration": 1.0, "reference": {"type": "point",
    ...     "position": [1, 0]}, "vehicles": [{"pose": [0, 0, 0]}]}))
    >>> run = sim.run()
    >>> run.pose.shape
    (101, 1, 3)
    """

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.h = scenario.dt
        self.steps = int(round(scenario.duration / scenario.dt))
        self.fleet = Fleet.from_scenario(scenario)
        self.world = World(scenario.vehicles, scenario.obstacles)
        self.names = [v.name for v in scenario.vehicles]
        self.leader = scenario.leader_index
        self.reference = scenario.reference.build() if scenario.reference else None
        law_spec = scenario.formation
        self.law = (
            LAWS[law_spec.law](self.fleet.offset, self.h, law_spec.rotate)
            if law_spec
            else None
        )
        self.obstacles = ObstacleField(scenario.obstacles)
        self.failures = FailureSchedule(scenario.failures, self.names)
        self.shift_motion = BackwardDifference(self.h)
        n = self.fleet.n
        # Vehicles that track the reference itself (eq. (6)) rather than a slot.
        self.tracks_reference = np.zeros(n, dtype=bool)
        if self.law is None:
            self.tracks_reference[:] = True
        elif law_spec.law != "virtual" and self.leader >= 0:
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

    def _targets(self, t: float) -> tuple[np.ndarray, ...]:
        """Slots, reference point, and the law's ``x_ref'``, ``x_ref''`` at ``t``."""
        fleet, n = self.fleet, self.fleet.n
        ref = self.reference.evaluate(t) if self.reference is not None else None
        if self.law is not None:
            lead = self.leader
            inputs = LawInputs(
                leader_pos=fleet.pos[lead] if lead >= 0 else None,
                leader_theta=float(fleet.theta[lead]) if lead >= 0 else None,
                reference=ref,
            )
            triple = self.law.targets(inputs)
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

    def _info(self) -> dict:
        sc = self.scenario
        obstacles = []
        for o in sc.obstacles:
            if o.type == "circle":
                obstacles.append(
                    {
                        "type": "circle",
                        "center": list(o.center),
                        "radius": o.radius,
                        "name": o.name,
                    }
                )
            else:
                obstacles.append(
                    {"type": "polygon", "points": o.outline(), "name": o.name}
                )
        info = {
            "scenario_name": sc.name,
            "law": sc.formation.law if sc.formation else None,
            "recovery": {
                "strategy": sc.recovery.strategy,
                "beta": sc.recovery.beta,
                "R": sc.recovery.R,
                "r": sc.recovery.r,
                "leader_avoids": sc.recovery.leader_avoids,
                "target_derivatives": sc.recovery.target_derivatives,
            },
            "obstacles": obstacles,
            "failures": [
                {"vehicle": f.vehicle, "kind": f.kind, "at": f.at, "until": f.until}
                for f in sc.failures
            ],
            "dt": sc.dt,
            "record_every": sc.record_every,
        }
        if self.reference is not None:
            times = np.linspace(0.0, sc.duration, REFERENCE_PATH_SAMPLES)
            info["reference_path"] = self.reference.evaluate(times)[0].round(6).tolist()
        return info

    # ------------------------------------------------------------------ the loop
    def run(
        self,
        progress: Callable[[int, int], None] | None = None,
        should_stop: Callable[[], bool] | None = None,
    ) -> Run:
        """Simulate the whole scenario and return the recorded run.

        Parameters
        ----------
        progress : callable, optional
            Called as ``progress(step, steps)`` about a hundred times over the run.
        should_stop : callable, optional
            Polled every step; when it returns True the run stops with status
            ``interrupted`` (the samples so far are kept).
        """
        sc, fleet, world, h = self.scenario, self.fleet, self.world, self.h
        n = fleet.n
        every = sc.record_every
        recorder = Recorder(self.steps // every + 1, n)
        rec = sc.recovery
        avoid_candidates = ~fleet.commanded
        if not rec.leader_avoids and self.leader >= 0:
            avoid_candidates[self.leader] = False
        status, info = STATUS_OK, self._info()
        failed_at: dict[str, float] = {}
        report_every = max(1, self.steps // 100)
        neighbours = NeighbourList(rec.R)
        has_failures = len(self.failures.specs) > 0
        failing = np.zeros(n, dtype=bool)
        gains, v1_max, v2_max, accel_max = (
            self._gains,
            self._v1_max,
            self._v2_max,
            self._accel_max,
        )
        wall = time.perf_counter()
        for k in range(self.steps + 1):
            t = k * h
            state = world.read_state()
            fleet.pos, fleet.theta, fleet.vel = state.pos, state.theta, state.vel
            bad = _diverged(fleet)
            if bad is not None:
                status = STATUS_DIVERGED
                info["diverged"] = {
                    "t": t,
                    "vehicle": self.names[bad[0]],
                    "reason": bad[1],
                }
                recorder.append(
                    t,
                    _pose(fleet),
                    _cmd(fleet),
                    fleet.chi,
                    np.full((n, 2), np.nan),
                    np.full((n, 2), np.nan),
                    fleet.mode,
                    fleet.failed,
                    np.full(2, np.nan),
                )
                break

            slot, v_ref, a_ref, point = self._targets(t)
            if has_failures:
                new = self.failures.start_new(t, fleet.v2)
                for i in self.failures.immovable(new):
                    world.immobilize(i)
                for j in new:
                    failed_at.setdefault(self.failures.specs[j].vehicle, t)
                failing = np.zeros(n, dtype=bool)
                failing[self.failures.vehicle[self.failures.active(t)]] = True
            shift, active = avoidance_shift(
                fleet.pos,
                avoid_candidates & ~failing,
                rec.strategy,
                rec.beta,
                rec.R,
                rec.r,
                rec.steepness,
                self.obstacles,
                neighbours,
            )
            target = slot + shift  # eq. (22) / (26)
            if rec.target_derivatives == "estimate":
                d_shift, dd_shift = self.shift_motion.update(shift)
                v_ref = v_ref + d_shift
                a_ref = a_ref + dd_shift
            aim = np.where(np.isnan(target), fleet.pos, target)

            chi_dot = extension_rate(fleet.pos, fleet.chi, aim, v_ref, a_ref, gains)
            chi_next, chi_dot = advance_extension(
                fleet.chi, chi_dot, h, v1_max, accel_max
            )
            v1, v2 = flat_inputs(fleet.theta, fleet.chi, chi_dot, gains.kp)
            v2 = np.clip(v2, -v2_max, v2_max)
            if self._schedules:
                self._scheduled_commands(t, v1, v2)
            v1, v2, failed, frozen = self.failures.apply(t, v1, v2)
            # Vehicles not driven by the controller: chi follows the applied velocity so
            # that the law resumes without a jump when the failure clears.
            passive = frozen | fleet.commanded
            if np.any(passive):
                heading = np.stack((np.cos(fleet.theta), np.sin(fleet.theta)), -1)
                chi_next[passive] = v1[passive, None] * heading[passive]

            fleet.v1, fleet.v2, fleet.failed = v1, v2, failed
            mode = np.full(n, MODE_FORMATION, dtype=np.int8)
            mode[active] = MODE_AVOID
            mode[failed] = MODE_FAILED
            fleet.mode = mode
            if k % every == 0:
                recorder.append(
                    t,
                    _pose(fleet),
                    _cmd(fleet),
                    fleet.chi,
                    slot,
                    target,
                    mode,
                    failed,
                    point,
                )
            if should_stop is not None and should_stop():
                status = STATUS_INTERRUPTED
                info["interrupted"] = {"t": t}
                break
            if k == self.steps:
                break
            fleet.chi = chi_next
            world.write_commands(fleet.theta, v1, v2, h)
            world.step(h, sc.substeps, t)
            if progress is not None and k % report_every == 0:
                progress(k, self.steps)
        info["failed_at"] = failed_at
        info["wall_time"] = time.perf_counter() - wall
        info["steps"] = k
        return Run(
            names=list(self.names),
            colors=[v.color for v in sc.vehicles],
            diameter=fleet.diameter.copy(),
            leader=self.leader,
            events=list(world.events),
            status=status,
            info=info,
            scenario=sc,
            **recorder.arrays(),
        )


def _pose(fleet: Fleet) -> np.ndarray:
    return np.concatenate((fleet.pos, fleet.theta[:, None]), axis=1)


def _cmd(fleet: Fleet) -> np.ndarray:
    return np.stack((fleet.v1, fleet.v2), axis=1)


def _uniform(values: np.ndarray) -> float | np.ndarray:
    """``values[0]`` as a scalar when every entry equals it, else ``values`` itself."""
    first = values[0]
    return float(first) if np.all(values == first) else values


def _diverged(fleet: Fleet) -> tuple[int, str] | None:
    """First vehicle whose state is non-finite or beyond the bounds, with the reason."""
    # Fast path, one reduction per array: clearly healthy (NaN fails every comparison).
    vel, chi = fleet.vel, fleet.chi
    speed2 = (0.999 * DIVERGED_SPEED) ** 2
    if (
        np.max(np.abs(fleet.pos)) <= DIVERGED_POSITION
        and np.max(np.abs(fleet.theta)) < np.inf
        and np.max(vel[:, 0] * vel[:, 0] + vel[:, 1] * vel[:, 1]) <= speed2
        and np.max(chi[:, 0] * chi[:, 0] + chi[:, 1] * chi[:, 1]) <= speed2
    ):
        return None
    finite = (
        np.isfinite(fleet.pos).all(axis=1)
        & np.isfinite(fleet.theta)
        & np.isfinite(fleet.chi).all(axis=1)
    )
    if not finite.all():
        return int(np.flatnonzero(~finite)[0]), "non-finite state"
    far = np.abs(fleet.pos).max(axis=1) > DIVERGED_POSITION
    fast = np.hypot(fleet.vel[:, 0], fleet.vel[:, 1]) > DIVERGED_SPEED
    bad = far | fast | (np.hypot(fleet.chi[:, 0], fleet.chi[:, 1]) > DIVERGED_SPEED)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        return i, "position beyond 1e6 m" if far[i] else "speed beyond 1e3 m/s"
    return None


def simulate(scenario: Scenario, **kwargs) -> Run:
    """Run a scenario; return its :class:`~sandbox.run.Run` (:meth:`Simulation.run`)."""
    return Simulation(scenario).run(**kwargs)
