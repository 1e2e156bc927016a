"""What a plug-in sees: the context objects passed to laws, strategies, failures, ...

One dataclass per kind of plug-in (:mod:`sandbox.plugins`), filled by the simulation
loop (or the loader, for obstacles) each time the plug-in is called. Arrays are indexed
by vehicle, in fleet order; the plug-in must not modify them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class StrategyContext:
    """What a recovery strategy sees at one control step.

    Attributes
    ----------
    t, dt : float [s]
        Time and control period.
    pos : ndarray (n, 2) [m]
    theta : ndarray (n,) [rad]
    vel : ndarray (n, 2) [m/s]
        Measured positions, headings and velocities.
    slot : ndarray (n, 2) [m]
        The law's slot of each vehicle (NaN for open-loop vehicles).
    diameter : ndarray (n,) [m]
    may_avoid : ndarray (n,) bool
        Vehicles allowed to avoid (not the leader unless ``leader_avoids``, not failed,
        not open loop).
    failed : ndarray (n,) bool
        Vehicles with an active failure.
    params : dict
        The strategy's YAML values (lengths in metres, defaults filled in).
    R : float [m]
        The safe-zone radius ``recovery.R`` (the radius of the neighbour index).
    obstacle_field : ObstacleField
        The static obstacles.
    neighbours : NeighbourList or None
        The loop's incremental neighbour index (over the true positions).
    seen_pos : ndarray (n, 2) [m] or None
        The broadcast positions each vehicle receives of the others (``sensing:``,
        see :mod:`sandbox.behaviour.sensing`); None: every vehicle sees the others' true
        ``pos``. A vehicle's own position is always ``pos``.
    ranges : ndarray (n, B) [m] or None
        The range sensor's last readings (``sensors.range``, see
        :mod:`sandbox.behaviour.ranges`), NaN for a vehicle or beam without one; None:
        no sensor. With ``recovery.obstacles: sensed``, ``obstacle_field`` holds the
        sensed points instead of the map.
    beam_angles : ndarray (n, B) [rad] or None
        Each beam's angle about the heading, from ``-fov/2`` (right) to ``+fov/2``.
    platoon : ndarray (n,) int or None
        The index of each vehicle's platoon in ``platoons:`` (None: one platoon).
    """

    t: float
    dt: float
    pos: np.ndarray
    theta: np.ndarray
    vel: np.ndarray
    slot: np.ndarray
    diameter: np.ndarray
    may_avoid: np.ndarray
    failed: np.ndarray
    params: dict[str, Any]
    R: float
    obstacle_field: Any
    neighbours: Any = None
    seen_pos: np.ndarray | None = None
    ranges: np.ndarray | None = None
    beam_angles: np.ndarray | None = None
    platoon: np.ndarray | None = None

    @property
    def n(self) -> int:
        """Number of vehicles."""
        return len(self.pos)

    def pairs(self, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vehicle pairs closer than ``radius`` [m]: ``(i, j, dist)``, ``i < j``.

        From the neighbour index (kept between steps) when ``radius <= R``, else a
        fresh search. Sorted by ``(i, j)``; ``dist`` (m,) [m] centre to centre.
        """
        i, j, rel = self._near(radius)
        return i, j, np.sqrt(rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1])

    def _near(self, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from sandbox.geometry.neighbours import neighbour_pairs

        if self.neighbours is not None and radius <= self.neighbours.radius:
            i, j, rel = self.neighbours.near(self.pos)
            if radius < self.neighbours.radius:
                d2 = rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]
                keep = np.flatnonzero(d2 < radius * radius)
                i, j, rel = i.take(keep), j.take(keep), np.take(rel, keep, axis=0)
            return i, j, rel
        i, j = neighbour_pairs(self.pos, radius)
        order = np.lexsort((j, i))
        i, j = i[order].astype(np.intp), j[order].astype(np.intp)
        return i, j, self.pos[i] - self.pos[j]

    def obstacles(
        self, radius: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Vehicle-obstacle pairs closer than ``radius`` [m] to the surface.

        Returns
        -------
        i : ndarray (m,) int
            Vehicle.
        k : ndarray (m,) int
            Obstacle, its index in the scenario's ``obstacles`` list.
        dist : ndarray (m,) [m]
            Distance from the vehicle's centre to the obstacle's surface, negative
            inside it.
        away : ndarray (m, 2)
            Unit vector from the nearest surface point toward the vehicle (out of the
            obstacle when the centre is inside).
        """
        field_ = self.obstacle_field
        if field_ is None or field_.empty:
            empty = np.zeros(0, dtype=np.intp)
            return empty, empty, np.zeros(0), np.zeros((0, 2))
        rows, cols = field_.candidates(self.pos, radius)
        signed, point = field_.pair_distance(self.pos, rows, cols)
        keep = np.flatnonzero(signed < radius)
        rows, cols, signed = rows[keep], cols[keep], signed[keep]
        rel = (self.pos[rows] - point[keep]) * np.where(signed < 0, -1.0, 1.0)[:, None]
        norm = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), 1e-12)
        return rows, field_.order[cols], signed, rel / norm[:, None]


@dataclass
class LawContext:
    """What a formation law sees at one control step.

    Attributes
    ----------
    t, dt : float [s]
    pos : ndarray (n, 2) [m]
    theta : ndarray (n,) [rad]
    vel : ndarray (n, 2) [m/s]
    offset : ndarray (n, 2) [m]
        The vehicles' ``offset`` (delta1, delta2).
    leader : int
        Index of the leader, -1 if none. A built-in law of K worlds that re-form
        apart (``reconfigure:``, ``on_leader_failure:``) gets each world's, an int
        array of shape (K,), with ``leader_pos`` and ``leader_theta`` each world's
        leader's; a plug-in law is then called world by world.
    leader_pos : ndarray (2,) [m] or None
    leader_theta : float [rad] or None
    reference : tuple of ndarray (2,) or None
        ``(p, p', p'')`` of the reference at ``t``.
    params : dict
        The law's YAML values.
    memory : dict
        Kept from one step to the next (for a law's own estimates).
    ranges, beam_angles : ndarray (n, B) or None
        The range sensor's readings [m] and beam angles [rad], as for
        :class:`StrategyContext`; None: no sensor.
    platoon : ndarray (n,) int or None
        With ``platoons:``, the rows are the law's platoon only; this is the index
        of that platoon for each (None: one platoon).
    """

    t: float
    dt: float
    pos: np.ndarray
    theta: np.ndarray
    vel: np.ndarray
    offset: np.ndarray
    leader: int
    leader_pos: np.ndarray | None
    leader_theta: float | None
    reference: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    params: dict[str, Any]
    memory: dict[str, Any]
    ranges: np.ndarray | None = None
    beam_angles: np.ndarray | None = None
    platoon: np.ndarray | None = None


@dataclass
class FailureContext:
    """What a failure kind sees for one failed vehicle at one control step.

    Attributes
    ----------
    t : float [s]
    since : float [s]
        Time since the failure's onset.
    vehicle : str
        Name of the vehicle.
    index : int
        Its index in the fleet.
    v1, v2 : float [m/s], [rad/s]
        The controller's commands this step.
    v2_onset : float [rad/s]
        The steering command at onset.
    params : dict
        The failure's YAML values.
    """

    t: float
    since: float
    vehicle: str
    index: int
    v1: float
    v2: float
    v2_onset: float
    params: dict[str, Any]


@dataclass
class ReferenceContext:
    """What a reference function sees: ``t`` (float or array [s]) and its params."""

    t: Any
    params: dict[str, Any]


@dataclass
class ObstacleContext:
    """What an obstacle type sees: its ``name`` and its YAML values ``params``."""

    name: str
    params: dict[str, Any]


@dataclass
class FilterContext:
    """What a safety filter sees at one control step (``safety:``).

    Attributes
    ----------
    t, dt : float [s]
    pos, theta, vel : ndarray
        As for :class:`StrategyContext`: the true positions [m], headings [rad] and
        measured velocities [m/s] of the centres.
    v1, v2 : ndarray (n,) [m/s], [rad/s]
        The commands about to be applied (the controller's, ``v2`` within
        ``v2_max``).
    diameter : ndarray (n,) [m]
    params : dict
        The filter's YAML values (lengths in metres, defaults filled in).
    v1_prev, v2_prev : ndarray (n,) [m/s], [rad/s] or None
        The commands applied over the last period (None at the first step).
    v1_max, v2_max, accel_max : float or ndarray (n,)
        The vehicles' limits [m/s], [rad/s], [m/s^2] (``inf`` where unlimited).
    known_failed : ndarray (n,) bool or None
        The vehicles the platoon believes failed (``Simulation.known_failed``).
    commanded : ndarray (n,) bool or None
        Vehicles driven open loop (``drive: commands``).
    obstacle_field : ObstacleField or None
        The static obstacles (with ``recovery.obstacles: sensed``, the points each
        vehicle's range sensor sees, :class:`~sandbox.model.sensed_field.SensedField`).
    seen : ndarray (n, 3) or None
        The broadcast poses ``(x1, x2, x3)`` each vehicle receives of the others
        (``sensing:``); None: the truth.
    sensing : dict or None
        The declared ``sensing:`` values (``position_noise`` [m], ``heading_noise``
        [rad], ``delay`` [s], ``loss``), from which a filter may derive a margin;
        None: no sensing.
    memory : dict
        Kept from one step to the next (the filter's own state).
    stats : dict
        Counters the filter keeps; written to ``metrics.json`` under ``safety``.
    ranges, beam_angles : ndarray (n, B) or None
        The range sensor's readings [m] and beam angles [rad], as for
        :class:`StrategyContext`; None: no sensor.
    platoon : ndarray (n,) int or None
        The index of each vehicle's platoon in ``platoons:`` (None: one platoon).
    worlds : int
        How many worlds the rows hold (1, or K for a filter registered with
        ``batched=True`` called once for a loop of K worlds: ``n`` rows each, world
        after world).
    world_stats : list of dict or None
        Each world's counters, in the order of its rows (None: ``stats``, the
        counters of one world).
    slot : ndarray (n, 2) or None
        Each vehicle's formation slot [m] (NaN where undefined); None: unknown.
    substeps : int
        The physics' substeps a period: a drive reaches a new command one substep
        into the period (the first substep runs at the last period's command).
    steering : CarSteering or None
        The cars among the rows (``model: bicycle``): their wheelbases (NaN on a
        unicycle's row), steering limits and last steering angles
        (:class:`~sandbox.model.bicycle.CarSteering`); None: no car. A car executes
        the turn rate ``v1 tan(delta) / L`` of a steering angle within its limits,
        whatever ``v2`` the filter returns.
    """

    t: float
    dt: float
    pos: np.ndarray
    theta: np.ndarray
    vel: np.ndarray
    v1: np.ndarray
    v2: np.ndarray
    diameter: np.ndarray
    params: dict[str, Any]
    v1_prev: np.ndarray | None = None
    v2_prev: np.ndarray | None = None
    v1_max: Any = np.inf
    v2_max: Any = np.inf
    accel_max: Any = np.inf
    known_failed: np.ndarray | None = None
    commanded: np.ndarray | None = None
    obstacle_field: Any = None
    seen: np.ndarray | None = None
    sensing: dict[str, float] | None = None
    memory: dict[str, Any] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    ranges: np.ndarray | None = None
    beam_angles: np.ndarray | None = None
    platoon: np.ndarray | None = None
    worlds: int = 1
    world_stats: list[dict[str, Any]] | None = None
    slot: np.ndarray | None = None
    substeps: int = 1
    steering: Any = None


@dataclass
class DetectorContext:
    """What a failure detector sees at one control step.

    Arrays are indexed by vehicle. What a detector may use is what the vehicles
    broadcast (poses and commands) and what the world knows (contacts); ``pos``,
    ``theta``, ``vel`` and ``failing`` are the truth, for the ``oracle`` and for a
    detector's first call (the initial velocities).

    Attributes
    ----------
    t, dt : float [s]
        Time and control period.
    pos : ndarray (n, 2) [m]
    theta : ndarray (n,) [rad]
    vel : ndarray (n, 2) [m/s]
        The true states.
    seen : ndarray (n, 3) [m, m, rad]
        The broadcast poses received at ``t`` (``sensing:``), or the true poses
        without sensing.
    fresh : ndarray (n,) bool
        Whether each vehicle's packet of this period arrived (a lost one leaves
        ``seen`` at the last copy received).
    commands : ndarray (n, 2) [m/s, rad/s]
        The commands ``(v1, v2)`` each vehicle's controller asked for in the period
        ending at the pose in ``seen`` (before any failure acted on them; delayed
        with the poses).
    in_contact : ndarray (n,) bool
        Whether each vehicle is in an open contact episode.
    failing : ndarray (n,) bool
        The vehicles with an active failure (the truth: for the oracle only).
    position_noise, heading_noise : float [m], [rad]
        The broadcast noise of ``sensing:``.
    substeps : int
        Physics substeps per control period.
    motor_accel, turn_accel : ndarray (n,) [m/s^2], [rad/s^2]
        The motors' acceleration limits (inf: the command is reached within one
        substep).
    params : dict
        The detector's YAML values.
    memory : dict
        Kept from one step to the next.
    brake_accel : ndarray (n,) [m/s^2], optional
        The hardest a vehicle's drive brakes: the least of its ``max_accel`` and
        ``motor_accel`` (inf: neither declared; None: as ``motor_accel``).
    """

    t: float
    dt: float
    pos: np.ndarray
    theta: np.ndarray
    vel: np.ndarray
    seen: np.ndarray
    fresh: np.ndarray
    commands: np.ndarray
    in_contact: np.ndarray
    failing: np.ndarray
    position_noise: float
    heading_noise: float
    substeps: int
    motor_accel: np.ndarray
    turn_accel: np.ndarray
    params: dict[str, Any]
    memory: dict[str, Any]
    brake_accel: np.ndarray | None = None
