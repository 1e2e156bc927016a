"""The detection stage of K worlds: what each world's platoon believes has failed.

Without ``detection:`` (the oracle) a platoon knows its failures at once. With a
detector, :class:`Detecting` asks the worlds'
:class:`~sandbox.behaviour.detection.BatchDetection` every period, with the rows of
every world: the detector is called once for all of them (registered with
``batched=True``) or world by world, and each world's detections are its own.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from sandbox.behaviour.detection import BatchDetection
from sandbox.loop.layout import Layout
from sandbox.loop.liveness import Failed
from sandbox.loop.perception import Perception
from sandbox.loop.state import Fleet


class Detecting:
    """The detector of a loop's K worlds (see the module docstring).

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
        #: The worlds' detector (their events and summaries), None: the oracle.
        self.detection: BatchDetection | None = BatchDetection.make(
            layout.scenarios, layout.names
        )
        #: Whether a detector runs (not the oracle).
        self.on = self.detection is not None

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
        if seen is None:  # the true poses: np.column_stack's, in two copies
            seen = np.empty((len(fleet.theta), 3))
            seen[:, :2], seen[:, 2] = fleet.pos, fleet.theta
        return self.detection.update(
            t,
            self._layout.h,
            fleet,
            seen,
            self._perception.fresh(),
            self._physics.in_contact(),
            failing,
            live,
            failed,
        )

    def intend(self, v1: np.ndarray, v2: np.ndarray) -> None:
        """Tell the detector the commands the vehicles send this period."""
        intended = np.empty((len(v1), 2))  # np.column_stack's, in two copies
        intended[:, 0], intended[:, 1] = v1, v2
        self.detection.intended = intended
