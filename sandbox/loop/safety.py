"""The safety stage of K worlds: the filter between the controller and the drives.

:class:`Safety` calls the safety filter (``safety:``) on the controller's commands of
a period, once for the rows of every world (a filter registered with
``batched=True``: ``FilterContext.worlds`` is K, each world's counters its own) or
world by world (each world's memory and counters its own). With ``platoons:`` each
platoon's safety section is called on its rows
(:mod:`sandbox.loop.platoon_sections`, or each world's platoons apart). Where the
rows hold cars (``model: bicycle``) the filter sees their steering
(``FilterContext.steering``, :class:`~sandbox.model.bicycle.CarSteering`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from sandbox.behaviour.ranges import avoid_field
from sandbox.errors import PluginRunError
from sandbox.loop.layout import Layout
from sandbox.loop.liveness import Failed
from sandbox.loop.perception import Perception
from sandbox.loop.state import Fleet
from sandbox.model.bicycle import CarSteering
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.registration import FilterContext, get, runnable


class Safety:
    """The safety filter of a loop's K worlds (see the module docstring).

    Parameters
    ----------
    layout : Layout
    perception : Perception
    obstacles : ObstacleField
        The worlds' obstacles.
    limits : tuple
        The fleet's ``v1_max``, ``v2_max``, ``accel_max`` (scalars where uniform).
    world_limits : list of tuple
        Each world's own limits (scalars where uniform in that world).
    """

    def __init__(
        self,
        layout: Layout,
        perception: Perception,
        obstacles: ObstacleField,
        limits: tuple,
        world_limits: list[tuple],
    ) -> None:
        self._layout = layout
        self._perception = perception
        first = layout.scenarios[0]
        name = first.safety.filter
        #: The filter as the loop calls it (None: no ``safety:`` filter).
        self.filter: Any = None if name == "none" else runnable(get("filter", name))
        #: Whether it is called once for every world (``batched=True``).
        self.batched = name != "none" and bool(
            get("filter", name).options.get("batched", False)
        )
        self._filters = [self.filter] * layout.K
        self._memory: dict = {}
        #: Each world's counters (``metrics.json``'s ``safety``).
        self.world_stats: list[dict] = [{} for _ in range(layout.K)]
        self._world_memory: list[dict] = [{} for _ in range(layout.K)]
        self._limits = limits
        self._world_limits = world_limits
        rec = first.recovery
        self._field = avoid_field(perception.ranges, obstacles, rec)
        self._world_fields = [
            avoid_field(
                None if perception.ranges is None else perception.ranges.part(w),
                obstacles,
                sc.recovery,
            )
            for w, sc in enumerate(layout.scenarios)
        ]
        self._started = False
        #: Which worlds hold a car (their filter sees the cars' steering).
        self._cars = [
            any(v.model == "bicycle" for v in sc.vehicles) for sc in layout.scenarios
        ]

    def use_platoons(self, sections: Any, world_filters: list) -> None:
        """With ``platoons:``: their sections (one call for all) or each world's."""
        if sections is not None:
            self.filter = sections.filter if sections.filtered else None
            self.batched = True
        else:
            self._filters = list(world_filters)
            self.filter = world_filters[0]
            self.batched = False

    def commands(
        self,
        t: float,
        v1: np.ndarray,
        v2: np.ndarray,
        fleet: Fleet,
        slot: np.ndarray,
        known: np.ndarray,
        seen: np.ndarray | None,
        live: Sequence[int],
        failed: Failed,
        last: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The filtered commands of the period from ``t`` [s], (N,) each.

        Parameters
        ----------
        t : float [s]
        v1, v2 : ndarray, shape (N,)
            The controller's commands [m/s], [rad/s].
        fleet : Fleet
            The state at ``t`` and the commands of the last period.
        slot : ndarray, shape (N, 2) [m]
            The period's slots.
        known : ndarray, shape (N,), bool
            The vehicles believed failed.
        seen : ndarray, shape (N, 3), or None
            The broadcast copies (None: the truth).
        live : list of int
            The live worlds.
        failed : callable
            ``failed(w, exc)`` ends world ``w`` (its plug-in failed).
        last : tuple of ndarray, shape (N,) each, or None
            The last period's commands ``(v1, v2)`` as the platoon knows them (the
            filter's ``v1_prev``, ``v2_prev``; None: the fleet's).
        """
        started = self._started
        self._started = True
        prev = (fleet.v1, fleet.v2) if last is None else last
        if self.batched:
            return self._batched(t, v1, v2, fleet, slot, known, seen, started, prev)
        layout = self._layout
        n = layout.n
        v1_out, v2_out = v1.copy(), v2.copy()
        for w in live:
            rows = layout.rows(w)
            sc = layout.scenarios[w]
            sensing = self._perception.sensing[w]
            v1_max, v2_max, accel_max = self._world_limits[w]
            ctx = FilterContext(
                t=t,
                dt=layout.h,
                pos=fleet.pos[rows],
                theta=fleet.theta[rows],
                vel=fleet.vel[rows],
                v1=v1[rows],
                v2=v2[rows],
                diameter=fleet.diameter[rows],
                params=dict(sc.safety.params),
                v1_prev=prev[0][rows] if started else None,
                v2_prev=prev[1][rows] if started else None,
                v1_max=v1_max,
                v2_max=v2_max,
                accel_max=accel_max,
                known_failed=known[rows],
                commanded=fleet.commanded[rows],
                obstacle_field=self._world_fields[w],
                seen=None if seen is None else seen[rows],
                sensing=sensing,
                memory=self._world_memory[w],
                stats=self.world_stats[w],
                slot=slot[rows],
                substeps=layout.substeps,
                steering=steering(fleet, rows) if self._cars[w] else None,
                **self._perception.context(w),
            )
            try:
                out = self._filters[w](ctx)
            except PluginRunError as exc:
                failed(w, exc)
                continue
            v1_out[rows] = np.broadcast_to(np.asarray(out[0], dtype=float), (n,))
            v2_out[rows] = np.broadcast_to(np.asarray(out[1], dtype=float), (n,))
        return v1_out, v2_out

    def _batched(
        self, t, v1, v2, fleet, slot, known, seen, started, prev
    ) -> tuple[np.ndarray, np.ndarray]:
        """One call of a batched filter on the rows of all worlds."""
        layout = self._layout
        v1_max, v2_max, accel_max = self._limits
        ctx = FilterContext(
            t=t,
            dt=layout.h,
            pos=fleet.pos,
            theta=fleet.theta,
            vel=fleet.vel,
            v1=v1,
            v2=v2,
            diameter=fleet.diameter,
            params=dict(layout.scenarios[0].safety.params),
            v1_prev=prev[0] if started else None,
            v2_prev=prev[1] if started else None,
            v1_max=v1_max,
            v2_max=v2_max,
            accel_max=accel_max,
            known_failed=known,
            commanded=fleet.commanded,
            obstacle_field=self._field,
            seen=seen,
            sensing=self._perception.sensing[0],
            memory=self._memory,
            stats=self.world_stats[0],  # read by a filter of one world only
            worlds=layout.K,
            world_stats=self.world_stats,
            slot=slot,
            substeps=layout.substeps,
            steering=steering(fleet, slice(None)) if any(self._cars) else None,
            **self._perception.context(),
        )
        out = self.filter(ctx)  # a PluginRunError ends every world (the loop's guard)
        return rows_of(out[0], layout.N), rows_of(out[1], layout.N)


def rows_of(value: object, n: int) -> np.ndarray:
    """A filter's command as a new float array of ``n`` rows (a scalar broadcast).

    An array of ``n`` floats is copied as it is (what the broadcast gives it, without
    its cost).
    """
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (n,):
        return value.copy()
    return np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()


def steering(fleet: Fleet, rows: slice) -> CarSteering:
    """The cars' steering of the fleet's ``rows`` as a filter sees it (views)."""
    return CarSteering(
        fleet.wheelbase[rows],
        fleet.max_steer[rows],
        fleet.max_steer_rate[rows],
        fleet.steer[rows],
    )
