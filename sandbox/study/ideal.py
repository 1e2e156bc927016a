"""The report's ideal kinematics: eq. (1) integrated exactly, without contacts.

:class:`IdealKinematics` implements the :class:`~sandbox.physics.interface.Physics`
interface with :func:`~sandbox.model.dynamics.unicycle_step` instead of pymunk: every
vehicle moves exactly as its commands say and vehicles pass through each other. Run
under the same :class:`~sandbox.loop.simulation.Simulation` (same controller, laws,
recovery), it answers "would the report's model collide here?": :func:`ideal_encounters`
counts the encounters (a pair closer than the sum of the radii, until the gap exceeds
the contact release distance, as contact episodes are counted) and the closest approach.
A check tool, not a scenario mode.
"""

from __future__ import annotations

import numpy as np

from sandbox.model.dynamics import unicycle_step
from sandbox.physics.world import PhysicalState
from sandbox.run.record import CollisionEvent
from sandbox.scenario import Scenario


class IdealKinematics:
    """Vehicles that obey eq. (1) exactly, with no contacts (a Physics back-end).

    Parameters
    ----------
    scenario : Scenario
    """

    def __init__(self, scenario: Scenario) -> None:
        self.pose = np.array([v.pose for v in scenario.vehicles], dtype=float)
        self.radius = np.array([v.diameter / 2 for v in scenario.vehicles])
        self.names = [v.name for v in scenario.vehicles]
        self.release = scenario.metrics.contact_release
        n = len(self.pose)
        self.events: list[CollisionEvent] = []
        self.closest = np.inf
        self._v1 = np.zeros(n)
        self._v2 = np.zeros(n)
        self._vel = np.zeros((n, 2))
        self._wrecked = np.zeros(n, dtype=bool)
        self._i, self._j = np.triu_indices(n, 1)
        self._touching = np.zeros(len(self._i), dtype=bool)

    def read_state(self) -> PhysicalState:
        """Poses and the velocities of the last period (copies)."""
        return PhysicalState(
            pos=self.pose[:, :2].copy(),
            theta=self.pose[:, 2].copy(),
            vel=self._vel.copy(),
            omega=self._v2.copy(),
        )

    def write_commands(
        self, theta: np.ndarray, v1: np.ndarray, v2: np.ndarray, dt: float
    ) -> None:
        """Hold ``(v1, v2)`` for the next period (wrecks stay at rest)."""
        self._v1 = np.where(self._wrecked, 0.0, v1)
        self._v2 = np.where(self._wrecked, 0.0, v2)

    def step(self, dt: float, substeps: int, t0: float) -> None:
        """Integrate eq. (1) exactly over ``dt``; count encounters at its end."""
        before = self.pose[:, :2].copy()
        self.pose = unicycle_step(self.pose, self._v1, self._v2, dt)
        self._vel = (self.pose[:, :2] - before) / dt
        if len(self._i) == 0:
            return
        d = self.pose[self._i, :2] - self.pose[self._j, :2]
        dist = np.hypot(d[:, 0], d[:, 1])
        gap = dist - self.radius[self._i] - self.radius[self._j]
        self.closest = min(self.closest, float(np.min(dist)))
        start = (gap < 0) & ~self._touching
        for k in np.flatnonzero(start):
            a, b = self.names[self._i[k]], self.names[self._j[k]]
            self.events.append(CollisionEvent(t0 + dt, a, b, "vehicle_vehicle"))
        self._touching = (self._touching & (gap <= self.release)) | (gap < 0)

    def immobilize(self, index: int) -> None:
        """A wreck: it stands still from now on."""
        self._wrecked[index] = True


def ideal_encounters(scenario: Scenario) -> tuple[int, float]:
    """Encounters and closest centre distance [m] of ``scenario`` under eq. (1).

    The same controller, laws and recovery as a run; vehicles move by eq. (1) exactly
    and pass through each other. Static obstacles are ignored (vehicle pairs only).
    """
    from sandbox.loop.simulation import Simulation

    world = IdealKinematics(scenario)
    Simulation(scenario, world=world).run()
    return len(world.events), world.closest
