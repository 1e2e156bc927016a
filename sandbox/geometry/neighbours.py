"""Neighbour search in the plane: the pairs of points closer than a radius.

:func:`neighbour_pairs` finds the pairs directly (all pairs up to
:data:`BRUTE_FORCE_MAX` points, a KD-tree of scipy above); :class:`NeighbourList` keeps
the candidates from one control step to the next (a Verlet list), so the cost per step
stays about linear in the number of vehicles; :class:`AllPairsByWorld` holds every
pair of each of K small worlds stacked; :func:`neighbour_search` chooses. Pure numpy:
used by the recovery strategies, the safety filter and the plug-in contexts alike.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

#: Below this many vehicles all pairs are checked directly (cheaper than a tree).
BRUTE_FORCE_MAX = 48


class Obstacles(Protocol):
    """What a neighbour list asks of a set of obstacles (an ``ObstacleField``).

    ``candidates(pos, radius)`` gives the sorted ``(vehicle, obstacle)`` pairs whose
    obstacle's bounding circle lies within ``radius`` [m] of the vehicle's position;
    a set whose obstacles change between calls may say so with ``dynamic = True``.
    """

    def candidates(
        self, pos: np.ndarray, radius: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The candidate pairs ``(vehicle, obstacle)`` within ``radius`` [m]."""
        ...


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

    def candidates(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The candidate pairs ``(i, j)``, intp and sorted, that :meth:`near` filters.

        Rebuilt first where some vehicle has moved more than ``skin / 2``.
        """
        n = len(pos)
        anchor = self._anchor
        if anchor is None or len(anchor) != n:
            self._rebuild(pos)
        elif n > BRUTE_FORCE_MAX:
            moved = pos - anchor
            worst = float(np.max(moved[:, 0] * moved[:, 0] + moved[:, 1] * moved[:, 1]))
            if not worst <= 0.25 * self.skin * self.skin:  # also rebuilds on NaN
                self._rebuild(pos)
        return self._i, self._j

    def remember(self, pos: np.ndarray, d2: np.ndarray) -> None:
        """Take note of the candidates' squared distances at ``pos`` (unused here)."""

    def near(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Like :meth:`pairs`, with the offsets ``pos[i] - pos[j]`` (m, 2) [m] too."""
        self.candidates(pos)
        # np.take on rows is several times faster than fancy indexing pos[i].
        rel = np.take(pos, self._i, axis=0)
        rel -= np.take(pos, self._j, axis=0)
        d2 = rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]
        keep = (d2 < self.radius * self.radius).nonzero()[0]
        return self._i.take(keep), self._j.take(keep), np.take(rel, keep, axis=0)

    def obstacle_pairs(
        self, pos: np.ndarray, field: Obstacles
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
        field : Obstacles
            The same field at every call; a field whose obstacles change between
            calls (``field.dynamic``, e.g. sensed points) is searched afresh.
        """
        if getattr(field, "dynamic", False):
            return field.candidates(pos, self.radius)
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


class AllPairsByWorld:
    """Every pair of each of K worlds of ``n`` vehicles, never one across worlds.

    Every pair of a world is a candidate (as alone, up to
    :data:`~sandbox.geometry.neighbours.BRUTE_FORCE_MAX` vehicles), in the single
    run's ``(i, j)`` order, world after world; so the sums over pairs add each
    vehicle's terms in the order it adds them alone. Obstacle candidates come from a
    :class:`NeighbourList` over all vehicles (a superset of the pairs in range; the
    others weigh exactly 0). Positions of another number of rows give the pairs of
    worlds of that many vehicles each (as a :class:`NeighbourList` takes them).
    """

    def __init__(self, worlds: int, n: int, radius: float) -> None:
        self.radius = float(radius)
        self.worlds = worlds
        self._pairs_of(n)
        self._obstacles = NeighbourList(radius)
        self._last: tuple[np.ndarray, np.ndarray] | None = None

    def _pairs_of(self, n: int) -> None:
        """The candidates of the worlds of ``n`` vehicles each."""
        self.rows = self.worlds * n
        i, j = np.triu_indices(n, 1)
        base = (np.arange(self.worlds) * n)[:, None]
        self._i = (base + i).ravel().astype(np.intp)
        self._j = (base + j).ravel().astype(np.intp)

    def _check(self, pos: np.ndarray) -> None:
        """The pairs of worlds of as many rows as ``pos`` has, where that changed."""
        if len(pos) != self.rows:
            if len(pos) % self.worlds:
                raise ValueError(f"{len(pos)} positions for {self.worlds} worlds")
            self._pairs_of(len(pos) // self.worlds)

    def near(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pairs closer than ``radius``, with ``pos[i] - pos[j]`` (as alone)."""
        self._check(pos)
        rel = np.take(pos, self._i, axis=0)
        rel -= np.take(pos, self._j, axis=0)
        d2 = rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]
        self._last = (pos, d2)
        keep = (d2 < self.radius * self.radius).nonzero()[0]
        return self._i.take(keep), self._j.take(keep), np.take(rel, keep, axis=0)

    def candidates(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every pair of every world (the candidates :meth:`near` filters)."""
        self._check(pos)
        return self._i, self._j

    def remember(self, pos: np.ndarray, d2: np.ndarray) -> None:
        """Keep the candidates' squared distances at ``pos`` for :meth:`distances`."""
        self._last = (pos, d2)

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

    def obstacle_pairs(
        self, pos: np.ndarray, field: Obstacles
    ) -> tuple[np.ndarray, np.ndarray]:
        """Candidate ``(vehicle, obstacle)`` pairs (see ``NeighbourList``)."""
        return self._obstacles.obstacle_pairs(pos, field)


def neighbour_search(
    worlds: int, n: int, radius: float
) -> AllPairsByWorld | NeighbourList:
    """The neighbour search of ``worlds`` worlds of ``n`` vehicles, stacked.

    Every pair of each world (:class:`AllPairsByWorld`) up to
    :data:`BRUTE_FORCE_MAX` vehicles a world, a Verlet list (:class:`NeighbourList`)
    of a larger fleet, which runs alone.

    Parameters
    ----------
    worlds : int
        The worlds whose rows are stacked, world after world.
    n : int
        Vehicles per world.
    radius : float [m]

    Raises
    ------
    ValueError
        Several worlds of more than :data:`BRUTE_FORCE_MAX` vehicles.

    >>> [type(neighbour_search(k, n, 1.5)).__name__ for k, n in ((4, 3), (1, 60))]
    ['AllPairsByWorld', 'NeighbourList']
    """
    if n <= BRUTE_FORCE_MAX:
        return AllPairsByWorld(worlds, n, radius)
    if worlds > 1:
        raise ValueError(
            f"{worlds} worlds of {n} vehicles: a fleet of more than "
            f"{BRUTE_FORCE_MAX} vehicles runs alone"
        )
    return NeighbourList(radius)
