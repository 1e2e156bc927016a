"""Range beams cast in the pymunk world: a planar LiDAR for every vehicle at once.

:class:`RangeCaster` answers one question per control period: along each beam of each
sensing vehicle, how far is the first surface (a static obstacle, a wall or another
vehicle), up to the beam's ``max_range``? The hits are pymunk's own segment queries on
the shapes of :class:`~sandbox.physics.world.World`, by one of two methods:

- ``space``: ``cpSpaceSegmentQueryFirst`` per beam (Chipmunk's spatial index finds the
  first shape; the vehicle's own disc is left out by a shape-filter group of its own);
- ``prefilter`` (the default): the (vehicle, shape) pairs whose bounding circles lie
  within reach are found in numpy (a KD-tree over the vehicles, the obstacle field's
  bounding circles), each pair's bearing and angular half-width select the beams that
  can touch it, and ``cpShapeSegmentQuery`` is called for those (beam, shape) pairs
  only; the nearest hit of each beam wins. A beam in open space costs nothing.

Both give the same distances (``tests/test_ranges.py`` checks it);
``benchmarks/bench_ranges.py`` measures them against the bare physics step. The C
functions are reached through pymunk's cffi module, as the bulk I/O of
:mod:`sandbox.physics.world` does, with pymunk's public queries as the fallback.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymunk

from sandbox.geometry.neighbours import neighbour_pairs
from sandbox.model.obstacle_field import ObstacleField

#: Codes of :attr:`Scan.kind`: what a beam hit.
HIT_NONE = 0
HIT_OBSTACLE = 1
HIT_VEHICLE = 2
#: The casting methods (see the module's docstring).
METHODS = ("prefilter", "space")


@dataclass
class Scan:
    """One scan of every vehicle, arrays ``(n, B)`` with ``B`` the most beams.

    Attributes
    ----------
    dist : ndarray (n, B) [m]
        Distance from the vehicle's centre to the first surface along each beam,
        ``max_range`` where nothing is hit, NaN for a beam the vehicle does not have.
    kind : ndarray (n, B) int8
        :data:`HIT_NONE`, :data:`HIT_OBSTACLE` or :data:`HIT_VEHICLE`.
    index : ndarray (n, B) int
        The obstacle's index in the scenario's ``obstacles``, or the vehicle's row;
        -1 where nothing is hit.
    """

    dist: np.ndarray
    kind: np.ndarray
    index: np.ndarray


class RangeCaster:
    """Casts the beams of many vehicles in a :class:`~sandbox.physics.world.World`.

    Parameters
    ----------
    world : World
        The pymunk world (its ``space``, vehicle ``bodies`` and ``obstacle_shapes``).
    field : ObstacleField
        The same obstacles as geometry (their bounding circles, for ``prefilter``).
    method : str
        ``prefilter`` or ``space`` (see the module's docstring).

    Raises
    ------
    TypeError
        ``world`` is not a pymunk world.
    """

    def __init__(
        self, world: object, field: ObstacleField, method: str = "prefilter"
    ) -> None:
        space = getattr(world, "space", None)
        if not isinstance(space, pymunk.Space):
            raise TypeError(
                "range sensors cast their beams in the pymunk world (a World with a "
                f"space); got {type(world).__name__}"
            )
        if method not in METHODS:
            raise ValueError(f"method {method!r} is not one of {METHODS}")
        self.world, self.field, self.method = world, field, method
        self.space = space
        self._vehicles = [body.shapes for body in world.bodies]
        self._discs = [next(iter(s)) for s in self._vehicles]
        self._radius = np.array([c.radius for c in self._discs], dtype=float)
        # What each shape is: (kind, index), by the address of its C shape.
        self._what: dict[int, tuple[int, int]] = {}
        for i, disc in enumerate(self._discs):
            self._what[_address(disc)] = (HIT_VEHICLE, i)
        for k, shape in enumerate(world.obstacle_shapes):
            self._what[_address(shape)] = (HIT_OBSTACLE, k)
        self._c = _c_functions()
        #: The vehicles' discs, then the obstacles' shapes, and their C handles.
        self._shapes = [*self._discs, *world.obstacle_shapes]
        self._handles = [shape._shape for shape in self._shapes]
        if method == "space":
            # A group of its own per vehicle: a query in that group skips its disc
            # (shapes of one non-zero group never collide; different groups do, so
            # the contacts are unchanged).
            for i, disc in enumerate(self._discs):
                disc.filter = pymunk.ShapeFilter(group=i + 1)

    def cast(
        self,
        pos: np.ndarray,
        theta: np.ndarray,
        rows: np.ndarray,
        first: np.ndarray,
        step: np.ndarray,
        count: np.ndarray,
        max_range: np.ndarray,
    ) -> Scan:
        """Cast the beams of the vehicles ``rows`` from their poses now.

        Beam ``k`` of vehicle ``rows[m]`` points at ``theta + first[m] + k step[m]``
        [rad], ``k < count[m]``, and reaches ``max_range[m]`` [m].

        Parameters
        ----------
        pos : ndarray (n, 2) [m]
        theta : ndarray (n,) [rad]
            Every vehicle's pose (the others are obstacles to the sensing ones).
        rows : ndarray (s,) int
            The sensing vehicles.
        first, step : ndarray (s,) [rad]
            Their first beam's angle about the heading and the spacing of the beams.
        count : ndarray (s,) int
            Their number of beams (>= 1).
        max_range : ndarray (s,) [m]

        Returns
        -------
        Scan
            Arrays ``(n, max(count))``: rows of vehicles without a sensor are NaN.
        """
        n, width = len(pos), int(count.max()) if len(count) else 0
        dist = np.full((n, width), np.nan)
        kind = np.zeros((n, width), dtype=np.int8)
        index = np.full((n, width), -1, dtype=np.intp)
        if not len(rows):
            return Scan(dist, kind, index)
        k = np.arange(width)
        valid = k[None, :] < count[:, None]
        dist[rows] = np.where(valid, max_range[:, None], np.nan)
        angle = theta[rows, None] + first[:, None] + k[None, :] * step[:, None]
        ends = pos[rows, None, :] + max_range[:, None, None] * np.stack(
            (np.cos(angle), np.sin(angle)), -1
        )
        if self.method == "space":
            hits = self._space_hits(pos, rows, ends, valid)
        else:
            hits = self._pair_hits(
                pos, theta, rows, first, step, count, max_range, ends
            )
        m, beam, alpha, what = hits
        if len(m):
            # The nearest hit of each beam: sorted by beam, then distance.
            d = alpha * max_range[m]
            flat = m * width + beam
            order = np.lexsort((d, flat))
            _, first_hit = np.unique(flat[order], return_index=True)
            pick = order[first_hit]
            r, b = rows[m[pick]], beam[pick]
            dist[r, b] = d[pick]
            kind[r, b] = what[pick, 0]
            index[r, b] = what[pick, 1]
        return Scan(dist, kind, index)

    # ------------------------------------------------------------------ methods
    def _space_hits(
        self, pos: np.ndarray, rows: np.ndarray, ends: np.ndarray, valid: np.ndarray
    ) -> tuple[np.ndarray, ...]:
        """``cpSpaceSegmentQueryFirst`` per beam: ``(row, beam, alpha, what)``."""
        m_out, b_out, a_out, w_out = [], [], [], []
        m, b = np.nonzero(valid)
        what, c = self._what, self._c
        if c is None:  # pragma: no cover - the public path
            starts, end_rows = pos[rows].tolist(), ends.tolist()
            for mm, bb in zip(m.tolist(), b.tolist(), strict=True):
                hit = self._first_hit(starts[mm], end_rows[mm][bb], int(rows[mm]) + 1)
                if hit is not None:
                    m_out.append(mm)
                    b_out.append(bb)
                    a_out.append(hit[0])
                    w_out.append(what[hit[1]])
            return _arrays(m_out, b_out, a_out, w_out)
        ffi, lib, info = c
        query, null, handle = lib.cpSpaceSegmentQueryFirst, ffi.NULL, self.space._space
        start = ffi.from_buffer(
            "cpVect[]", np.ascontiguousarray(pos[rows], dtype=float)
        )
        end = ffi.from_buffer("cpVect[]", np.ascontiguousarray(ends, dtype=float))
        everything = 0xFFFFFFFF
        filters = [(int(i) + 1, everything, everything) for i in rows.tolist()]
        width = ends.shape[1]
        for mm, bb in zip(m.tolist(), b.tolist(), strict=True):
            shape = query(
                handle, start[mm], end[mm * width + bb], 0.0, filters[mm], info
            )
            if shape != null:
                m_out.append(mm)
                b_out.append(bb)
                a_out.append(info.alpha)
                w_out.append(what[int(ffi.cast("uintptr_t", shape))])
        return _arrays(m_out, b_out, a_out, w_out)

    def _first_hit(
        self, start: list[float], end: list[float], group: int
    ) -> tuple[float, int] | None:
        """The first shape along one beam: ``(alpha, shape address)`` or None."""
        c = self._c
        if c is not None:
            ffi, lib, info = c
            shape = lib.cpSpaceSegmentQueryFirst(
                self.space._space,
                start,
                end,
                0.0,
                (group, 0xFFFFFFFF, 0xFFFFFFFF),
                info,
            )
            if shape == ffi.NULL:
                return None
            return float(info.alpha), int(ffi.cast("uintptr_t", shape))
        hit = self.space.segment_query_first(  # pragma: no cover - the public path
            tuple(start), tuple(end), 0.0, pymunk.ShapeFilter(group=group)
        )
        if hit is None:  # pragma: no cover
            return None
        return hit.alpha, _address(hit.shape)  # pragma: no cover

    def _pair_hits(
        self,
        pos: np.ndarray,
        theta: np.ndarray,
        rows: np.ndarray,
        first: np.ndarray,
        step: np.ndarray,
        count: np.ndarray,
        max_range: np.ndarray,
        ends: np.ndarray,
    ) -> tuple[np.ndarray, ...]:
        """Bounding circles in reach, their beams, ``cpShapeSegmentQuery`` for those."""
        n = len(pos)
        reach = float(max_range.max())
        slot = np.full(n, -1, dtype=np.intp)
        slot[rows] = np.arange(len(rows))
        # Vehicle pairs (both ways), then vehicle-obstacle pairs; m: the sensing row.
        i, j = neighbour_pairs(pos, reach + float(self._radius.max(initial=0.0)))
        a = np.concatenate((i, j))
        b = np.concatenate((j, i))
        keep = slot[a] >= 0
        a, b = a[keep], b[keep]
        center = [pos[b]]
        radius = [self._radius[b]]
        sensor, shape, code = [slot[a]], [b], [np.full(len(a), HIT_VEHICLE)]
        if not self.field.empty:
            o_rows, cols = self.field.candidates(pos[rows], reach)
            center.append(self.field.bound_center[cols])
            radius.append(self.field.bound_radius[cols])
            sensor.append(o_rows)
            shape.append(self.field.order[cols])
            code.append(np.full(len(cols), HIT_OBSTACLE))
        c, rho = np.concatenate(center), np.concatenate(radius)
        s, target, what = (
            np.concatenate(sensor),
            np.concatenate(shape),
            np.concatenate(code),
        )
        rel = c - pos[rows[s]]
        d = np.hypot(rel[:, 0], rel[:, 1])
        near = d - rho < max_range[s]
        s, target, what, rel, d, rho = (x[near] for x in (s, target, what, rel, d, rho))
        # The beams within the circle's angular half-width: relative angles k step
        # in [edge, edge + 2 half], edge the lowest in [0, 2 pi), and the same span one
        # turn lower (a circle across the first beam). A vehicle inside the bounding
        # circle tries every beam.
        inside = d <= rho
        half = np.arcsin(np.minimum(rho / np.maximum(d, 1e-12), 1.0))
        bearing = np.arctan2(rel[:, 1], rel[:, 0]) - theta[rows[s]] - first[s]
        edge = np.mod(bearing - half, 2.0 * math.pi)
        last = count[s] - 1
        pair, beam = [], []
        for turn in (0.0, -2.0 * math.pi):
            lo = np.ceil(_beams_to(edge + turn, step[s]) - 1e-9)
            hi = np.floor(_beams_to(edge + turn + 2.0 * half, step[s]) + 1e-9)
            lo = np.where(inside, 0, np.clip(lo, 0, last + 1)).astype(np.intp)
            hi = np.clip(hi, -1, last).astype(np.intp)
            hi = np.where(inside, last if turn == 0.0 else -1, hi)
            length = np.maximum(hi - lo + 1, 0)
            p = np.repeat(np.arange(len(s)), length)
            offset = np.arange(len(p)) - np.repeat(np.cumsum(length) - length, length)
            pair.append(p)
            beam.append(lo[p] + offset)
        p, beam = np.concatenate(pair), np.concatenate(beam)
        m = s[p]
        # Nearest circles first: each beam's candidates in order of the near edge of
        # their bounding circle, queried round by round while that edge is nearer
        # than the beam's nearest hit so far (a disc's circle is the disc: the first
        # candidate a beam meets usually ends it).
        near = np.maximum(d - rho, 0.0)[p]
        width = int(count.max()) + 1
        key = m * width + beam
        order = np.lexsort((near, key))
        key, near, p, beam, m = key[order], near[order], p[order], beam[order], m[order]
        first = np.ones(len(key), dtype=bool)
        first[1:] = key[1:] != key[:-1]
        where = np.arange(len(key))
        rank = where - np.maximum.accumulate(np.where(first, where, 0))
        beam_of = np.cumsum(first) - 1
        best = np.full(int(first.sum()), np.inf)
        alpha = np.full(len(key), np.nan)
        by_rank = np.argsort(rank, kind="stable")
        edges = np.searchsorted(rank[by_rank], np.arange(int(rank.max(initial=-1)) + 2))
        for r in range(len(edges) - 1):
            sel = by_rank[edges[r] : edges[r + 1]]
            sel = sel[near[sel] < best[beam_of[sel]]]
            if not len(sel):
                break
            got = self._shape_alpha(
                pos[rows[m[sel]]], ends[m[sel], beam[sel]], target[p[sel]], what[p[sel]]
            )
            alpha[sel] = got
            reach_hit = np.where(np.isfinite(got), got * max_range[m[sel]], np.inf)
            best[beam_of[sel]] = np.minimum(best[beam_of[sel]], reach_hit)
        hit = np.isfinite(alpha)
        what_hit = np.column_stack((what[p], target[p]))[hit]
        return m[hit], beam[hit], alpha[hit], what_hit

    def _shape_alpha(
        self, start: np.ndarray, end: np.ndarray, target: np.ndarray, what: np.ndarray
    ) -> np.ndarray:
        """``cpShapeSegmentQuery`` per (beam, shape): the hit's fraction, NaN: none."""
        shapes = self._shapes
        which = np.where(what == HIT_VEHICLE, target, len(self._discs) + target)
        c = self._c
        if c is not None:
            ffi, lib, info = c
            query, nan = lib.cpShapeSegmentQuery, math.nan
            handles = self._handles
            # The segments' ends as C arrays of cpVect over the numpy buffers.
            a = ffi.from_buffer("cpVect[]", np.ascontiguousarray(start, dtype=float))
            b = ffi.from_buffer("cpVect[]", np.ascontiguousarray(end, dtype=float))
            got = [
                info.alpha if query(handles[j], a[k], b[k], 0.0, info) else nan
                for k, j in enumerate(which.tolist())
            ]
            return np.array(got, dtype=float)
        out = np.full(len(which), np.nan)  # pragma: no cover - the public path
        for k, j in enumerate(which.tolist()):  # pragma: no cover
            hit = shapes[j].segment_query(tuple(start[k]), tuple(end[k]), 0.0)
            if hit is not None and hit.shape is not None:
                out[k] = hit.alpha
        return out  # pragma: no cover


def _beams_to(angle: np.ndarray, step: np.ndarray) -> np.ndarray:
    """How many beam spacings ``step`` [rad] the angles [rad] are, without overflow.

    One beam (``step`` 0) is at 0: an angle above it is ``+inf`` spacings away, one
    below ``-inf``; a spacing so narrow that the count overflows gives an infinite
    count too (the caller clips the counts to the beams there are).

    >>> _beams_to(np.array([1.0, -1.0, 0.0, 1.0]), np.array([0.5, 0.0, 0.0, 0.0]))
    array([  2., -inf,   0.,  inf])
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        count = angle / step
    beyond = np.where(angle > 0.0, np.inf, np.where(angle < 0.0, -np.inf, 0.0))
    return np.where(step > 0.0, count, beyond)


def _address(shape: pymunk.Shape) -> int:
    """The address of a shape's C struct (what ``cpSpaceSegmentQueryFirst`` returns)."""
    try:
        from pymunk._chipmunk import ffi

        return int(ffi.cast("uintptr_t", shape._shape))
    except (ImportError, AttributeError):  # pragma: no cover
        return id(shape)


def _c_functions() -> tuple | None:
    """The cffi ``ffi``, ``lib`` and a query-info struct, or None."""
    try:
        from pymunk._chipmunk import ffi, lib

        return ffi, lib, ffi.new("cpSegmentQueryInfo *")
    except (ImportError, AttributeError):  # pragma: no cover
        return None


def _arrays(
    m: list[int], b: list[int], a: list[float], w: list[tuple[int, int]]
) -> tuple[np.ndarray, ...]:
    return (
        np.array(m, dtype=np.intp),
        np.array(b, dtype=np.intp),
        np.array(a, dtype=float),
        np.array(w, dtype=np.intp).reshape(-1, 2),
    )
