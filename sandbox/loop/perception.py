"""What the vehicles of K worlds perceive at ``t_k``: broadcast, estimate, ranges.

:class:`Perception` holds the loop's sensing (``sensing:``: every world's broadcast,
each drawing from its own random stream, one
:class:`~sandbox.behaviour.sensing.Broadcast` of K worlds), the estimate the braking
barrier makes of the copies (:func:`~sandbox.behaviour.estimation.platoon_estimate`)
and the range sensors of every world (``sensors.range``,
:class:`~sandbox.behaviour.ranges.RangeReadings`). :meth:`Perception.update` turns
the true poses of a period into what the law, the recovery, the filter and the
detector see of them.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

import numpy as np

from sandbox.behaviour.estimation import platoon_estimate
from sandbox.behaviour.ranges import RangeReadings, context_fields
from sandbox.behaviour.sensing import make_broadcast
from sandbox.loop.layout import Layout
from sandbox.loop.state import Fleet
from sandbox.model.obstacle_field import ObstacleField


class Perception:
    """The broadcast, its estimate and the range sensors of K worlds.

    Parameters
    ----------
    layout : Layout
    worlds : list of Physics
        Each world's physics (the range sensors cast in it).
    obstacles : ObstacleField
        The worlds' obstacles (one map: their structure).
    """

    def __init__(self, layout: Layout, worlds: list[Any], obstacles: ObstacleField):
        scenarios, h = layout.scenarios, layout.h
        first = scenarios[0]
        self._layout = layout
        #: Every world's broadcast (each its own random stream), None without sensing.
        self.broadcast = make_broadcast(
            [sc.sensing for sc in scenarios], h, [sc.seed for sc in scenarios], layout.n
        )
        #: Each world's declared ``sensing:`` values (None: no broadcast).
        self.sensing = [
            None if self.broadcast is None else asdict(sc.sensing) for sc in scenarios
        ]
        #: The estimate of the copies the law and the recovery see (braking only).
        self.estimate = platoon_estimate(first, h, layout.substeps)
        #: The worlds' obstacles as geometry (the map).
        self.obstacles = obstacles
        #: Every world's range sensors (None: no vehicle has one).
        self.ranges = RangeReadings.make(list(scenarios), worlds, obstacles, layout.n)
        #: Whether anything is perceived but the truth (else :meth:`update` is idle).
        self.active = self.broadcast is not None or self.ranges is not None

    def update(
        self, t: float, fleet: Fleet, seen: np.ndarray | None
    ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """What is perceived at ``t`` [s] of the fleet's true poses.

        Returns the broadcast copies every vehicle holds (``seen``, (N, 3); None:
        the truth) and what the law and the recovery see of the others
        (``believed``: the copies, or their estimate under the braking barrier). The
        range sensors scan the vehicles whose scan is due.
        """
        if self.broadcast is not None:  # every world's copies, each its own draws
            seen = self.broadcast.update(fleet.pos, fleet.theta).copy()
        believed = seen
        if self.estimate is not None:  # the detector and the filter keep the copies
            believed = self.estimate.update(seen, fleet.v1, fleet.v2)
        if self.ranges is not None:
            self.ranges.update(t, fleet.pos, fleet.theta)
        return seen, believed

    def context(self, w: int | None = None) -> dict[str, np.ndarray]:
        """The range readings of a plug-in's context: world ``w``'s (None: all rows)."""
        ranges = self.ranges
        if ranges is None:
            return {}
        return context_fields(ranges if w is None else ranges.part(w))

    def fresh(self, w: int | None = None) -> np.ndarray | None:
        """Which copies of the last period arrived (world ``w``'s; None: all rows)."""
        if self.broadcast is None or self.broadcast.fresh is None:
            return None
        if w is None:
            return self.broadcast.fresh
        return self.broadcast.fresh[self._layout.rows(w)]
