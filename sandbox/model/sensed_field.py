"""Obstacles as a range sensor saw them: points, each seen by one vehicle.

:class:`SensedField` answers the queries of :class:`~sandbox.model.obstacle_field.
ObstacleField` (candidate pairs, distances and nearest points) for obstacles that are
points, each owned by the vehicle that sensed it: the recovery strategies and the
safety filter then work on what each vehicle measured (``recovery.obstacles:
sensed``) with the same code as on the map. A vehicle's points are, for each obstacle
its beams touched (the beams grouped by the obstacle they hit, a perfect segmentation
of the scan), the nearest point of the outline its hits draw
(:func:`nearest_surface_points`), in world coordinates, so a held scan keeps them
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


def nearest_surface_points(
    origin: np.ndarray,
    points: np.ndarray,
    obstacle: np.ndarray,
    count: np.ndarray,
    wrap: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each vehicle's nearest point of each obstacle its scan shows.

    The hits of one obstacle on adjacent beams are joined into a polyline (the scan's
    outline of its surface); the point is the nearest to the scan's origin on the two
    segments either side of the nearest hit (the hit itself when its neighbours missed
    that obstacle). On a flat face this is the face's own nearest point, so it moves
    smoothly as the vehicle does, where the nearest hit alone jumps from beam to beam.

    Parameters
    ----------
    origin : ndarray (n, 2) [m]
        Each vehicle's position when its scan was taken.
    points : ndarray (n, B, 2) [m]
        The hit points (world coordinates).
    obstacle : ndarray (n, B) int
        The obstacle each beam hit (its index in the scenario), -1 for none.
    count : ndarray (n,) int
        Each vehicle's number of beams.
    wrap : ndarray (n,) bool
        Whether its beams close a full turn (the last is adjacent to the first).

    Returns
    -------
    vehicle, obstacle : ndarray (k,) int
        Sorted by vehicle, then obstacle.
    point : ndarray (k, 2) [m]
    """
    v, b = np.nonzero(obstacle >= 0)
    o = obstacle[v, b]
    rel = points[v, b] - origin[v]
    dist = np.hypot(rel[:, 0], rel[:, 1])
    order = np.lexsort((dist, o, v))
    vs, os_ = v[order], o[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = (vs[1:] != vs[:-1]) | (os_[1:] != os_[:-1])
    pick = order[first]
    v, b, o = v[pick], b[pick], o[pick]
    best, best_d = points[v, b], dist[pick]
    for step in (-1, 1):
        nb = b + step
        nb = np.where(wrap[v], np.mod(nb, np.maximum(count[v], 1)), nb)
        inside = (nb >= 0) & (nb < count[v])
        nb = np.clip(nb, 0, points.shape[1] - 1)
        same = inside & (obstacle[v, nb] == o)
        q = _closest_on_segment(origin[v], points[v, b], points[v, nb])
        d = np.hypot(*(q - origin[v]).T)
        better = same & (d < best_d)
        best = np.where(better[:, None], q, best)
        best_d = np.where(better, d, best_d)
    return v.astype(np.intp), o.astype(np.intp), best


def _closest_on_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The point of segment ``a``-``b`` nearest ``p``, row by row (m, 2)."""
    ab, ap = b - a, p - a
    den = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    t = np.clip(np.sum(ap * ab, axis=1) / den, 0.0, 1.0)
    return a + t[:, None] * ab
