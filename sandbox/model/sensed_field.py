"""Obstacles as a range sensor saw them: points, each seen by one vehicle.

:class:`SensedField` answers the queries of :class:`~sandbox.model.obstacle_field.
ObstacleField` (candidate pairs, distances and nearest points) for obstacles that are
points, each owned by the vehicle that sensed it: the recovery strategies and the
safety filter then work on what each vehicle measured (``recovery.obstacles:
sensed``) with the same code as on the map. A vehicle's points are the nearest hit of
each obstacle its beams touched (the beams grouped by the obstacle they hit, a
perfect segmentation of the scan), in world coordinates, so a held scan keeps them
where they were measured. Pure numpy.
"""

from __future__ import annotations

import numpy as np

from sandbox.model.obstacle_field import MIN_DIST


class SensedField:
    """Point obstacles, each seen by one vehicle; the interface of ``ObstacleField``.

    Attributes
    ----------
    owner : ndarray (m,) int
        The vehicle that sensed each point (sorted).
    point : ndarray (m, 2) [m]
        The points, in world coordinates.
    order : ndarray (m,) int
        The index in the scenario's ``obstacles`` of the obstacle each point is on.
    kind : ndarray (m,) int
        That obstacle's shape as :attr:`ObstacleField.kind` codes it (0: a circle,
        1: a wall, 2: a box or polygon), for the tangential term's surfaces.
    """

    #: Changes from one scan to the next: never cached between calls.
    dynamic = True

    def __init__(self) -> None:
        self.set(
            np.zeros(0, dtype=np.intp),
            np.zeros((0, 2)),
            np.zeros(0, dtype=np.intp),
            np.zeros(0, dtype=np.intp),
        )

    def set(
        self, owner: np.ndarray, point: np.ndarray, order: np.ndarray, kind: np.ndarray
    ) -> None:
        """Replace the points (``owner`` sorted, then ``order`` within an owner)."""
        self.owner, self.point, self.order, self.kind = owner, point, order, kind
        self.bound_center = point
        self.bound_radius = np.zeros(len(owner))

    @property
    def empty(self) -> bool:
        """Whether no vehicle sees any obstacle."""
        return len(self.owner) == 0

    def candidates(
        self, pos: np.ndarray, reach: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pairs ``(vehicle, point)`` of each vehicle and its points within ``reach``.

        Parameters
        ----------
        pos : ndarray (n, 2) [m]
            The vehicles' positions (or look-ahead points), in fleet order.
        reach : float [m]

        Returns
        -------
        rows, cols : ndarray of int (k,)
            Vehicle and point, sorted by vehicle then point.
        """
        if self.empty:
            empty = np.zeros(0, dtype=np.intp)
            return empty, empty
        rel = np.take(pos, self.owner, axis=0) - self.point
        near = np.flatnonzero(rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1] < reach**2)
        return self.owner[near], near.astype(np.intp)

    def pair_distance(
        self, pos: np.ndarray, rows: np.ndarray, cols: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Distance from ``pos[rows]`` to the points ``cols`` [m], and the points."""
        point = self.point[cols]
        rel = np.take(pos, rows, axis=0) - point
        return np.maximum(np.hypot(rel[:, 0], rel[:, 1]), MIN_DIST), point

    def nearest(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances (n, m) [m] to every point, ``inf`` to other vehicles' points."""
        rel = pos[:, None, :] - self.point[None]
        dist = np.maximum(np.hypot(rel[..., 0], rel[..., 1]), MIN_DIST)
        mine = self.owner[None, :] == np.arange(len(pos))[:, None]
        point = np.broadcast_to(self.point, (len(pos), *self.point.shape))
        return np.where(mine, dist, np.inf), point.copy()


def nearest_hits(
    vehicle: np.ndarray, obstacle: np.ndarray, dist: np.ndarray, point: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nearest hit of each (vehicle, obstacle): ``(vehicle, obstacle, point)``.

    Parameters
    ----------
    vehicle, obstacle : ndarray (h,) int
        Who saw each hit and what it hit.
    dist : ndarray (h,) [m]
        The hit's range.
    point : ndarray (h, 2) [m]
        The hit point.

    Returns
    -------
    vehicle, obstacle : ndarray (k,) int
        Sorted by vehicle, then obstacle.
    point : ndarray (k, 2) [m]
    """
    order = np.lexsort((dist, obstacle, vehicle))
    v, o = vehicle[order], obstacle[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = (v[1:] != v[:-1]) | (o[1:] != o[:-1])
    pick = order[first]
    return vehicle[pick], obstacle[pick], point[pick]
