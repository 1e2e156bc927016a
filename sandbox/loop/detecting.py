"""The detection stage of K worlds: what each world's platoon believes has failed.

Without ``detection:`` (the oracle) a platoon knows its failures at once. With a
detector, :class:`Detecting` asks it every period: once for the rows of every world
(a detector registered with ``batched=True``; each detection written to its world's
own record, :meth:`~sandbox.behaviour.detection.Detection.stack`) or world by world.
Each world's :class:`~sandbox.behaviour.detection.Detection` keeps that world's
events and summary.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from sandbox.behaviour.detection import Detection
from sandbox.errors import PluginRunError
from sandbox.loop.divergence import RowsView
from sandbox.loop.layout import Layout
from sandbox.loop.liveness import Failed
from sandbox.loop.perception import Perception
from sandbox.loop.state import Fleet
from sandbox.plugins.registration import get


class Detecting:
    """The detectors of a loop's K worlds (see the module docstring).

    Parameters
    ----------
    layout : Layout
    perception : Perception
        The broadcast (which copies arrived).
    physics : LoopPhysics
        The worlds' physics (their contact episodes).
    """

    def __init__(self, layout: Layout, perception: Perception, physics: Any) -> None:
        self._layout = layout
        self._perception = perception
        self._physics = physics
        #: Each world's detector (its events and summary), None: the oracle.
        self.worlds: list[Detection | None] = [
            Detection.make(sc, list(names))
            for sc, names in zip(layout.scenarios, layout.names, strict=True)
        ]
        #: Whether a detector runs (not the oracle).
        self.on = self.worlds[0] is not None
        #: One detector for the rows of all worlds (``batched=True``), else None.
        self.batch: Detection | None = None
        if self.on:
            method = layout.scenarios[0].detection.method
            if get("detector", method).options.get("batched"):
                self.batch = Detection.stack(self.worlds)

    def known(
        self,
        t: float,
        failing: np.ndarray,
        fleet: Fleet,
        seen: np.ndarray | None,
        live: Sequence[int],
        failed: Failed,
    ) -> np.ndarray:
        """What each world's platoon believes has failed at ``t`` [s], (N,) bool.

        Parameters
        ----------
        t : float [s]
        failing : ndarray, shape (N,), bool
            The vehicles with an active failure (the truth the detectors never read).
        fleet : Fleet
        seen : ndarray, shape (N, 3), or None
            The broadcast copies (None: the truth).
        live : list of int
            The live worlds.
        failed : callable
            ``failed(w, exc)`` ends world ``w`` (its plug-in failed).
        """
        layout = self._layout
        h = layout.h
        if self.batch is not None:  # one call of a batched detector
            if seen is None:  # the true poses: np.column_stack's, in two copies
                seen = np.empty((len(fleet.theta), 3))
                seen[:, :2], seen[:, 2] = fleet.pos, fleet.theta
            fresh = self._perception.fresh()
            contact = self._physics.in_contact()
            return self.batch.update_rows(t, h, fleet, seen, fresh, contact, failing)
        known = np.zeros(layout.N, dtype=bool)
        for w in live:
            rows = layout.rows(w)
            mine = RowsView(fleet, rows)
            if seen is None:
                rows_seen = np.column_stack((mine.pos, mine.theta))
            else:
                rows_seen = seen[rows]
            in_contact = getattr(self._physics.worlds[w], "in_contact", None)
            try:
                known[rows] = self.worlds[w].update_rows(
                    t,
                    h,
                    mine,
                    rows_seen,
                    self._perception.fresh(w),
                    None if in_contact is None else in_contact(),
                    failing[rows],
                )
            except PluginRunError as exc:
                failed(w, exc)
        return known

    def intend(self, v1: np.ndarray, v2: np.ndarray, live: Sequence[int]) -> None:
        """Tell the detectors the commands the controllers ask for this period."""
        if self.batch is not None:  # np.column_stack's, in two copies
            intended = np.empty((len(v1), 2))
            intended[:, 0], intended[:, 1] = v1, v2
            self.batch.intended = intended
            return
        layout = self._layout
        for w in live:
            rows = layout.rows(w)
            self.worlds[w].intended = np.column_stack((v1[rows], v2[rows]))
