"""The reference of a loop, evaluated a chunk of periods at a time.

A reference elementwise in time
(:data:`~sandbox.model.references.TABULATED_REFERENCES`) gives at ``t_k = k h`` the
bits its evaluation at that time alone gives, whatever other times it is evaluated
with. :class:`ReferenceRows` therefore evaluates it for :data:`CHUNK` periods at once
and hands out the row of each period: a long run keeps one chunk, never a table of
its whole duration.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Periods of the reference evaluated at once.
CHUNK = 1024


class ReferenceRows:
    """A tabulated reference's rows ``(p, p', p'')`` at the loop's times ``k h``.

    Parameters
    ----------
    reference : object
        A built reference whose type is in
        :data:`~sandbox.model.references.TABULATED_REFERENCES`.
    h : float [s]
        The control period.
    steps : int
        The last period (``k`` runs from 0 to ``steps``).

    K : int
        The worlds that share the reference (:meth:`points` gives a row each).
    """

    def __init__(self, reference: Any, h: float, steps: int, K: int = 1) -> None:
        self.reference, self.h, self.steps, self.K = reference, h, steps, K
        #: The first period of the chunk held, and its rows (three (m, 2) arrays).
        self.start = -1
        self.table: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._points: np.ndarray | None = None

    def chunk(self, k: int) -> tuple[tuple[np.ndarray, ...], int]:
        """The chunk holding period ``k`` and ``k``'s row in it (evaluated if new)."""
        start = self.start
        if self.table is None or not start <= k < start + len(self.table[0]):
            end = min(k + CHUNK, self.steps + 1)
            times = np.array([j * self.h for j in range(k, max(end, k + 1))])
            self.table = tuple(self.reference.evaluate(times))
            self.start = start = k
            self._points = None
        return self.table, k - start

    def points(self, k: int) -> np.ndarray:
        """The reference point at ``t_k`` of every world, (K, 2) [m] (a view)."""
        _, i = self.chunk(k)
        return self.points_of(i)

    def points_of(self, i: int) -> np.ndarray:
        """The points of row ``i`` of the chunk held, (K, 2) [m] (a view)."""
        if self._points is None:  # the chunk's points, a row each world
            p = self.table[0]
            self._points = np.empty((len(p), self.K, 2))
            self._points[...] = p[:, None, :]
        return self._points[i]

    def row(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(p, p', p'')`` at ``t_k`` (views of the chunk, never written)."""
        (p, dp, ddp), i = self.chunk(k)
        return p[i], dp[i], ddp[i]
