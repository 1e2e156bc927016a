"""The interface between the simulation loop and a physics back-end.

:class:`~sandbox.loop.simulation.Simulation` talks to its world only through the few
methods of :class:`Physics`: one bulk read of every vehicle's state, one bulk write of
every vehicle's unicycle commands, one fixed-period step, and the ``crash`` failure's
immobilisation. The pymunk world (:class:`sandbox.physics.world.World`) implements it; a
kinematic world (pure integration of eq. (1), no contacts) or a batched world holding
many independent worlds in stacked arrays can implement the same methods and run under
the same loop.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from sandbox.physics.world import PhysicalState
from sandbox.run.record import CollisionEvent


@runtime_checkable
class Physics(Protocol):
    """What the simulation loop needs from a world.

    Attributes
    ----------
    events : list of CollisionEvent
        Contact onsets so far, in time order (appended by :meth:`step`).
    failed : ndarray, shape (n,), bool, or None
        Set by the loop every period before :meth:`step`: the vehicles with an active
        failure, so that a contact starting then can be marked not ``healthy``.
    """

    events: list[CollisionEvent]
    failed: np.ndarray | None

    def read_state(self) -> PhysicalState:
        """Every vehicle's pose and velocity, arrays indexed by vehicle (copies)."""
        ...

    def write_commands(
        self, theta: np.ndarray, v1: np.ndarray, v2: np.ndarray, dt: float
    ) -> None:
        """Set the commands ``(v1, v2)`` [m/s, rad/s], shape (n,) each, for one period.

        ``theta`` (n,) [rad] is the heading at the start of the period and ``dt`` [s]
        the period, so that a back-end can drive the arc of eq. (1).
        """
        ...

    def step(self, dt: float, substeps: int, t0: float) -> None:
        """Advance by one control period ``dt`` [s] from time ``t0`` [s]."""
        ...

    def immobilize(self, index: int) -> None:
        """Make vehicle ``index`` an immovable wreck (the ``crash`` failure)."""
        ...
