"""The static obstacles as geometry: distances and nearest surface points, many at once.

:class:`ObstacleField` keeps circles as centres and radii, walls as capsules and boxes
and polygons as convex outlines, and answers the queries of the recovery strategies
and the safety filter for all vehicles in a few numpy expressions.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from sandbox.model.obstacles import ObstacleSpec

#: Distances are floored here [m] so that eq. (23) stays finite.
MIN_DIST = 1e-6


class ObstacleField:
    """Static obstacles as geometry for distance queries.

    Circles are kept as centres and radii, walls as capsules (segment plus radius),
    boxes
    and polygons as convex polygons (pymunk hulls them too).
    """

    def __init__(self, obstacles: tuple[ObstacleSpec, ...]) -> None:
        circles = [o for o in obstacles if o.type == "circle"]
        group = {"circle": 0, "wall": 1, "box": 2, "polygon": 2}
        #: The index in ``obstacles`` of each column of :meth:`nearest`.
        self.order = np.array(
            sorted(range(len(obstacles)), key=lambda k: group[obstacles[k].type]),
            dtype=np.intp,
        )
        self.circle_center = np.array([o.center for o in circles], dtype=float).reshape(
            -1, 2
        )
        self.circle_radius = np.array([o.radius for o in circles], dtype=float)
        walls = [o for o in obstacles if o.type == "wall"]
        self.wall_a = np.array([o.start for o in walls], dtype=float).reshape(-1, 2)
        self.wall_b = np.array([o.end for o in walls], dtype=float).reshape(-1, 2)
        self.wall_radius = np.array([o.thickness / 2 for o in walls], dtype=float)
        self.polygons = [
            np.array(o.outline(), dtype=float)
            for o in obstacles
            if o.type in ("box", "polygon")
        ]
        self.empty = not obstacles
        # Per column of nearest() (circles, walls, polygons): kind, index in its kind
        # and bounding circle; polygons padded to one vertex count by repeating their
        # last vertex (a zero-length edge changes neither the nearest point nor the
        # inside test).
        nc, nw = len(self.circle_radius), len(self.wall_radius)
        npoly = len(self.polygons)
        self.kind = np.repeat(np.arange(3), (nc, nw, npoly))
        self.index = np.concatenate((np.arange(nc), np.arange(nw), np.arange(npoly)))
        size = max((len(q) for q in self.polygons), default=1)
        self.poly = np.zeros((npoly, size, 2))
        for k, q in enumerate(self.polygons):
            self.poly[k, : len(q)] = q
            self.poly[k, len(q) :] = q[-1]
        poly_center = np.array([q.mean(axis=0) for q in self.polygons]).reshape(-1, 2)
        poly_reach = [
            float(np.hypot(*(q - c).T).max())
            for q, c in zip(self.polygons, poly_center, strict=True)
        ]
        self.bound_center = np.concatenate(
            (self.circle_center, 0.5 * (self.wall_a + self.wall_b), poly_center)
        )
        self.bound_radius = np.concatenate(
            (
                self.circle_radius,
                0.5 * np.hypot(*(self.wall_b - self.wall_a).T) + self.wall_radius,
                np.array(poly_reach, dtype=float),
            )
        )

    def candidates(
        self, pos: np.ndarray, reach: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(vehicle, obstacle)`` pairs whose bounding circle is closer than ``reach``.

        Every vehicle closer than ``reach`` to an obstacle's surface is among them.
        Sorted by vehicle, then obstacle; vehicles are tested in blocks so that memory
        stays small with many obstacles.

        Parameters
        ----------
        pos : ndarray, shape (n, 2) [m]
        reach : float [m]

        Returns
        -------
        rows, cols : ndarray of int, shape (k,)
            Vehicle and obstacle (column of :meth:`nearest`) of each pair.
        """
        m = len(self.bound_radius)
        rows, cols = [np.zeros(0, dtype=np.intp)], [np.zeros(0, dtype=np.intp)]
        if m:
            limit = (self.bound_radius + reach) ** 2
            block = max(1, 1_000_000 // m)
            for start in range(0, len(pos), block):
                p = pos[start : start + block]
                dx = p[:, 0:1] - self.bound_center[:, 0]
                dy = p[:, 1:2] - self.bound_center[:, 1]
                r, c = np.nonzero(dx * dx + dy * dy < limit)
                rows.append(r + start)
                cols.append(c)
        return (
            np.concatenate(rows).astype(np.intp),
            np.concatenate(cols).astype(np.intp),
        )

    def pair_distance(
        self, pos: np.ndarray, rows: np.ndarray, cols: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Like :meth:`nearest`, for the given ``(vehicle, obstacle)`` pairs only.

        Parameters
        ----------
        pos : ndarray, shape (n, 2) [m]
        rows, cols : ndarray of int, shape (k,)
            Vehicle and obstacle (column of :meth:`nearest`) of each pair.

        Returns
        -------
        dist : ndarray, shape (k,) [m]
            Negative inside an obstacle.
        point : ndarray, shape (k, 2) [m]
        """
        p = np.take(pos, rows, axis=0)
        dist = np.empty(len(rows))
        point = np.empty((len(rows), 2))
        kind, index = self.kind[cols], self.index[cols]
        sel = np.flatnonzero(kind == 0)
        if len(sel):
            center = self.circle_center[index[sel]]
            radius = self.circle_radius[index[sel]]
            rel = p[sel] - center
            norm = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), MIN_DIST)
            dist[sel] = norm - radius
            point[sel] = center + rel / norm[:, None] * radius[:, None]
        sel = np.flatnonzero(kind == 1)
        if len(sel):
            w = index[sel]
            q = _closest_on_segment_pairs(p[sel], self.wall_a[w], self.wall_b[w])
            rel = p[sel] - q
            norm = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), MIN_DIST)
            dist[sel] = norm - self.wall_radius[w]
            point[sel] = q + rel / norm[:, None] * self.wall_radius[w][:, None]
        sel = np.flatnonzero(kind == 2)
        if len(sel):
            a = self.poly[index[sel]]  # (k, E, 2)
            b = np.roll(a, -1, axis=1)
            ps = p[sel][:, None, :]
            q = _closest_on_segment_pairs(ps, a, b)  # (k, E, 2)
            d = np.hypot(ps[..., 0] - q[..., 0], ps[..., 1] - q[..., 1])
            k = np.argmin(d, axis=1)
            at = np.arange(len(sel))
            edge, rel = b - a, ps - a
            cross = edge[..., 0] * rel[..., 1] - edge[..., 1] * rel[..., 0]
            inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
            dist[sel] = np.where(inside, -d[at, k], d[at, k])
            point[sel] = q[at, k]
        return dist, point

    def nearest(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance to each obstacle's surface and the nearest surface point.

        Parameters
        ----------
        pos : ndarray, shape (n, 2) [m]

        Returns
        -------
        dist : ndarray, shape (n, m) [m]
            Negative inside an obstacle.
        point : ndarray, shape (n, m, 2) [m]
        """
        dists, points = [], []
        if len(self.circle_radius):
            rel = pos[:, None, :] - self.circle_center[None]
            norm = np.maximum(np.linalg.norm(rel, axis=-1), MIN_DIST)
            dists.append(norm - self.circle_radius)
            points.append(
                self.circle_center + rel / norm[..., None] * self.circle_radius[:, None]
            )
        if len(self.wall_radius):
            q = _closest_on_segments(pos, self.wall_a, self.wall_b)
            rel = pos[:, None, :] - q
            norm = np.maximum(np.linalg.norm(rel, axis=-1), MIN_DIST)
            dists.append(norm - self.wall_radius)
            points.append(q + rel / norm[..., None] * self.wall_radius[:, None])
        for poly in self.polygons:
            a, b = poly, np.roll(poly, -1, axis=0)
            q = _closest_on_segments(pos, a, b)
            d = np.linalg.norm(pos[:, None, :] - q, axis=-1)
            k = np.argmin(d, axis=1)
            rows = np.arange(len(pos))
            inside = _inside_convex(pos, poly)
            dists.append(np.where(inside, -d[rows, k], d[rows, k])[:, None])
            points.append(q[rows, k][:, None, :])
        if not dists:
            return np.zeros((len(pos), 0)), np.zeros((len(pos), 0, 2))
        return np.concatenate(dists, axis=1), np.concatenate(points, axis=1)


def _closest_on_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Closest point of each segment ``a[k]-b[k]`` to each point ``p[i]``: (n, m, 2)."""
    ab = b - a
    t = np.einsum("nmk,mk->nm", p[:, None, :] - a[None], ab) / np.maximum(
        np.sum(ab * ab, axis=1), 1e-300
    )
    t = np.clip(t, 0.0, 1.0)
    return a[None] + t[..., None] * ab[None]


def _closest_on_segment_pairs(
    p: np.ndarray, a: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """Closest point of segment ``a-b`` to ``p``, elementwise over the leading axes."""
    ab = b - a
    ap = p - a
    t = (ap[..., 0] * ab[..., 0] + ap[..., 1] * ab[..., 1]) / np.maximum(
        ab[..., 0] * ab[..., 0] + ab[..., 1] * ab[..., 1], 1e-300
    )
    t = np.clip(t, 0.0, 1.0)
    return a + t[..., None] * ab


def _inside_convex(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    edge = np.roll(poly, -1, axis=0) - poly
    rel = p[:, None, :] - poly[None]
    cross = edge[None, :, 0] * rel[..., 1] - edge[None, :, 1] * rel[..., 0]
    return np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
