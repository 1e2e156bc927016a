"""Collision-avoidance (recovery) strategies of section 4, selected by name.

Every strategy shifts each avoiding vehicle's target away from the obstacles within its
safe zone, eqs. (22)/(26):

    x_ref = slot + beta * sum_i alpha_i * vect_avoid_i,   vect_avoid_i = u_i / dist_i

with ``u_i`` the unit vector from obstacle i to the vehicle (eq. (24)) and ``dist_i``
the
distance (eq. (25)). Strategies differ only in the weight ``alpha(dist)``:

- ``none``: 0;
- ``discontinuous`` (4.1): 1 inside R, 0 outside (a switch);
- ``continuous`` (4.2, eq. (27)): 1 inside r, a linear ramp from 1 to 0 between r and R;
- ``smooth`` (the conclusion's proposal): a hyperbolic-tangent transition between r and
R,
  scaled to equal exactly 1 at r and 0 at R. It is continuous, not differentiable, at r
  and R: its slope there is ``s (1 - tanh(s)^2) / tanh(s)`` times the ramp's (0.15 for
  the default steepness s = 2), so the mode changes more gently than with the ramp.

Beyond the report, the weighted strategies take a tangential term (``recovery.
tangential``, the weight ``kappa >= 0``; 0, the default, is the report's field):

    shift = beta * sum_i alpha_i (u_i + kappa * s_i * J u_i) / dist_i

with ``J`` the +90 degree rotation and ``s_i = max(0, -g . u_i)``, ``g`` the unit
direction from the vehicle to its slot: 1 for an obstacle straight between the vehicle
and its slot, 0 once it is abeam or behind. Two vehicles meeting head-on both veer to
their right and pass (the rule of the road), where the radial field alone has a
symmetric equilibrium in which both stall. For walls, boxes and polygons ``u_i`` is
the normal from the nearest surface point, and of the two tangents along the surface
the one nearer ``g`` is taken (:func:`tangential_terms`).

Derivatives fed to eq. (6) with the shifted target (``recovery.target_derivatives``):

- ``hold`` (section 4.1): the law's own ``x_ref'``, ``x_ref''``, unchanged ("with all
  the other derivatives being unchanged"); only the position term sees the shift;
- ``estimate`` (the conclusion's second proposal): the backward-Euler estimates
  (eqs. (8)-(9)) of the shift's first and second derivatives are added to the law's.
  The differences are linear, so for a law that estimates its slot's motion
  (``own_estimate``, eqs. (18)-(19)) this is exactly the estimate of the shifted target
  ``slot + shift`` itself; for ``fixed`` (a constant offset) and unrotated ``virtual``
  it differs only in using the exact instead of the estimated motion of the slot; for
  ``rotating``, ``leader_ref`` and rotated ``virtual`` it keeps those laws' own
  approximation (the leader's or the reference's derivatives for every slot, eq. (12))
  and adds what recovery changes.

  Two caveats. A switch (``discontinuous``) makes the shift jump, so its estimated
  derivatives are impulses (a 0.67 m jump reads as 67 m/s, then +-6700 m/s^2). And the
  shift depends on the vehicle's own position x: its estimated acceleration feeds the
  vehicle's own acceleration back, one and two periods late, with the gain
  ``J = d shift / d x`` (``beta / dist^2`` for the switch, more with the slope of the
  ramp or of the tanh). To leading order in h the loop's extra poles are the roots of
  ``z^2 = J``: for ``|J| > 1`` it oscillates at the control rate, growing until the
  limits bound it, and v2 chatters between its limits when the vehicle is slow.

Obstacles are the other vehicles (centre-to-centre distance) and the static obstacles
(distance from the vehicle centre to the nearest surface point, pushing away from it).
Pure numpy; neighbours come from a KD-tree (scipy) above a few dozen vehicles, kept
between control steps as a Verlet list (:class:`NeighbourList`), so the cost per step
stays about linear in the number of vehicles.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox.plugins import Param, StrategyContext, get, register_strategy

if TYPE_CHECKING:
    from sandbox.obstacles import ObstacleSpec

#: A weight ``alpha(dist, R, r, steepness)`` of the built-in strategies, eq. (22).
Weight = Callable[[np.ndarray, float, float | None, float], np.ndarray]
#: The weights of the built-in strategies by name.
WEIGHTS: dict[str, Weight] = {}
#: Below this many vehicles all pairs are checked directly (cheaper than a tree).
BRUTE_FORCE_MAX = 48
#: Distances are floored here [m] so that eq. (23) stays finite.
MIN_DIST = 1e-6

#: The parameters of the built-in strategies.
BETA = Param(
    "number",
    1.0,
    unit="m^2",
    doc="Weight of the avoidance vectors, eq. (22)",
    minimum=0.0,
)
SMALL_R = Param(
    "length",
    None,
    unit="m",
    doc="Inner radius, < R (default: R / 2)",
    minimum=0.0,
    exclusive=True,
)
STEEPNESS = Param(
    "number",
    2.0,
    doc="Steepness s of the tanh transition",
    minimum=0.0,
    exclusive=True,
)
TANGENTIAL = Param(
    "number",
    0.0,
    doc="Weight kappa of the tangential term (0: the report's field)",
    minimum=0.0,
)


def _inner_radius(values: dict[str, Any], section: dict[str, Any]) -> list[tuple]:
    """Default ``r = R / 2``; ``r < R`` (the ramp runs from R in to r)."""
    big_r = section.get("R")
    if big_r is None:
        return []
    if values.get("r") is None:
        values["r"] = big_r / 2.0
        return []
    if values["r"] >= big_r:
        return [
            (
                "r",
                "r must be smaller than R",
                f"r = {values['r']:g} m, R = {big_r:g} m",
                "r < R: avoidance ramps up between R and r, eqs. (26)-(27)",
            )
        ]
    return []


def _weighted(name: str, weight: Weight) -> Callable[[StrategyContext], Any]:
    """The strategy of eqs. (22)-(27) with the weight ``alpha`` of ``name``."""
    WEIGHTS[name] = weight

    def strategy(ctx: StrategyContext) -> tuple[np.ndarray, np.ndarray]:
        p = ctx.params
        return weighted_shift(
            ctx,
            weight,
            p["beta"],
            p.get("r"),
            p.get("steepness", 2.0),
            p.get("tangential", 0.0),
        )

    strategy.__doc__ = weight.__doc__
    strategy.__name__ = strategy.__qualname__ = name
    strategy.__module__ = weight.__module__
    return strategy


def no_avoidance(
    dist: np.ndarray, R: float, r: float | None, steepness: float
) -> np.ndarray:
    """No recovery: alpha = 0."""
    return np.zeros_like(dist)


def discontinuous(
    dist: np.ndarray, R: float, r: float | None, steepness: float
) -> np.ndarray:
    """Section 4.1: alpha = 1 within the safe zone R, else 0 (eq. (22))."""
    return (dist < R).astype(float)


def continuous(
    dist: np.ndarray, R: float, r: float | None, steepness: float
) -> np.ndarray:
    """Section 4.2, eq. (27): 1 below r, ``1 - (dist - r)/(R - r)``, 0 above R."""
    return np.clip(1.0 - (dist - r) / (R - r), 0.0, 1.0)  # eq. (27)


def smooth(dist: np.ndarray, R: float, r: float | None, steepness: float) -> np.ndarray:
    """Conclusion: a tanh transition centred between r and R, 1 at r and 0 at R.

    ``alpha = (tanh(s (c - dist) / w) + tanh(s)) / (2 tanh(s))`` with ``c = (R + r)/2``,
    ``w = (R - r)/2`` and ``s`` the steepness; clipped to [0, 1] outside [r, R].
    """
    c, w = 0.5 * (R + r), 0.5 * (R - r)
    t = np.tanh(steepness)
    return np.clip((np.tanh(steepness * (c - dist) / w) + t) / (2.0 * t), 0.0, 1.0)


@register_strategy("none")
def no_recovery(ctx: StrategyContext) -> tuple[np.ndarray, np.ndarray]:
    """No recovery: targets are never shifted."""
    return np.zeros((ctx.n, 2)), np.zeros(ctx.n, dtype=bool)


WEIGHTS["none"] = no_avoidance
register_strategy("discontinuous", {"beta": BETA, "tangential": TANGENTIAL})(
    _weighted("discontinuous", discontinuous)
)
register_strategy(
    "continuous",
    {"beta": BETA, "r": SMALL_R, "tangential": TANGENTIAL},
    check=_inner_radius,
)(_weighted("continuous", continuous))
register_strategy(
    "smooth",
    {"beta": BETA, "r": SMALL_R, "steepness": STEEPNESS, "tangential": TANGENTIAL},
    check=_inner_radius,
)(_weighted("smooth", smooth))


def neighbour_pairs(pos: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i, j)``, ``i < j``, of vehicles closer than ``radius`` [m]."""
    n = len(pos)
    if n < 2:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    if n <= BRUTE_FORCE_MAX:
        i, j = np.triu_indices(n, 1)
        d2 = np.sum((pos[i] - pos[j]) ** 2, axis=1)
        keep = d2 < radius * radius
        return i[keep], j[keep]
    from scipy.spatial import cKDTree

    pairs = cKDTree(pos).query_pairs(radius, output_type="ndarray")
    return pairs[:, 0], pairs[:, 1]


class NeighbourList:
    """Pairs of vehicles closer than ``radius``, kept from one control step to the next.

    A Verlet list: the candidate pairs closer than ``radius + skin`` are found with a
    KD-tree and reused until some vehicle has moved more than ``skin / 2`` since; each
    call filters the candidates by their current distance. Two vehicles closer than
    ``radius`` now, having each moved at most ``skin / 2``, were closer than
    ``radius + skin`` when the candidates were built, so the result is exactly the set
    of :func:`neighbour_pairs`. Candidates are sorted by ``(i, j)``, which makes the
    order of the pairs (and so of the sums over them) independent of when the list was
    rebuilt.
    Up to :data:`BRUTE_FORCE_MAX` vehicles all pairs are the candidates (never rebuilt).

    Parameters
    ----------
    radius : float [m]
        Pairs closer than this are returned.
    skin : float [m], optional
        Extra search distance of the candidates; default ``radius / 2``. Larger: rarer
        rebuilds, more candidates to filter each step.

    Examples
    --------
    >>> pos = np.column_stack((np.arange(60.0), np.zeros(60)))
    >>> i, j = NeighbourList(1.5).pairs(pos)
    >>> len(i), bool(np.all(j == i + 1))
    (59, True)
    """

    def __init__(self, radius: float, skin: float | None = None) -> None:
        self.radius = float(radius)
        self.skin = 0.5 * self.radius if skin is None else float(skin)
        self.rebuilds = 0
        self._anchor: np.ndarray | None = None
        self._i = self._j = np.zeros(0, dtype=np.intp)
        self._obstacle_anchor: np.ndarray | None = None
        self._rows = self._cols = np.zeros(0, dtype=np.intp)

    def pairs(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sorted index pairs ``(i, j)``, ``i < j``, of vehicles closer than ``radius``.

        Parameters
        ----------
        pos : ndarray, shape (n, 2) [m]
            Current positions.
        """
        i, j, _ = self.near(pos)
        return i, j

    def near(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Like :meth:`pairs`, with the offsets ``pos[i] - pos[j]`` (m, 2) [m] too."""
        n = len(pos)
        anchor = self._anchor
        if anchor is None or len(anchor) != n:
            self._rebuild(pos)
        elif n > BRUTE_FORCE_MAX:
            moved = pos - anchor
            worst = float(np.max(moved[:, 0] * moved[:, 0] + moved[:, 1] * moved[:, 1]))
            if not worst <= 0.25 * self.skin * self.skin:  # also rebuilds on NaN
                self._rebuild(pos)
        # np.take on rows is several times faster than fancy indexing pos[i].
        rel = np.take(pos, self._i, axis=0)
        rel -= np.take(pos, self._j, axis=0)
        d2 = rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]
        keep = np.flatnonzero(d2 < self.radius * self.radius)
        return self._i.take(keep), self._j.take(keep), np.take(rel, keep, axis=0)

    def obstacle_pairs(
        self, pos: np.ndarray, field: ObstacleField
    ) -> tuple[np.ndarray, np.ndarray]:
        """Candidate ``(vehicle, obstacle)`` pairs: all obstacles closer than radius.

        The pairs whose obstacle's bounding circle is within ``radius + skin``, kept
        until some vehicle has moved more than ``skin / 2``: a vehicle now closer than
        ``radius`` to an obstacle's surface is within ``radius`` of its bounding circle,
        so it was within ``radius + skin / 2`` when the pairs were made. Sorted by
        vehicle, then obstacle (the column order of :meth:`ObstacleField.nearest`).

        Parameters
        ----------
        pos : ndarray, shape (n, 2) [m]
        field : ObstacleField
            The same field at every call.
        """
        anchor = self._obstacle_anchor
        rebuild = anchor is None or len(anchor) != len(pos)
        if not rebuild:
            moved = pos - anchor
            worst = float(np.max(moved[:, 0] * moved[:, 0] + moved[:, 1] * moved[:, 1]))
            rebuild = not worst <= 0.25 * self.skin * self.skin
        if rebuild:
            self._rows, self._cols = field.candidates(pos, self.radius + self.skin)
            self._obstacle_anchor = pos.copy()
        return self._rows, self._cols

    def _rebuild(self, pos: np.ndarray) -> None:
        n = len(pos)
        if n <= BRUTE_FORCE_MAX:
            i, j = np.triu_indices(n, 1)  # already in (i, j) order
        else:
            i, j = neighbour_pairs(pos, self.radius + self.skin)
            order = np.lexsort((j, i))
            i, j = i[order], j[order]
        self._i, self._j = i.astype(np.intp), j.astype(np.intp)
        self._anchor = pos.copy()
        self.rebuilds += 1


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


def avoidance_shift(
    pos: np.ndarray,
    avoiders: np.ndarray,
    strategy: str,
    beta: float,
    R: float,
    r: float | None,
    steepness: float,
    obstacles: ObstacleField,
    neighbours: NeighbourList | None = None,
    slot: np.ndarray | None = None,
    tangential: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The shift ``beta * sum_i alpha_i vect_avoid_i`` of a built-in strategy.

    Implements eqs. (22)-(27) for all vehicles at once: the registered strategy
    ``strategy`` called with a :class:`~sandbox.plugins.StrategyContext` of these
    positions (the simulation builds the full context).

    Parameters
    ----------
    pos : ndarray, shape (n, 2) [m]
        Vehicle positions.
    avoiders : ndarray, shape (n,), bool
        Vehicles that apply the strategy (others get a zero shift, but are still
        obstacles for the rest).
    strategy : str
        A registered strategy of :data:`WEIGHTS` (``none``, ``discontinuous``, ...).
    beta : float
        Aggressiveness of the avoidance [m^2].
    R, r : float [m]
        Safe-zone radius and (continuous/smooth) inner radius.
    steepness : float
        Steepness of the ``smooth`` transition.
    obstacles : ObstacleField
    neighbours : NeighbourList, optional
        Reused between calls (with radius ``R``) to find the vehicle pairs; default: a
        fresh search with :func:`neighbour_pairs`.
    slot : ndarray, shape (n, 2) [m], optional
        Each vehicle's slot (default: none, NaN), for the tangential term.
    tangential : float
        The tangential weight ``kappa`` (``recovery.tangential``), >= 0.

    Returns
    -------
    shift : ndarray, shape (n, 2) [m]
    active : ndarray, shape (n,), bool
        Vehicles with at least one obstacle weighted above zero (mode ``avoid``).
    """
    n = len(pos)
    ctx = StrategyContext(
        t=0.0,
        dt=0.0,
        pos=pos,
        theta=np.zeros(n),
        vel=np.zeros((n, 2)),
        slot=np.full((n, 2), np.nan) if slot is None else np.asarray(slot, float),
        diameter=np.zeros(n),
        may_avoid=avoiders,
        failed=np.zeros(n, dtype=bool),
        params={"beta": beta, "r": r, "steepness": steepness, "tangential": tangential},
        R=R,
        obstacle_field=obstacles,
        neighbours=neighbours,
    )
    return get("strategy", strategy).obj(ctx)


def weighted_shift(
    ctx: StrategyContext,
    weight: Weight,
    beta: float,
    r: float | None,
    steepness: float,
    kappa: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Eqs. (22)-(27): ``beta * sum_i alpha(dist_i) u_i / dist_i`` for each vehicle.

    The obstacles are the other vehicles within ``ctx.R`` and the static obstacles;
    ``weight`` is ``alpha(dist, R, r, steepness)``, zero beyond ``R``. With the
    tangential weight ``kappa > 0`` each term becomes ``alpha_i (u_i + kappa s_i t_i)
    / dist_i`` (:func:`tangential_terms`); ``kappa = 0`` computes exactly the
    report's field.
    """
    pos, avoiders, R = ctx.pos, ctx.may_avoid, ctx.R
    obstacles, neighbours = ctx.obstacle_field, ctx.neighbours
    n = len(pos)
    shift = np.zeros((n, 2))
    active = np.zeros(n, dtype=bool)
    if not np.any(avoiders):
        return shift, active
    goal = slot_directions(pos, ctx.slot) if kappa > 0 else None
    if neighbours is not None:
        i, j, rel = neighbours.near(pos)  # rel: from j to i
    else:
        i, j = neighbour_pairs(pos, R)
        rel = pos[i] - pos[j]  # from j to i
    if len(i):
        dist2 = rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]
        dist = np.maximum(np.sqrt(dist2), MIN_DIST)  # eq. (25)
        alpha = weight(dist, R, r, steepness)
        dd = dist * dist
        on = alpha > 0
        # Sum over the pairs, +alpha u/dist on i and -alpha u/dist on j (eqs. (23)-
        # (24)), in pair order: the same sums as np.add.at, several times faster.
        both = np.concatenate((i, j))
        seen = ctx.seen_pos
        if seen is None and goal is None:
            for axis in (0, 1):
                c = alpha * (rel[:, axis] / dd)
                shift[:, axis] = np.bincount(both, np.concatenate((c, -c)), minlength=n)
            active[i[on]] = True
            active[j[on]] = True
        elif goal is None:
            # Each vehicle sees itself exactly and the other's broadcast position: i
            # reads pos[i] - seen[j], j reads seen[i] - pos[j] (the pairs are those
            # of the true positions).
            rel_i = pos[i] - seen[j]
            rel_j = seen[i] - pos[j]
            terms = []
            for r_ in (rel_i, rel_j):
                d2 = r_[:, 0] * r_[:, 0] + r_[:, 1] * r_[:, 1]
                d = np.maximum(np.sqrt(d2), MIN_DIST)  # eq. (25)
                terms.append((weight(d, R, r, steepness), r_, d * d))
            for axis in (0, 1):
                (a_i, r_i, dd_i), (a_j, r_j, dd_j) = terms
                c = np.concatenate(
                    (a_i * r_i[:, axis] / dd_i, -a_j * r_j[:, axis] / dd_j)
                )
                shift[:, axis] = np.bincount(both, c, minlength=n)
            active[i[terms[0][0] > 0]] = True
            active[j[terms[1][0] > 0]] = True
        else:
            # With the tangential term: each side's vector from its obstacle, u, and
            # the term kappa s J u, over the true or the broadcast positions.
            if seen is None:
                rel_i, rel_j = rel, rel
            else:
                rel_i, rel_j = pos[i] - seen[j], seen[i] - pos[j]
            sides = []
            for v, g in ((rel_i, goal[i]), (-rel_j, goal[j])):
                d = np.maximum(np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]), MIN_DIST)
                u = v / d[:, None]
                vect = (u + tangential_terms(u, g, kappa)) / d[:, None]
                sides.append((weight(d, R, r, steepness), vect))
            (a_i, c_i), (a_j, c_j) = sides
            for axis in (0, 1):
                c = np.concatenate((a_i * c_i[:, axis], a_j * c_j[:, axis]))
                shift[:, axis] = np.bincount(both, c, minlength=n)
            active[i[a_i > 0]] = True
            active[j[a_j > 0]] = True
    if not obstacles.empty and neighbours is not None:
        # Only the obstacles near each vehicle (alpha is 0 beyond R for every strategy);
        # the same terms as below, summed over the candidate pairs.
        rows, cols = neighbours.obstacle_pairs(pos, obstacles)
        signed, point = obstacles.pair_distance(pos, rows, cols)
        dist = np.maximum(np.abs(signed), MIN_DIST)  # eq. (25)
        alpha = weight(np.maximum(signed, MIN_DIST), R, r, steepness)
        outward = np.where(signed < 0, -1.0, 1.0)[:, None]
        rel = (np.take(pos, rows, axis=0) - point) * outward
        dd = dist * dist
        if goal is not None:
            u = rel / dist[:, None]
            t = tangential_terms(u, goal[rows], kappa, obstacles.kind[cols] > 0)
            rel = rel + t * dist[:, None]
        for axis in (0, 1):  # eqs. (23)-(24)
            c = alpha * (rel[:, axis] / dd)
            shift[:, axis] += np.bincount(rows, c, minlength=n)
        active[rows[alpha > 0]] = True
    elif not obstacles.empty:
        signed, point = obstacles.nearest(pos)
        # A centre inside an obstacle (negative distance; possible only at the start) is
        # pushed out of it with full weight: u_i points from the surface point outward.
        dist = np.maximum(np.abs(signed), MIN_DIST)  # eq. (25)
        alpha = weight(np.maximum(signed, MIN_DIST), R, r, steepness)
        rel = (pos[:, None, :] - point) * np.where(signed < 0, -1.0, 1.0)[..., None]
        if goal is not None:
            m = signed.shape[1]
            u = (rel / dist[..., None]).reshape(-1, 2)
            g = np.repeat(goal, m, axis=0)
            flat = np.tile(obstacles.kind > 0, len(pos))
            t = tangential_terms(u, g, kappa, flat).reshape(rel.shape)
            rel = rel + t * dist[..., None]
        vect = rel / (dist * dist)[..., None]  # eqs. (23)-(24)
        shift += np.sum(alpha[..., None] * vect, axis=1)
        active |= np.any(alpha > 0, axis=1)
    shift *= beta  # eq. (22) / (26)
    shift[~avoiders] = 0.0
    active &= avoiders
    return shift, active


def slot_directions(pos: np.ndarray, slot: np.ndarray) -> np.ndarray:
    """Unit direction ``g`` from each vehicle to its slot, (n, 2); 0 when undefined.

    Zero for a vehicle on its slot (closer than :data:`MIN_DIST`) or without one (a
    NaN slot: open loop), so that its tangential term vanishes.
    """
    rel = np.asarray(slot, dtype=float) - pos
    norm = np.hypot(rel[:, 0], rel[:, 1])
    ok = np.isfinite(norm) & (norm > MIN_DIST)
    out = np.zeros_like(pos, dtype=float)
    out[ok] = rel[ok] / norm[ok, None]
    return out


def tangential_terms(
    u: np.ndarray,
    goal: np.ndarray,
    kappa: float,
    surface: np.ndarray | None = None,
) -> np.ndarray:
    """The tangential terms ``kappa s_i t_i`` of the avoidance vectors, (m, 2).

    ``s_i = max(0, -g . u_i)`` is 1 when obstacle i lies straight between the vehicle
    and its slot and 0 once it is abeam or behind; ``t_i = J u_i`` with ``J`` the +90
    degree rotation, so that two vehicles meeting head-on both pass on the same hand
    (each turns to its right). For an extended obstacle (``surface`` true: walls,
    boxes, polygons) ``u_i`` is the normal from its nearest point and ``J u_i`` runs
    along the surface; the sign of the tangent is chosen whose dot product with ``g``
    is the larger (the tangent nearest the slot direction; ``+J u_i`` on a tie).

    Parameters
    ----------
    u : ndarray, shape (m, 2)
        Unit vectors from the obstacles to the vehicles.
    goal : ndarray, shape (m, 2)
        Unit direction from each vehicle to its slot (0 when undefined).
    kappa : float
        Tangential weight, >= 0.
    surface : ndarray of bool, shape (m,), optional
        Terms of extended obstacles (default: none).
    """
    s = np.maximum(0.0, -(goal[:, 0] * u[:, 0] + goal[:, 1] * u[:, 1]))
    t = np.column_stack((-u[:, 1], u[:, 0]))  # J u
    if surface is not None:
        along = goal[:, 0] * t[:, 0] + goal[:, 1] * t[:, 1]
        t = np.where((surface & (along < 0))[:, None], -t, t)
    return (kappa * s)[:, None] * t
