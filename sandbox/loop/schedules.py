"""The open-loop command schedules of K worlds (``drive: {type: commands}``).

A vehicle driven by a schedule applies the rows ``(t_k, v1, v2)`` of its table, each
from ``t_k`` until the next (zero before the first), whatever its controller asks.
:class:`CommandSchedules` holds the tables of every such vehicle of every world, a
row of the stacked arrays each, and looks the rows in force up for all of them at
once.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sandbox.scenario import Scenario


class CommandSchedules:
    """The command schedules of K worlds of ``n`` vehicles (see the module docstring).

    The rows in force are looked up again only when ``t`` passes a row time of some
    schedule; in between the same commands are written again.

    Parameters
    ----------
    scenarios : sequence of Scenario
        The worlds' scenarios, in world order.
    n : int
        Vehicles per world.
    """

    def __init__(self, scenarios: Sequence[Scenario], n: int) -> None:
        rows, tables = [], []
        for w, sc in enumerate(scenarios):
            for i, v in enumerate(sc.vehicles):
                if v.drive.type == "commands":
                    rows.append(w * n + i)
                    table = np.array(v.drive.schedule, dtype=float)
                    tables.append(table.reshape(-1, 3))
        #: The stacked row of each schedule's vehicle.
        self.rows = np.array(rows, dtype=np.intp)
        self._length = np.array([len(tab) for tab in tables], dtype=np.intp)
        self._start = (np.cumsum(self._length) - self._length).astype(np.intp)
        # every table's rows one after the other, and a row of zeros at the end
        table = np.concatenate([*tables, np.zeros((1, 3))])
        self._times, self._v1, self._v2 = table[:, 0], table[:, 1], table[:, 2]
        #: How many rows of each schedule are in force (have started) so far.
        self._started = np.zeros(len(rows), dtype=np.intp)
        self._next = float(self._times[self._start].min()) if rows else np.inf
        self._v1_now = np.zeros(len(rows))
        self._v2_now = np.zeros(len(rows))

    def __len__(self) -> int:
        return len(self.rows)

    def apply(self, t: float, v1: np.ndarray, v2: np.ndarray) -> None:
        """Write the rows in force at ``t`` [s] into the scheduled vehicles' commands.

        Parameters
        ----------
        t : float [s]
        v1, v2 : ndarray, shape (N,) [m/s], [rad/s]
            The commands of every row, written in place.
        """
        now = t + 1e-12
        if self._next <= now:  # some schedule passes a row: look them up again
            length, start = self._length, self._start
            while True:
                more = self._started < length
                at = start + np.minimum(self._started, length - 1)
                due = more & (self._times[at] <= now)
                if not due.any():
                    break
                self._started += due
            more = self._started < length
            upcoming = self._times[start + np.minimum(self._started, length - 1)]
            self._next = float(upcoming[more].min()) if more.any() else np.inf
            held = self._started > 0
            at = start + np.maximum(self._started - 1, 0)
            self._v1_now = np.where(held, self._v1[at], 0.0)
            self._v2_now = np.where(held, self._v2[at], 0.0)
        v1[self.rows] = self._v1_now
        v2[self.rows] = self._v2_now
