"""The range sensor (``sensors.range``): what each vehicle's LiDAR reads, every scan.

Each sensing vehicle has ``beams`` beams from its centre over its field of view ``fov``
about the heading, ordered from ``-fov/2`` (right) to ``+fov/2`` (left): ``fov /
(beams - 1)`` apart with a beam on each edge, or ``2 pi / beams`` apart from ``-pi``
for a full turn (one beam: straight ahead). A beam reads the distance [m] from the
centre to the first surface it meets (a static obstacle, a wall, another vehicle),
``max_range`` where it meets none; the casting is :mod:`sandbox.physics.ranges`.

``noise`` adds white Gaussian noise of that standard deviation to every beam that hits
something (a miss reads ``max_range``), the reading clipped to ``[0, max_range]``. The
draws come from a generator of their own, ``numpy.random.default_rng([seed,
crc32("ranges")])``: adding a sensor changes no other draw of a scenario.

``memory`` [s] keeps, for recovery from sensed obstacles, an obstacle a vehicle no
longer sees (hidden behind another, or between two beams) at the point it was last
seen, for that long after its last hit (0: the current scan only).

``rate`` [Hz] sets a scan every ``1 / rate`` s: the scan of ``t_k`` is taken at the
first control period at or after each multiple of ``1 / rate`` and held until the
next (without ``rate``, every period).

With ``recovery.obstacles: sensed`` the recovery strategy and the safety filter see
the static obstacles as each vehicle's hits (:class:`~sandbox.model.sensed_field.
SensedField`): for each obstacle the vehicle's beams touched, the nearest point of the
outline its hits draw (:func:`~sandbox.model.sensed_field.nearest_surface_points`), in
world coordinates (held with the scan). Beams that hit vehicles are left out there:
the other vehicles reach the strategy as before (true or broadcast positions).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from sandbox.model.obstacle_field import ObstacleField
from sandbox.model.sensed_field import SensedField, nearest_surface_points
from sandbox.physics.ranges import HIT_OBSTACLE, RangeCaster

#: The stream of the range noise, mixed with the scenario's seed.
RANGES_STREAM = zlib.crc32(b"ranges")


def beam_layout(beams: int, fov: float) -> tuple[float, float]:
    """The first beam's angle about the heading and the spacing [rad].

    Examples
    --------
    >>> beam_layout(4, 2 * math.pi)  # a full turn: -pi, -pi/2, 0, pi/2
    (-3.141592653589793, 1.5707963267948966)
    >>> beam_layout(3, 1.0)  # -0.5 (right), 0, 0.5 (left)
    (-0.5, 0.5)
    >>> beam_layout(1, 1.0)
    (0.0, 0.0)
    """
    if beams == 1:
        return 0.0, 0.0
    if fov >= 2.0 * math.pi - 1e-12:
        return -math.pi, 2.0 * math.pi / beams
    return -0.5 * fov, fov / (beams - 1)


@dataclass(frozen=True)
class NearObstacles:
    """The obstacles within a radius of each vehicle, from the map: one row per pair.

    Attributes
    ----------
    vehicle : ndarray (m,) int
        The vehicle's row.
    obstacle : ndarray (m,) int
        The obstacle's index in the scenario's ``obstacles``.
    name : tuple of str (m,)
        Its name.
    kind : tuple of str (m,)
        Its type: ``circle``, ``wall``, ``box`` or ``polygon``.
    point : ndarray (m, 2) [m]
        The nearest point of its surface to the vehicle's centre.
    distance : ndarray (m,) [m]
        From the centre to that point (negative inside the obstacle).
    """

    vehicle: np.ndarray
    obstacle: np.ndarray
    name: tuple[str, ...]
    kind: tuple[str, ...]
    point: np.ndarray
    distance: np.ndarray

    def of(self, row: int) -> NearObstacles:
        """The rows of one vehicle."""
        sel = np.flatnonzero(self.vehicle == row)
        return NearObstacles(
            self.vehicle[sel],
            self.obstacle[sel],
            tuple(self.name[k] for k in sel),
            tuple(self.kind[k] for k in sel),
            self.point[sel],
            self.distance[sel],
        )


def near_obstacles(
    field: ObstacleField, specs: Any, pos: np.ndarray, radius: np.ndarray
) -> NearObstacles:
    """The obstacles whose surface is within ``radius[i]`` of vehicle ``i``'s centre.

    Parameters
    ----------
    field : ObstacleField
    specs : sequence of ObstacleSpec
        The scenario's obstacles (names and types).
    pos : ndarray (n, 2) [m]
    radius : ndarray (n,) [m]
    """
    if field.empty or not len(pos):
        none = np.zeros(0, dtype=np.intp)
        return NearObstacles(none, none, (), (), np.zeros((0, 2)), np.zeros(0))
    rows, cols = field.candidates(pos, float(np.max(radius)))
    signed, point = field.pair_distance(pos, rows, cols)
    keep = np.flatnonzero(signed <= radius[rows])
    rows, cols = rows[keep], cols[keep]
    index = field.order[cols]
    return NearObstacles(
        rows,
        index,
        tuple(specs[k].name for k in index.tolist()),
        tuple(specs[k].type for k in index.tolist()),
        point[keep],
        signed[keep],
    )


class RangeSensor:
    """The range sensors of one world's fleet, scanned by the loop every period.

    One world's: its beams are cast in that world's Space, its noise drawn from that
    world's own stream (:class:`RangeReadings` holds those of a loop's K worlds).

    Parameters
    ----------
    specs : sequence of RangeSpec or None
        Each vehicle's sensor (None: it has none; :meth:`Scenario.range_specs`).
    world : World
        The pymunk world the beams are cast in.
    field : ObstacleField
        The scenario's obstacles as geometry.
    seed : int
        The scenario's seed (the noise stream is its own).
    method : str
        The casting method of :class:`~sandbox.physics.ranges.RangeCaster`.

    Attributes
    ----------
    ranges : ndarray (n, B) [m]
        The last scan's readings, NaN for vehicles (or beams) without a sensor.
    beam_angles : ndarray (n, B) [rad]
        Each beam's angle about the heading (NaN likewise).
    points : ndarray (n, B, 2) [m]
        The hit points in world coordinates (NaN where nothing was hit).
    field : SensedField
        The nearest hit of each obstacle each vehicle sees.
    """

    def __init__(
        self,
        specs: Any,
        world: Any,
        field: ObstacleField,
        seed: int,
        method: str = "prefilter",
    ) -> None:
        rows = [i for i, s in enumerate(specs) if s is not None]
        self.rows = np.array(rows, dtype=np.intp)
        chosen = [specs[i] for i in rows]
        n = len(specs)
        self.count = np.array([s.beams for s in chosen], dtype=np.intp)
        layout = [beam_layout(s.beams, s.fov) for s in chosen]
        self.first = np.array([a for a, _ in layout], dtype=float)
        self.step = np.array([b for _, b in layout], dtype=float)
        self.max_range = np.array([s.max_range for s in chosen], dtype=float)
        self.noise = np.array([s.noise for s in chosen], dtype=float)
        self.rate = np.array([s.rate or np.inf for s in chosen], dtype=float)
        width = int(self.count.max()) if rows else 0
        k = np.arange(width)
        angles = np.full((n, width), np.nan)
        angles[self.rows] = np.where(
            k[None] < self.count[:, None],
            self.first[:, None] + k[None] * self.step[:, None],
            np.nan,
        )
        self.beam_angles = angles
        self.ranges = np.full((n, width), np.nan)
        self.points = np.full((n, width, 2), np.nan)
        self._kind = np.zeros((n, width), dtype=np.int8)
        self._index = np.full((n, width), -1, dtype=np.intp)
        self._last = np.full(len(rows), -np.inf)  # the last scan's number
        # Per vehicle: where its last scan was taken, its beams, whether they close
        # a full turn (for the outline of the sensed surfaces).
        self._origin = np.full((n, 2), np.nan)
        self._count = np.zeros(n, dtype=np.intp)
        self._count[self.rows] = self.count
        self._wrap = np.zeros(n, dtype=bool)
        # How long each vehicle keeps an obstacle it no longer sees [s], and the
        # points kept: (owner, obstacle, point, time last seen).
        self._hold = np.zeros(n)
        self._hold[self.rows] = [s.memory for s in chosen]
        self._remember = bool(np.any(self._hold > 0))
        none = np.zeros(0, dtype=np.intp)
        self._memory = (none, none, np.zeros((0, 2)), np.zeros(0))
        self._wrap[self.rows] = [
            s.beams > 1 and s.fov >= 2.0 * math.pi - 1e-12 for s in chosen
        ]
        self.caster = RangeCaster(world, field, method)
        self.rng = np.random.default_rng([seed, RANGES_STREAM])
        self.field = SensedField()
        # The shape code (ObstacleField.kind) of each obstacle, by scenario index.
        self._obstacle_kind = np.zeros(len(field.order), dtype=np.intp)
        self._obstacle_kind[field.order] = field.kind
        self.scans = 0
        self._recorded: list[np.ndarray] = []

    @classmethod
    def make(
        cls, scenario: Any, world: Any, field: ObstacleField
    ) -> RangeSensor | None:
        """The scenario's sensors, or None when no vehicle has one."""
        specs = scenario.range_specs()
        if all(s is None for s in specs):
            return None
        return cls(specs, world, field, scenario.seed)

    def update(self, t: float, pos: np.ndarray, theta: np.ndarray) -> None:
        """Scan the vehicles whose scan is due at ``t`` [s]; hold the others' last."""
        finite = np.isfinite(self.rate)
        number = np.floor(t * np.where(finite, self.rate, 0.0) + 1e-9)
        due = np.flatnonzero(~finite | (number > self._last))
        if not len(due):
            return
        self._last[due] = number[due]
        rows = self.rows[due]
        scan = self.caster.cast(
            pos,
            theta,
            rows,
            self.first[due],
            self.step[due],
            self.count[due],
            self.max_range[due],
        )
        dist, kind = scan.dist[rows], scan.kind[rows]
        hit = kind != 0
        noise = self.noise[due]
        if np.any(noise > 0):
            draw = self.rng.standard_normal(dist.shape)
            noisy = dist + noise[:, None] * draw
            cap = self.max_range[due][:, None]
            dist = np.where(hit, np.clip(noisy, 0.0, cap), dist)
        width = dist.shape[1]
        self.ranges[rows, :width] = dist
        self._kind[rows, :width] = kind
        self._index[rows, :width] = scan.index[rows]
        angle = theta[rows, None] + self.beam_angles[rows, :width]
        ray = np.stack((np.cos(angle), np.sin(angle)), -1)
        points = pos[rows, None, :] + dist[..., None] * ray
        self.points[rows, :width] = np.where(hit[..., None], points, np.nan)
        self._origin[rows] = pos[rows]
        self.scans += 1
        self._sense_obstacles(t)

    def _sense_obstacles(self, t: float) -> None:
        """Rebuild :attr:`field` from every vehicle's current scan (and memory).

        An obstacle a vehicle saw within its ``memory`` [s] but not in its current
        scan (hidden behind another, between two beams) keeps the point last seen.
        """
        obstacle = np.where(self._kind == HIT_OBSTACLE, self._index, -1)
        owner, obstacle, point = nearest_surface_points(
            self._origin, self.points, obstacle, self._count, self._wrap
        )
        seen = np.full(len(owner), t)
        if self._remember:
            wide = len(self._obstacle_kind) + 1
            key = owner * wide + obstacle
            old = self._memory
            old_key = old[0] * wide + old[1]
            keep = ~np.isin(old_key, key) & (t - old[3] <= self._hold[old[0]] + 1e-9)
            owner = np.concatenate((owner, old[0][keep]))
            obstacle = np.concatenate((obstacle, old[1][keep]))
            point = np.concatenate((point, old[2][keep]))
            seen = np.concatenate((seen, old[3][keep]))
            order = np.lexsort((obstacle, owner))
            owner, obstacle, point, seen = (
                x[order] for x in (owner, obstacle, point, seen)
            )
            self._memory = (owner, obstacle, point, seen)
        self.field.set(owner, point, obstacle, self._obstacle_kind[obstacle])

    # ------------------------------------------------------------------ views
    def radius(self, n: int, default: float) -> np.ndarray:
        """Each vehicle's ``max_range`` [m], ``default`` for those without a sensor."""
        out = np.full(n, float(default))
        out[self.rows] = self.max_range
        return out

    def record(self) -> None:
        """Keep the current readings as a sample of the record (float32)."""
        self._recorded.append(self.ranges.astype(np.float32))

    def arrays(self) -> dict[str, np.ndarray]:
        """The recorded readings ``ranges`` (T, n, B) and the ``beam_angles``."""
        n, width = self.ranges.shape
        ranges = (
            np.stack(self._recorded)
            if self._recorded
            else np.zeros((0, n, width), dtype=np.float32)
        )
        return {"ranges": ranges, "beam_angles": self.beam_angles.copy()}


class RangeReadings:
    """The range sensors of K worlds of ``n`` vehicles, read as the loop's rows.

    Each world's :class:`RangeSensor` casts in its own world, with its own noise
    stream, as alone (a world's Space and random stream are its own); the readings,
    the beam angles and the sensed points are its rows of the loop's arrays
    (:attr:`ranges`, :attr:`beam_angles`, :attr:`field`, the points' owners offset
    by ``w n``), so that a strategy or filter called once for all worlds sees each
    world's obstacles only through its own vehicles.

    Parameters
    ----------
    sensors : list of RangeSensor
        Each world's sensors, in world order.
    n : int
        Vehicles per world.
    """

    def __init__(self, sensors: list[RangeSensor], n: int) -> None:
        self.parts, self.n = sensors, n
        self.beam_angles = np.concatenate([s.beam_angles for s in sensors])
        self.ranges = np.concatenate([s.ranges for s in sensors])
        self.field = SensedField()

    @classmethod
    def make(
        cls, scenarios: list[Any], worlds: list[Any], field: ObstacleField, n: int
    ) -> RangeReadings | None:
        """The sensors of every world (:meth:`RangeSensor.make`), or None without."""
        sensors = [
            RangeSensor.make(sc, w, field)
            for sc, w in zip(scenarios, worlds, strict=True)
        ]
        if sensors[0] is None:
            return None
        return cls(sensors, n)

    def update(self, t: float, pos: np.ndarray, theta: np.ndarray) -> None:
        """Every world's scans due at ``t`` [s] (:meth:`RangeSensor.update`)."""
        n, owners, points, orders, kinds = self.n, [], [], [], []
        for w, sensor in enumerate(self.parts):
            rows = slice(w * n, (w + 1) * n)
            sensor.update(t, pos[rows], theta[rows])
            f = sensor.field
            owners.append(f.owner + w * n)
            points.append(f.point)
            orders.append(f.order)
            kinds.append(f.kind)
        self.ranges = np.concatenate([s.ranges for s in self.parts])
        self.field.set(
            np.concatenate(owners),
            np.concatenate(points),
            np.concatenate(orders),
            np.concatenate(kinds),
        )

    def record(self) -> None:
        """Every world keeps its readings as a sample of its record."""
        for sensor in self.parts:
            sensor.record()

    def part(self, w: int) -> RangeSensor:
        """World ``w``'s own sensors."""
        return self.parts[w]


def avoid_field(
    sensor: RangeSensor | RangeReadings | None, field: ObstacleField, recovery: Any
) -> ObstacleField | SensedField:
    """The obstacles recovery and the safety filter avoid (``recovery.obstacles``).

    The map's ``field``, or with ``sensed`` the sensor's points (updated in place at
    every scan).
    """
    if recovery.obstacles == "sensed" and sensor is not None:
        return sensor.field
    return field


def context_fields(
    sensor: RangeSensor | RangeReadings | None,
) -> dict[str, np.ndarray]:
    """The ``ranges`` and ``beam_angles`` of a plug-in context (none: no sensor)."""
    if sensor is None:
        return {}
    return {"ranges": sensor.ranges, "beam_angles": sensor.beam_angles}


def observation_fields(
    sensor: RangeSensor | None, field: ObstacleField, scenario: Any, pos: np.ndarray
) -> dict[str, Any]:
    """What an :class:`~sandbox.loop.observation.Observation` shows of obstacles.

    The readings and beam angles (copies; none without a sensor), and what
    ``Observation.obstacles`` is computed from when read: the obstacles within each
    vehicle's ``max_range`` (``recovery.R`` for a vehicle without a sensor).
    """
    out: dict[str, Any] = {}
    if sensor is not None:
        out = {"ranges": sensor.ranges.copy(), "beam_angles": sensor.beam_angles.copy()}
        radius = sensor.radius(len(pos), scenario.recovery.R)
    else:
        radius = np.full(len(pos), scenario.recovery.R)
    out["near"] = (field, scenario.obstacles, pos.copy(), radius)
    return out
