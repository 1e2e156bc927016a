"""Which worlds of a loop are live, each world's status and description, its run.

A world ends alone (a diverged state, a plug-in that failed) or with the others (at
the duration, when stopped, when the caller asks for the results early); from then
on its rows are not stepped, and its :class:`~sandbox.Run` is kept here.
:class:`Liveness` is built with the loop (:mod:`sandbox.loop.building`) and changed
by the loop alone (:class:`~sandbox.loop.simulation.Simulation`, where worlds end).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from sandbox.errors import PluginRunError
from sandbox.run.record import STATUS_OK, Run

#: What a stage calls to end a world whose plug-in failed: ``failed(w, exc)``.
Failed = Callable[[int, PluginRunError], None]


class Liveness:
    """The worlds' liveness, statuses, descriptions and runs (module docstring).

    Parameters
    ----------
    info : list of dict
        Each world's description (``Run.info`` in the making).

    Attributes
    ----------
    live : ndarray, shape (K,), bool
        The worlds still stepped.
    count : int
        How many are (``np.count_nonzero(live)``).
    status : list of str
        Each world's status: ``ok`` until it ends otherwise.
    info : list of dict
        Each world's description.
    failed_at : list of dict
        When each failed vehicle of each world failed [s], by name.
    runs : dict of int to Run
        The runs of the worlds that ended.
    undefined : ndarray, shape (K,), bool
        The worlds that ended with their plan undefined (diverged, a plug-in that
        failed): their last sample shows no slot or target.
    closed : bool
        Whether the loop is over (every world ended, or the results were asked for).
    stopped : bool
        Whether ``should_stop`` stopped the loop.
    """

    def __init__(self, info: list[dict[str, Any]]) -> None:
        K = len(info)
        self.live = np.ones(K, dtype=bool)
        self.count = K
        self.status = [STATUS_OK] * K
        self.info = info
        self.failed_at: list[dict[str, float]] = [{} for _ in range(K)]
        self.runs: dict[int, Run] = {}
        self.undefined = np.zeros(K, dtype=bool)
        self.closed = False
        self.stopped = False
        self._worlds = tuple(range(K))

    def worlds(self) -> tuple[int, ...]:
        """The live worlds in order (as they are now: a world that ends later stays)."""
        return self._worlds

    def end(self, w: int, run: Run, undefined: bool) -> None:
        """World ``w`` has ended with ``run`` (``undefined``: its plan undefined)."""
        self.live[w] = False
        self.count -= 1
        self.undefined[w] = undefined
        self.runs[w] = run
        self._worlds = tuple(int(k) for k in self.live.nonzero()[0])
