"""Many small runs at once: a batch of independent worlds stepped together.

A sweep's runs usually differ only in values (starts, offsets, ``beta``, failure times,
seeds), not in structure (vehicle count, law, strategy, reference, obstacles). For such
runs the fixed cost of a control step (about 200 numpy calls, 0.19 ms for three
vehicles, against 0.01 ms of physics) is paid once per step for the whole batch:
:class:`Batch` keeps K worlds, each its own pymunk
:class:`~sandbox.physics.world.World`, and evaluates the loop of
:class:`~sandbox.loop.simulation.Simulation` (reference, formation law, failures,
recovery, the flatness controller of eqs. (5)-(6), limits, the motor sizing, the loop
metrics, the record) on stacked arrays of all ``K * n`` vehicles in one pass per step.
Only the physics itself (bulk read, bulk write, ``Space.step``) is called world
by world.

Results are bit-identical to single runs (``Simulation(scenario).run()``): the same
functions are called on the stacked arrays (elementwise, so each vehicle's numbers are
computed exactly as alone), neighbour pairs never cross worlds and are summed in the
single run's order, each world keeps its own law memory (backward differences stack
elementwise), failure schedule and contact episodes, and a world that diverges stops
alone. What the batch does not implement is refused by
:func:`~sandbox.study.batchable.batch_reason` and runs
on the single-run path: a plug-in law or strategy, sensing noise, a safety filter, a
failure detector, open-loop command schedules, more than :data:`MAX_VEHICLES`
vehicles, a record spilled to disk, and any scenario key this module does not know (a
newer section set to a non-default value).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from sandbox.geometry.neighbours import NeighbourList
from sandbox.loop.divergence import diverged
from sandbox.loop.simulation import Simulation
from sandbox.model.failures import within_drive
from sandbox.model.flatness import advance_extension, extension_rate, flat_inputs
from sandbox.model.laws import (
    BackwardDifference,
)
from sandbox.physics.stepping import WorldStepper
from sandbox.physics.world import World, motor_limits
from sandbox.plugins.registration import (
    FailureContext,
    LawContext,
    StrategyContext,
    make_law,
)
from sandbox.run.record import (
    MODE_AVOID,
    MODE_FAILED,
    MODE_FORMATION,
    STATUS_DIVERGED,
    STATUS_INTERRUPTED,
    Run,
)
from sandbox.scenario import Scenario
from sandbox.study.batch_metrics import BatchTally
from sandbox.study.batchable import (
    TABULATED_REFERENCES,
    batch_key,
    batch_reason,
)


class _Pairs:
    """Neighbour pairs of K worlds of ``n`` vehicles: never across worlds.

    Every pair of a world is a candidate (as alone, up to :data:`MAX_VEHICLES`), in the
    single run's ``(i, j)`` order, world after world; so the sums over pairs add each
    vehicle's terms in the order it adds them alone. Obstacle candidates come from a
    :class:`~sandbox.behaviour.recovery.NeighbourList` over all vehicles (a superset of
    the pairs in range; the others weigh exactly 0).
    """

    def __init__(self, worlds: int, n: int, radius: float) -> None:
        self.radius = float(radius)
        i, j = np.triu_indices(n, 1)
        base = (np.arange(worlds) * n)[:, None]
        self._i = (base + i).ravel().astype(np.intp)
        self._j = (base + j).ravel().astype(np.intp)
        self._obstacles = NeighbourList(radius)
        self._last: tuple[np.ndarray, np.ndarray] | None = None

    def near(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pairs closer than ``radius``, with ``pos[i] - pos[j]`` (as alone)."""
        rel = np.take(pos, self._i, axis=0)
        rel -= np.take(pos, self._j, axis=0)
        d2 = rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]
        self._last = (pos, d2)
        keep = np.flatnonzero(d2 < self.radius * self.radius)
        return self._i.take(keep), self._j.take(keep), np.take(rel, keep, axis=0)

    def distances(self, pos: np.ndarray) -> np.ndarray | None:
        """Squared distances of every pair, world after world (else None).

        Those of the last :meth:`near`, if it ran on this very array.
        """
        last = self._last
        return last[1] if last is not None and last[0] is pos else None

    def pairs(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pairs closer than ``radius``."""
        i, j, _ = self.near(pos)
        return i, j

    def obstacle_pairs(self, pos: np.ndarray, field: Any) -> tuple[np.ndarray, ...]:
        """Candidate ``(vehicle, obstacle)`` pairs (see ``NeighbourList``)."""
        return self._obstacles.obstacle_pairs(pos, field)


class _Failures:
    """The failure schedules of all worlds, stacked (one row per failure)."""

    def __init__(self, sims: Sequence[Simulation], n: int) -> None:
        self.world, self.vehicle, self.local = [], [], []
        self.kinds, self.specs = [], []
        start, end = [], []
        for w, sim in enumerate(sims):
            fs = sim.failures
            for k, spec in enumerate(fs.specs):
                self.world.append(w)
                self.local.append(int(fs.vehicle[k]))
                self.vehicle.append(w * n + int(fs.vehicle[k]))
                self.kinds.append(fs.kinds[k])
                self.specs.append(spec)
                start.append(fs.start[k])
                end.append(fs.end[k])
        self.world = np.array(self.world, dtype=np.intp)
        self.vehicle = np.array(self.vehicle, dtype=np.intp)
        self.start = np.array(start, dtype=float)
        self.end = np.array(end, dtype=float)
        self.started = np.zeros(len(self.specs), dtype=bool)
        self.v2_onset = np.zeros(len(self.specs))
        self.params = [dict(s.params) for s in self.specs]
        self.controlled = np.array(
            [k.options["controlled_speed"] for k in self.kinds], dtype=bool
        )
        self.immovable = np.array([k.options["immovable"] for k in self.kinds], bool)

    def active(self, t: float, live: np.ndarray) -> np.ndarray:
        """Active failures of the live worlds (``FailureSchedule.active``)."""
        on = (self.start <= t + 1e-12) & (t + 1e-12 < self.end)
        return on & live[self.world]


class Batch:
    """K runs of one :func:`batch_key` stepped together (see the module docstring).

    Parameters
    ----------
    sims : sequence of Simulation
        Fresh simulations for which :func:`batch_reason` is None, all of one key.

    Examples
    --------
    >>> from sandbox import load_scenario
    >>> doc = {"duration": 0.5, "reference": {"type": "point", "position": [1, 0]},
    ...        "vehicles": [{"name": "red", "pose": [0, 0, 0]}]}
    >>> runs = Batch([Simulation(load_scenario(doc)) for _ in range(3)]).run()
    >>> [r.pose.shape for r in runs]
    [(51, 1, 3), (51, 1, 3), (51, 1, 3)]
    """

    #: Step the worlds' physics with :class:`~sandbox.physics.stepping.WorldStepper`
    #: (False: world by world in Python; the same numbers, slower).
    fast_stepping = True

    def __init__(self, sims: Sequence[Simulation]) -> None:
        first = sims[0]
        self.sims = list(sims)
        self.K = K = len(sims)
        self.n = n = first.fleet.n
        self.N = N = K * n
        self.h = first.h
        self.steps = first.steps
        self.substeps = first.scenario.substeps
        self.record_every = first.scenario.record_every
        self.worlds: list[World] = [s.world for s in sims]
        self.live = np.ones(K, dtype=bool)
        self.k = 0

        def stack(name: str) -> np.ndarray:
            return np.concatenate([getattr(s.fleet, name) for s in sims])

        self.pos, self.theta, self.vel = stack("pos"), stack("theta"), stack("vel")
        self.chi, self.v1, self.v2 = stack("chi"), stack("v1"), stack("v2")
        self.failed, self.mode = stack("failed"), stack("mode")
        self.diameter = stack("diameter")
        self.offset = stack("offset").reshape(K, n, 2)
        # Parameters shared by the batch (equal in every world by batch_key).
        self.leader = first.leader
        self.reference = first.reference
        # References that are elementwise in t: evaluated once for every step time
        # (each row the bits of the scalar evaluation at t_k = k h).
        self._ref_table = None
        if type(self.reference) in TABULATED_REFERENCES:
            times = np.array([k * self.h for k in range(self.steps + 1)])
            self._ref_table = self.reference.evaluate(times)
        spec = first.scenario.formation
        self.law = (
            make_law(spec.law, spec.params, self.offset, self.h) if spec else None
        )
        self.law_params = dict(spec.params) if spec else {}
        self.law_memory: dict = {}
        self.track_rows = (np.arange(K)[:, None] * n + first._track_rows).ravel()
        self.gains = _tile_gains(first._gains, K)
        self.v1_max, self.v2_max = _tile(first._v1_max, K), _tile(first._v2_max, K)
        self.accel_max = _tile(first._accel_max, K)
        self.turn_max = None if first._turn_max is None else self.v2_max
        self.rec = first.rec
        self.strategy = first.strategy
        params = dict(first.strategy_params)
        if "beta" in params:
            betas = [s.strategy_params["beta"] for s in sims]
            if any(b != betas[0] for b in betas):
                params["beta"] = np.repeat(np.array(betas, dtype=float), n)[:, None]
        self.strategy_params = params
        self.obstacles = first.obstacles
        self.neighbours = _Pairs(K, n, self.rec.R)
        self.avoid_candidates = np.concatenate([s._avoid_candidates for s in sims])
        self.shift_motion = BackwardDifference(self.h)
        self.failures = _Failures(sims, n)
        self.failed_at: list[dict[str, float]] = [dict(s.failed_at) for s in sims]
        self._failing = np.zeros(N, dtype=bool)
        self.plan: tuple | None = None
        self._shared_motors(sims)
        self._live_list = list(range(K))
        self._rows = np.empty((K, n, 6))
        # The control bodies read their velocities straight from the stacked commands.
        self._out = np.zeros((N, 3))
        self._bound = [w._control_in_order for w in self.worlds]
        for k, world in enumerate(self.worlds):
            if self._bound[k]:
                world.bind_commands(self._out[k * n : (k + 1) * n])
        self._stepper: WorldStepper | None = None
        # Each world's failure flags are a view of one array, updated in place.
        self._failed_now = np.zeros(N, dtype=bool)
        for k, world in enumerate(self.worlds):
            world.failed = self._failed_now[k * n : (k + 1) * n]
        self._episodes = [w._open for w in self.worlds]
        #: Whether every position is finite (the last divergence check passed).
        self.finite = bool(np.isfinite(self.pos).all())
        self._tally = BatchTally(K, n, self.h)
        self._record_setup(first)
        self._control_time = 0.0
        self._dead_runs: dict[int, Run] = {}
        self._plan()

    # ------------------------------------------------------------------ set-up
    def _shared_motors(self, sims: Sequence[Simulation]) -> None:
        """The worlds' motor arrays become views of stacked ones (updated at once)."""
        n = self.n
        for name in (
            "_measured",
            "_mass",
            "_moment",
            "_tracking",
            "_force",
            "_torque",
            "_least_force",
            "_least_torque",
        ):
            stacked = np.concatenate([getattr(w, name) for w in self.worlds])
            setattr(self, name, stacked)
            for k, w in enumerate(self.worlds):
                setattr(w, name, stacked[k * n : (k + 1) * n])

    def _record_setup(self, first: Simulation) -> None:
        T, K, n = first.recorder.capacity, self.K, self.n
        self._count = 0
        self._buf = {
            "t": np.zeros(T),
            "pose": np.zeros((T, K, n, 3)),
            "cmd": np.zeros((T, K, n, 2)),
            "chi": np.zeros((T, K, n, 2)),
            "slot": np.zeros((T, K, n, 2)),
            "target": np.zeros((T, K, n, 2)),
            "mode": np.zeros((T, K, n), np.int8),
            "failed": np.zeros((T, K, n), bool),
            "reference": np.zeros((T, K, 2)),
        }

    # ------------------------------------------------------------------ stages
    def _sense(self) -> None:
        """Take every live world's state; a world that diverged stops (alone)."""
        K, n = self.K, self.n
        rows = self._rows  # read by _advance
        measured = self._measured.reshape(K, n, 3)
        measured[..., :2] = rows[..., 3:5]
        measured[..., 2] = rows[..., 5]
        if len(self._live_list) < K:  # stopped worlds: a harmless state, never used
            rows = rows.copy()
            dead = ~self.live
            rows[dead] = 0.0
            self.chi.reshape(K, n, 2)[dead] = 0.0
        rows = rows.reshape(self.N, 6)
        self.pos, self.theta = rows[:, 0:2].copy(), rows[:, 2].copy()
        self.vel = rows[:, 3:5].copy()
        self.finite = diverged(self) is None
        if self.finite:
            return
        t = self.k * self.h
        for w in np.flatnonzero(self.live):
            part = _WorldView(self, w)
            bad = diverged(part)
            if bad is None:
                continue
            sim = self.sims[w]
            sim.status = STATUS_DIVERGED
            sim.info["diverged"] = {
                "t": t,
                "vehicle": sim.names[bad[0]],
                "reason": bad[1],
            }
            self._record(np.array([w]), undefined=True)
            self.live[w] = False
            self._live_list = [int(k) for k in np.flatnonzero(self.live)]
            if self._stepper is not None:
                self._stepper.live(self._live_list)
            self._dead_runs[w] = self._close(w)

    def _targets(self, t: float) -> tuple[np.ndarray, ...]:
        """Slots, reference point and the law's ``x_ref'``, ``x_ref''`` (as alone)."""
        K, n, N = self.K, self.n, self.N
        if self._ref_table is not None:
            ref = tuple(a[self.k] for a in self._ref_table)
        elif self.reference is not None:
            ref = self.reference.evaluate(t)
        else:
            ref = None
        if self.law is not None:
            lead = self.leader
            pos3 = self.pos.reshape(K, n, 2)
            theta2 = self.theta.reshape(K, n)
            if lead < 0:
                leader_pos = leader_theta = None
            else:
                leader_pos = np.ascontiguousarray(pos3[:, lead : lead + 1])
                leader_theta = np.ascontiguousarray(theta2[:, lead : lead + 1])
            inputs = LawContext(
                t=t,
                dt=self.h,
                pos=pos3,
                theta=theta2,
                vel=self.vel.reshape(K, n, 2),
                offset=self.offset,
                leader=lead,
                leader_pos=leader_pos,
                leader_theta=leader_theta,
                reference=ref,
                params=self.law_params,
                memory=self.law_memory,
            )
            triple = [
                np.broadcast_to(a, (K, n, 2)).reshape(N, 2)
                for a in self.law.targets(inputs)
            ]
        else:
            triple = [np.zeros((N, 2)), np.zeros((N, 2)), np.zeros((N, 2))]
        tr = self.track_rows
        if ref is not None and len(tr):
            slot, v_ref, a_ref = (np.array(a, dtype=float) for a in triple)
            slot[tr], v_ref[tr], a_ref[tr] = ref[0], ref[1], ref[2]
        else:
            slot, v_ref, a_ref = (np.asarray(a, dtype=float) for a in triple)
        point = ref[0] if ref is not None else np.full(2, np.nan)
        return slot, v_ref, a_ref, point

    def _plan(self) -> None:
        """Slots, failures and recovery of every world (``Simulation._plan``)."""
        t, N, rec = self.k * self.h, self.N, self.rec
        slot, v_ref, a_ref, point = self._targets(t)
        failing = self._failing
        fs = self.failures
        if len(fs.specs):
            active = fs.active(t, self.live)
            new = np.flatnonzero(active & ~fs.started)
            fs.started[new] = True
            fs.v2_onset[new] = self.v2[fs.vehicle[new]]
            for j in new:
                w = int(fs.world[j])
                if fs.immovable[j]:
                    self.worlds[w].immobilize(int(fs.local[j]))
                self.failed_at[w].setdefault(fs.specs[j].vehicle, t)
            failing = np.zeros(N, dtype=bool)
            failing[fs.vehicle[active]] = True
        known = failing
        may_avoid = self.avoid_candidates & ~known
        shift, active_avoid = self.strategy(
            StrategyContext(
                t=t,
                dt=self.h,
                pos=self.pos,
                theta=self.theta,
                vel=self.vel,
                slot=slot,
                diameter=self.diameter,
                may_avoid=may_avoid,
                failed=known,
                params=self.strategy_params,
                R=rec.R,
                obstacle_field=self.obstacles,
                neighbours=self.neighbours,
                seen_pos=None,
            )
        )
        shift = np.where(may_avoid[:, None], shift, 0.0)
        active_avoid = np.asarray(active_avoid, dtype=bool) & may_avoid
        target = slot + shift  # eq. (22) / (26)
        if rec.target_derivatives == "estimate":
            d_shift, dd_shift = self.shift_motion.update(shift)
            v_ref = v_ref + d_shift
            a_ref = a_ref + dd_shift
        self._failing = failing
        self.plan = (slot, target, v_ref, a_ref, point, active_avoid, failing)

    def _act(self) -> np.ndarray:
        """Controller, limits and failures of every world (``Simulation._act``)."""
        h, t = self.h, self.k * self.h
        _, target, v_ref, a_ref, _, active, _ = self.plan
        aim = np.where(np.isnan(target), self.pos, target)
        chi_dot = extension_rate(self.pos, self.chi, aim, v_ref, a_ref, self.gains)
        aim = None
        if self.turn_max is None:
            chi_next, chi_dot = advance_extension(
                self.chi, chi_dot, h, self.v1_max, self.accel_max
            )
        else:
            chi_next, chi_dot, aim = advance_extension(
                self.chi,
                chi_dot,
                h,
                self.v1_max,
                self.accel_max,
                self.theta,
                self.turn_max,
            )
        v1, v2 = flat_inputs(self.theta, self.chi, chi_dot, self.gains.kp, aim)
        v2 = np.clip(v2, -self.v2_max, self.v2_max)
        v1, v2, failed, frozen = self._apply_failures(t, v1, v2)
        if np.any(frozen):
            th = self.theta
            heading = np.stack((np.cos(th), np.sin(th)), -1)
            chi_next[frozen] = v1[frozen, None] * heading[frozen]
        self.v1, self.v2, self.failed = v1, v2, failed
        self._failed_now[:] = failed  # the worlds' views (World.failed)
        mode = np.full(self.N, MODE_FORMATION, dtype=np.int8)
        mode[active] = MODE_AVOID
        mode[failed] = MODE_FAILED
        self.mode = mode
        return chi_next

    def _apply_failures(
        self, t: float, v1: np.ndarray, v2: np.ndarray
    ) -> tuple[np.ndarray, ...]:
        """``FailureSchedule.apply`` for every world's failures."""
        N, fs = self.N, self.failures
        failed = np.zeros(N, dtype=bool)
        frozen = np.zeros(N, dtype=bool)
        if not len(fs.specs):
            return v1, v2, failed, frozen
        v1, v2 = v1.copy(), v2.copy()
        for k in np.flatnonzero(fs.active(t, self.live)):
            i, spec = fs.vehicle[k], fs.specs[k]
            ctx = FailureContext(
                t=t,
                since=t - spec.at,
                vehicle=spec.vehicle,
                index=int(fs.local[k]),
                v1=float(v1[i]),
                v2=float(v2[i]),
                v2_onset=float(fs.v2_onset[k]),
                params=dict(fs.params[k]),
            )
            v1[i], v2[i] = fs.kinds[k].obj(ctx)
            if not fs.immovable[k]:  # within the drive's max_accel, as alone
                step = float(np.broadcast_to(self.accel_max, (N,))[i]) * self.h
                v1[i] = within_drive(float(v1[i]), float(self.v1[i]), step)
            failed[i] = True
            frozen[i] |= not fs.controlled[k]
        return v1, v2, failed, frozen

    def _in_contact(self) -> np.ndarray:
        out = np.zeros(self.N, dtype=bool)
        if not any(self._episodes):  # no open contact episode in any world
            return out
        n = self.n
        for w, world in enumerate(self.worlds):
            if world._open:
                out[w * n : (w + 1) * n] = world.in_contact()
        return out

    def _record(self, worlds: np.ndarray | None = None, undefined: bool = False):
        """The loop metrics, and the sample every ``record_every`` steps.

        ``worlds``: only these (a diverged world's last sample, ``undefined`` plan).
        """
        contact = self._in_contact()
        self._contact = contact
        self._tally.update(self, contact, worlds)
        if self.k % self.record_every and not undefined:
            return
        K, n = self.K, self.n
        b, c = self._buf, self._count
        if worlds is None and not undefined:  # every world: straight into the record
            b["t"][c] = self.k * self.h
            pose, cmd = b["pose"][c], b["cmd"][c]
            pose[..., :2] = self.pos.reshape(K, n, 2)
            pose[..., 2] = self.theta.reshape(K, n)
            cmd[..., 0] = self.v1.reshape(K, n)
            cmd[..., 1] = self.v2.reshape(K, n)
            slot, target, _, _, point, _, _ = self.plan
            b["chi"][c] = self.chi.reshape(K, n, 2)
            b["slot"][c] = slot.reshape(K, n, 2)
            b["target"][c] = target.reshape(K, n, 2)
            b["mode"][c] = self.mode.reshape(K, n)
            b["failed"][c] = self.failed.reshape(K, n)
            b["reference"][c] = point
            self._count = c + 1
            return
        pose = np.concatenate((self.pos, self.theta[:, None]), axis=1).reshape(K, n, 3)
        cmd = np.stack((self.v1, self.v2), axis=1).reshape(K, n, 2)
        if undefined:
            nan = np.full((K, n, 2), np.nan)
            slot = target = nan
            point = np.full(2, np.nan)
        else:
            slot, target, _, _, point, _, _ = self.plan
            slot, target = slot.reshape(K, n, 2), target.reshape(K, n, 2)
        rows = slice(None) if worlds is None else worlds
        b["t"][c] = self.k * self.h
        b["pose"][c, rows] = pose[rows]
        b["cmd"][c, rows] = cmd[rows]
        b["chi"][c, rows] = self.chi.reshape(K, n, 2)[rows]
        b["slot"][c, rows] = slot[rows]
        b["target"][c, rows] = target[rows]
        b["mode"][c, rows] = self.mode.reshape(K, n)[rows]
        b["failed"][c, rows] = self.failed.reshape(K, n)[rows]
        b["reference"][c, rows] = point
        if worlds is None:
            self._count = c + 1

    def _advance(self, chi_next: np.ndarray) -> None:
        """Write every live world's commands and step it (``Simulation._advance``)."""
        h, n = self.h, self.n
        self.chi = chi_next
        out = self._out
        commanded = self._tally.commanded
        if commanded is not None and self._tally.commanded_at == self.k:
            out[:, :2] = commanded  # the same numbers, computed by the loop metrics
        else:
            heading = self.theta + 0.5 * self.v2 * h
            out[:, 0] = self.v1 * np.cos(heading)
            out[:, 1] = self.v1 * np.sin(heading)
        out[:, 2] = self.v2
        if self._tracking.any():
            rows, force, torque = motor_limits(
                out, self._measured, ~self._contact, h / self.substeps, self
            )
            for r in rows:
                w, i = divmod(int(r), n)
                pivot, gear = self.worlds[w].joints[i]
                pivot.max_force = self._force[r] = force[r]
                gear.max_force = self._torque[r] = torque[r]
        t0, substeps = self.k * h, self.substeps
        if self._stepper is not None:  # every world at once (sandbox.physics.stepping)
            self._stepper.advance(t0, h)
            self.k += 1
            return
        # One pass over the worlds: write, step (World.step's loop, Chipmunk called
        # directly: the same calls and times), read the state of t_k+1.
        hh = h / substeps
        times = [t0 + s * hh for s in range(substeps)]
        ends = [t0 + (s + 1) * hh for s in range(substeps)]
        worlds, rows = self.worlds, self._rows
        for w in self._live_list:
            world = worlds[w]
            world.write_rows(None if self._bound[w] else out[w * n : (w + 1) * n])
            fast = world.c_step
            if fast is None or fast[2]:
                world.step(h, substeps, t0)
            else:
                c_step, handle = fast[0], fast[1]
                world._substeps = substeps
                for s in range(substeps):
                    world.time = times[s]
                    c_step(handle, hh)
                    if world._open:
                        world._update_episodes(ends[s])
            rows[w] = world.read_rows(measure=False)
        self.k += 1
        if self.k == 1 and self.fast_stepping:  # every body is checked in now
            self._stepper = WorldStepper.build(
                self.worlds, self._out, self._rows, substeps
            )
            if self._stepper is not None:
                self._stepper.live(self._live_list)

    # ------------------------------------------------------------------ results
    def _close(self, w: int) -> Run:
        """World ``w``'s run: the batch's record and tallies given to its Simulation."""
        sim, n = self.sims[w], self.n
        rows = slice(w * n, (w + 1) * n)
        c = self._count + (1 if not self.live[w] else 0)
        arrays = {
            name: np.ascontiguousarray(buf[:c] if name == "t" else buf[:c, w])
            for name, buf in self._buf.items()
        }
        if not self.live[w]:
            arrays["t"][-1] = self.k * self.h
        f = sim.fleet
        f.pos, f.theta = self.pos[rows].copy(), self.theta[rows].copy()
        f.vel = self.vel[rows].copy()
        f.chi, f.v1, f.v2 = self.chi[rows].copy(), self.v1[rows], self.v2[rows]
        f.failed, f.mode = self.failed[rows].copy(), self.mode[rows].copy()
        sim.k = self.k
        sim.failed_at = self.failed_at[w]
        sim.recorder = _Record(arrays)
        sim.tally = _Result(self._tally.result(w))
        sim._control_time = self._control_time / self.K
        sim._closed = True
        return sim.result()

    def run(self, should_stop: Callable[[], bool] | None = None) -> list[Run] | None:
        """Simulate every world to its end; the runs in order (None if stopped).

        ``should_stop`` is polled every step; when it returns True the batch stops and
        nothing is returned (the runs would be ``interrupted``).
        """
        while self.k < self.steps and self.live.any():
            start = time.perf_counter()
            chi_next = self._act()
            self._control_time += time.perf_counter() - start
            self._record()
            if should_stop is not None and should_stop():
                for sim in self.sims:
                    sim.status = STATUS_INTERRUPTED
                return None
            self._advance(chi_next)
            self._sense()
            if self.live.any():
                start = time.perf_counter()
                self._plan()
                self._control_time += time.perf_counter() - start
        if self.live.any():  # the last sample, with the controller's commands
            self._act()
            self._record()
        return [
            self._dead_runs[w] if w in self._dead_runs else self._close(w)
            for w in range(self.K)
        ]


class _WorldView:
    """One world's rows of the stacked state, for ``divergence.diverged``."""

    def __init__(self, batch: Batch, w: int) -> None:
        rows = slice(w * batch.n, (w + 1) * batch.n)
        self.pos, self.theta = batch.pos[rows], batch.theta[rows]
        self.vel, self.chi = batch.vel[rows], batch.chi[rows]


class _Record:
    """A finished record (what :meth:`Recorder.arrays` returns) of one world."""

    def __init__(self, arrays: dict[str, np.ndarray]) -> None:
        self._arrays = arrays
        self.count = len(arrays["t"])

    def arrays(self) -> dict[str, np.ndarray]:
        return self._arrays


class _Result:
    """Finished loop metrics (the ``result()`` of ``LoopMetrics``)."""

    def __init__(self, result: dict[str, Any]) -> None:
        self._result = result

    def result(self) -> dict[str, Any]:
        return self._result


def _tile(value: float | np.ndarray, K: int) -> float | np.ndarray:
    return np.tile(value, K) if isinstance(value, np.ndarray) else value


def _tile_gains(gains: Any, K: int) -> Any:
    return dataclasses.replace(
        gains,
        **{f.name: _tile(getattr(gains, f.name), K) for f in dataclasses.fields(gains)},
    )


def run_batch(
    scenarios: Sequence[Scenario], should_stop: Callable[[], bool] | None = None
) -> list[Run] | None:
    """Run scenarios as single runs would, batching those that can be batched.

    Returns the runs in order (None when ``should_stop`` stopped them). Scenarios
    :func:`batch_reason` refuses run alone.
    """
    sims = [Simulation(sc) for sc in scenarios]
    out: list[Run | None] = [None] * len(sims)
    groups: dict[str, list[int]] = {}
    for k, sim in enumerate(sims):
        if batch_reason(sim) is None:
            groups.setdefault(batch_key(sim), []).append(k)
        else:
            run = sim.run(should_stop=should_stop)
            if run.status == STATUS_INTERRUPTED:
                return None
            out[k] = run
    for members in groups.values():
        runs = Batch([sims[k] for k in members]).run(should_stop)
        if runs is None:
            return None
        for k, run in zip(members, runs, strict=True):
            out[k] = run
    return out  # type: ignore[return-value]


__all__ = ["Batch", "batch_key", "batch_reason", "run_batch"]
