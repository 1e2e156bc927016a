"""The recovery stage of K worlds: each vehicle's shift off its slot (eqs. (21)-(27)).

:class:`Avoidance` calls the recovery strategy (``recovery:``) once for the rows of
every world, or world by world for a plug-in registered without ``batched=True``,
and returns the shifted targets ``target = slot + shift`` (eqs. (22), (26)) with the
vehicles whose target recovery shifts. A built-in ``discontinuous`` or ``continuous``
strategy without the tangential term and without obstacles takes its period in one
C call where :mod:`sandbox.loop.plan_kernel` chose it. With ``platoons:`` each
platoon's recovery section is called on its rows
(:mod:`sandbox.loop.platoon_sections`). A strategy never moves a vehicle that may
not avoid.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from sandbox.behaviour.ranges import avoid_field
from sandbox.errors import PluginRunError
from sandbox.geometry.neighbours import NeighbourList, neighbour_search
from sandbox.loop.layout import Layout
from sandbox.loop.liveness import Failed
from sandbox.loop.perception import Perception
from sandbox.loop.state import Fleet
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.registration import StrategyContext, get, runnable


class Avoidance:
    """The recovery strategy of a loop's K worlds (see the module docstring).

    Parameters
    ----------
    layout : Layout
    perception : Perception
        The range readings (``recovery.obstacles: sensed``, the contexts' fields).
    obstacles : ObstacleField
        The worlds' obstacles.
    platoons : callable or None
        With ``platoons:``, the strategy of every world's platoons (one call for
        all), or None where each world's platoons are called apart.
    world_platoons : list or None
        With ``platoons:``, each world's platoons' strategy (world by world).
    """

    def __init__(
        self,
        layout: Layout,
        perception: Perception,
        obstacles: ObstacleField,
        platoons: Any = None,
        world_platoons: list | None = None,
    ) -> None:
        self._layout = layout
        self._perception = perception
        scenarios = layout.scenarios
        first = scenarios[0]
        self.rec = first.recovery
        plugin = get("strategy", first.recovery.strategy)
        #: The strategy as the loop calls it (the plug-in's, or the platoons').
        self.strategy: Any = runnable(plugin)
        #: Whether it is called world by world (a plug-in without ``batched=True``).
        self.per_world = not plugin.options.get("batched", False)
        # A built-in strategy keeps no context (one serves every period) and moves no
        # vehicle that may not avoid (its shift and flags need no mask).
        self.built_in = plugin.origin.startswith("built-in")
        self._strategies = [self.strategy] * layout.K
        if world_platoons is not None:
            self._strategies = list(world_platoons)
            self.strategy, self.per_world = platoons, platoons is None
            if platoons is None:
                self.strategy = world_platoons[0]
        self._ctx: StrategyContext | None = None
        self.world_params = [dict(sc.recovery.params) for sc in scenarios]
        params = dict(self.world_params[0])
        if "beta" in params:
            betas = [p["beta"] for p in self.world_params]
            if any(b != betas[0] for b in betas):
                params["beta"] = np.repeat(np.array(betas, dtype=float), layout.n)[
                    :, None
                ]
        #: The strategy's values (``beta`` a row each where the worlds differ).
        self.params = params
        #: Where recovery finds the static obstacles (the map, or the sensed points).
        self.field = avoid_field(perception.ranges, obstacles, self.rec)
        self._world_fields = [
            avoid_field(
                None if perception.ranges is None else perception.ranges.part(w),
                obstacles,
                sc.recovery,
            )
            for w, sc in enumerate(scenarios)
        ]
        # every pair of each world, or the Verlet list of a large fleet (alone)
        self.neighbours: Any = neighbour_search(layout.K, layout.n, self.rec.R)
        self._world_neighbours = [NeighbourList(sc.recovery.R) for sc in scenarios]
        #: The strategy's period in one C call (plan_kernel.py; set by the build).
        self.kernel: Any = None
        #: The strategy the C call replaces (another one set since: numpy).
        self.kernel_strategy: Any = None

    def targets(
        self,
        t: float,
        fleet: Fleet,
        slot: np.ndarray,
        may_avoid: np.ndarray,
        known: np.ndarray,
        believed: np.ndarray | None,
        live: Sequence[int],
        failed: Failed,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The targets, the shift and the avoiding vehicles of ``t`` (N rows each).

        Parameters
        ----------
        t : float [s]
        fleet : Fleet
        slot : ndarray, shape (N, 2) [m]
            The formation's slots.
        may_avoid, known : ndarray, shape (N,), bool
            Who may avoid, and who is believed failed (an obstacle to everyone).
        believed : ndarray, shape (N, 3), or None
            What the vehicles see of the others (None: the truth).
        live : list of int
            The live worlds.
        failed : callable
            ``failed(w, exc)`` ends world ``w`` (its plug-in failed).
        """
        if self.kernel is not None and self.strategy is self.kernel_strategy:
            try:  # eqs. (22)-(27) in one C call
                return self.kernel.shifted(fleet.pos, believed, may_avoid, slot)
            except (BufferError, TypeError, ValueError):  # not such arrays: numpy
                pass
        shift, active = self._shift(
            t, fleet, slot, may_avoid, known, believed, live, failed
        )
        return slot + shift, shift, active  # eq. (22) / (26)

    def _shift(
        self, t, fleet, slot, may_avoid, known, believed, live, failed
    ) -> tuple[np.ndarray, np.ndarray]:
        """The strategy's shift and avoiding vehicles of ``t`` (numpy, plug-ins)."""
        N = self._layout.N
        if self.per_world:
            shift, active = self._world_shift(
                t, fleet, slot, may_avoid, known, believed, live, failed
            )
        else:
            shift, active = self.strategy(
                self._context(t, fleet, slot, may_avoid, known, believed)
            )
        # a strategy never moves a vehicle that may not avoid (where every vehicle
        # may, a float (N, 2) shift is kept as it is: the same values; a built-in
        # one's shift and flags of every world are masked already)
        if self.per_world or not self.built_in:
            if not (
                type(shift) is np.ndarray
                and shift.dtype == np.float64
                and shift.shape == (N, 2)
                and np.count_nonzero(may_avoid) == N
            ):
                shift = np.where(may_avoid[:, None], shift, 0.0)
            active = np.asarray(active, dtype=bool) & may_avoid
        return shift, active

    def _context(self, t, fleet, slot, may_avoid, known, believed) -> StrategyContext:
        """The strategy's context of ``t``: a new one, or a built-in's one, updated.

        A built-in strategy reads its context during its call only, so one context
        serves it every period, its fields of the period set anew.
        """
        ctx = self._ctx
        ranges = self._perception.ranges
        if ctx is not None:
            ctx.t, ctx.slot, ctx.may_avoid, ctx.failed = t, slot, may_avoid, known
            ctx.pos, ctx.theta, ctx.vel = fleet.pos, fleet.theta, fleet.vel
            ctx.obstacle_field, ctx.neighbours = self.field, self.neighbours
            ctx.params, ctx.R = self.params, self.rec.R
            ctx.seen_pos = None if believed is None else believed[:, :2]
            if ranges is not None:
                ctx.ranges = ranges.ranges
                ctx.beam_angles = ranges.beam_angles
            return ctx
        ctx = StrategyContext(
            t=t,
            dt=self._layout.h,
            pos=fleet.pos,
            theta=fleet.theta,
            vel=fleet.vel,
            slot=slot,
            diameter=fleet.diameter,
            may_avoid=may_avoid,
            failed=known,
            params=self.params,
            R=self.rec.R,
            obstacle_field=self.field,
            neighbours=self.neighbours,
            seen_pos=None if believed is None else believed[:, :2],
            **self._perception.context(),
        )
        if self.built_in:
            self._ctx = ctx
        return ctx

    def _world_shift(
        self, t, fleet, slot, may_avoid, known, believed, live, failed
    ) -> tuple[np.ndarray, np.ndarray]:
        """A strategy without ``batched=True``, called world by world."""
        layout = self._layout
        N = layout.N
        shift, active = np.zeros((N, 2)), np.zeros(N, dtype=bool)
        for w in live:
            rows = layout.rows(w)
            sc = layout.scenarios[w]
            ctx = StrategyContext(
                t=t,
                dt=layout.h,
                pos=fleet.pos[rows],
                theta=fleet.theta[rows],
                vel=fleet.vel[rows],
                slot=slot[rows],
                diameter=fleet.diameter[rows],
                may_avoid=may_avoid[rows],
                failed=known[rows],
                params=self.world_params[w],
                R=sc.recovery.R,
                obstacle_field=self._world_fields[w],
                neighbours=self._world_neighbours[w],
                seen_pos=None if believed is None else believed[rows, :2],
                **self._perception.context(w),
            )
            try:
                out = self._strategies[w](ctx)
            except PluginRunError as exc:
                failed(w, exc)
                continue
            shift[rows], active[rows] = out[0], out[1]
        return shift, active
