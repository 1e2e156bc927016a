"""The physics: a pymunk Space of vehicles and static obstacles, fixed-step.

The only module that imports pymunk. Each vehicle is a dynamic circle of diameter d
driven by the unicycle kinematics through velocity constraints (pymunk's
``examples/tank.py`` pattern): a kinematic *control body* carries the commanded
velocity, and a ``PivotJoint`` and a ``GearJoint`` with ``max_bias = 0`` and finite
``max_force`` make the vehicle follow it. Contacts therefore win over the motors:
vehicles really collide, stop at walls and can be shoved. Control bodies live in a
second, never-stepped Space so that the bulk reads and writes of ``pymunk.batch``
cover exactly the vehicles. The motors' force limits of each period are sized by
:func:`motor_limits`, in C where the compiled path ``motors`` is on
(:mod:`sandbox.accel`).

Collisions are counted as contact *episodes* (:class:`ContactEpisodes`): a pair's
``begin`` callback opens one, and it closes only once ``separate`` has fired and the
gap between the two surfaces has exceeded the release distance
(``metrics.contact_release``, default 1 cm). A pair pressed together, grinding, or
bouncing back within that gap stays one episode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pymunk
import pymunk.batch

from sandbox import accel
from sandbox.run.record import CollisionEvent
from sandbox.scenario import ObstacleSpec, VehicleSpec

VEHICLE = 1
OBSTACLE = 2
# : Contact overlap the solver tolerates [m] (pymunk's default, 0.1, is meant for
# pixels).
COLLISION_SLOP = 0.002
FRICTION = 0.3
#: Angular motor limit as a multiple of ``motor_accel / radius`` [rad/s^2].
ANGULAR_MOTOR_FACTOR = 4.0
#: Strength of the tracking motor (``motor_accel`` left out) in contact, and its least
#: strength when free [m/s^2]: how hard a vehicle pushes and resists a shove.
CONTACT_MOTOR_ACCEL = 200.0
#: Headroom of the tracking motor over the force a command needs (a free body then
#: reaches its commanded velocity within one substep).
MOTOR_HEADROOM = 1.05

_READ = (
    pymunk.batch.BodyFields.POSITION
    | pymunk.batch.BodyFields.ANGLE
    | pymunk.batch.BodyFields.VELOCITY
    | pymunk.batch.BodyFields.ANGULAR_VELOCITY
)
#: Default gap [m] the surfaces of a pair must exceed to end a contact episode
#: (``metrics.contact_release``).
CONTACT_RELEASE = 0.01

_WRITE = pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY


@dataclass
class PhysicalState:
    """Vehicle state read back from the physics, all arrays indexed by vehicle.

    Attributes
    ----------
    pos : ndarray, shape (n, 2) [m]
    theta : ndarray, shape (n,) [rad]   (unwrapped body angle, x3)
    vel : ndarray, shape (n, 2) [m/s]
    omega : ndarray, shape (n,) [rad/s]
    """

    pos: np.ndarray
    theta: np.ndarray
    vel: np.ndarray
    omega: np.ndarray


class _BodyIterator:
    """``pymunk.batch``'s bulk read or write of one space's bodies, set up once.

    ``pymunk.batch.get_space_bodies`` and ``set_space_bodies`` build their C call
    data anew at every call; here it is built once and the same C iterator is called
    (the same values, read or written, a few microseconds sooner per call). The read
    returns a view of the buffer's memory, made again only when Chipmunk moves it. If
    this pymunk lacks the internals used, the public functions are called instead.
    """

    def __init__(
        self,
        space: pymunk.Space,
        fields: pymunk.batch.BodyFields,
        buffer: pymunk.batch.Buffer,
        write: bool,
    ) -> None:
        self.space, self.fields, self.buffer = space, fields, buffer
        self._call = None
        self._view = np.zeros(0)
        self._ptr = None
        try:
            from pymunk._chipmunk import ffi, lib

            data = ffi.new("pmBatchedData *")
            data.fields = fields.value
            data.floatArray = buffer._float_arr
            data.intArray = buffer._int_arr
            name = "pmSpaceBody%sIteratorFuncBatched" % ("Set" if write else "Get")
            func = ffi.addressof(lib, name)
            each, handle = lib.cpSpaceEachBody, space._space
            self._data, self._floats, self._ints = data, buffer._float_arr, None
            self._ints = buffer._int_arr
            self._ffi = ffi
            self._call = lambda: each(handle, func, data)
        except (ImportError, AttributeError, TypeError):  # pragma: no cover
            self._call = None

    def read(self) -> np.ndarray:
        """Every body's fields, shape (bodies, 6) (a view, valid until the next)."""
        if self._call is None:  # pragma: no cover - the public path
            self.buffer.clear()
            pymunk.batch.get_space_bodies(self.space, self.fields, self.buffer)
            return np.frombuffer(self.buffer.float_buf(), np.float64).reshape(-1, 6)
        floats = self._floats
        floats.num = 0
        self._ints.num = 0
        self._call()
        if floats.arr != self._ptr or floats.num != self._view.size:
            raw = self._ffi.buffer(floats.arr, 8 * floats.num)
            self._view = np.frombuffer(raw, np.float64)
            self._ptr = floats.arr
        return self._view.reshape(-1, 6)

    def write(self) -> None:
        """Write the buffer's values to the bodies."""
        if self._call is None:  # pragma: no cover - the public path
            pymunk.batch.set_space_bodies(self.space, self.fields, self.buffer)
            return
        floats = self._floats
        num, floats.num = floats.num, 0
        self._call()
        floats.num = num


def _space_stepper(space: pymunk.Space) -> tuple[Any, tuple | None]:
    """``space.step`` without its Python bookkeeping, once that is not needed.

    ``Space.step`` checks newly added bodies (once), and around Chipmunk's
    ``cpSpaceStep`` handles additions and removals made by callbacks; the world's
    callbacks make none, so after the first step the C function is called directly
    (the same computation). Returns the step function and ``(cpSpaceStep, space
    handle, bodies still to check)`` for callers that loop over many worlds (None
    if this pymunk lacks those internals).
    """
    try:
        from pymunk._chipmunk import lib

        c_step, handle = lib.cpSpaceStep, space._space
        pending = space._bodies_to_check
    except (ImportError, AttributeError):  # pragma: no cover
        return space.step, None
    if space.threaded:  # pragma: no cover
        return space.step, None

    def step(dt: float) -> None:
        if pending:  # bodies added since the last step: pymunk checks them
            space.step(dt)
            return
        c_step(handle, dt)

    return step, (c_step, handle, pending)


try:  # ``Constraint.max_force``'s setter as the C function it calls
    from pymunk._chipmunk import lib as _lib

    #: Set a joint's force limit: ``MAX_FORCE_SETTER(handle, force)``, the handle
    #: from :meth:`World.joint_handles` (the call ``Constraint.max_force`` makes).
    MAX_FORCE_SETTER = _lib.cpConstraintSetMaxForce

    def _handle(joint: pymunk.Constraint) -> Any:
        return joint._constraint

except (ImportError, AttributeError):  # pragma: no cover - other pymunk builds

    def MAX_FORCE_SETTER(joint: pymunk.Constraint, force: float) -> None:  # noqa: N802
        """Set ``joint.max_force``."""
        joint.max_force = force

    def _handle(joint: pymunk.Constraint) -> Any:
        return joint


def motor_limits(
    command: np.ndarray,
    measured: np.ndarray,
    free: np.ndarray,
    substep: float,
    motors: World,
    out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tracking motors' force limits for a period (see :meth:`World._size_motors`).

    Elementwise over vehicles, so that it serves one world or many stacked ones.

    Parameters
    ----------
    command, measured : ndarray, shape (n, 3)
        Commanded and last read velocities ``(v_x1, v_x2, omega)`` [m/s, rad/s].
    free : ndarray, shape (n,), bool
        Vehicles in no open contact episode.
    substep : float [s]
    motors : World or any object with the arrays ``_mass``, ``_moment``,
        ``_least_force``, ``_least_torque``, ``_force``, ``_torque`` and
        ``_tracking``, shape (n,)
    out : tuple of ndarray, optional
        Float64 ``(n,)``, float64 ``(n,)`` and bool ``(n,)`` arrays the C loop may
        write the limits and the changed rows into (returned in their place: valid
        until the next call with them); default new ones.

    Returns
    -------
    rows : ndarray of int
        The vehicles whose joints must change.
    force, torque : ndarray, shape (n,) [N], [N m]
        Their new limits (read at ``rows``).
    """
    m = motors
    c = accel.module("motors")
    if c is not None:
        n = len(m._mass)
        if out is None:
            out = np.empty(n), np.empty(n), np.empty(n, bool)
        force, torque, change = out
        try:
            changed = c.motor_limits(
                command=command,
                measured=measured,
                free=free,
                substep=substep,
                headroom=MOTOR_HEADROOM,
                mass=m._mass,
                moment=m._moment,
                least_force=m._least_force,
                least_torque=m._least_torque,
                force=m._force,
                torque=m._torque,
                tracking=m._tracking,
                force_out=force,
                torque_out=torque,
                change=change,
            )
        except (BufferError, TypeError, ValueError):  # not float64 C arrays: numpy
            pass
        else:
            return (change.nonzero()[0] if changed else _NO_ROWS), force, torque
    return motor_limits_numpy(command, measured, free, substep, motors)


#: No rows (the motors of a period where no joint changes).
_NO_ROWS = np.zeros(0, dtype=np.intp)
_NO_ROWS.flags.writeable = False


def motor_limits_numpy(
    command: np.ndarray,
    measured: np.ndarray,
    free: np.ndarray,
    substep: float,
    motors: World,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`motor_limits` by numpy (the reference)."""
    delta = command - measured
    linear = np.where(free, np.hypot(delta[:, 0], delta[:, 1]), 0.0) / substep
    angular = np.where(free, np.abs(delta[:, 2]), 0.0) / substep
    m = motors
    force = np.maximum(m._least_force, MOTOR_HEADROOM * m._mass * linear)
    torque = np.maximum(m._least_torque, MOTOR_HEADROOM * m._moment * angular)
    grow = (force > m._force) | (torque > m._torque)
    shrink = (force < 0.5 * m._force) | (torque < 0.5 * m._torque)
    return np.flatnonzero(m._tracking & (grow | shrink)), force, torque


@dataclass
class _Open:
    """An open contact episode: its event and whether the pair touches right now."""

    event: CollisionEvent
    touching: bool = True


class World:
    """The pymunk world of one run.

    Parameters
    ----------
    vehicles : sequence of VehicleSpec
    obstacles : sequence of ObstacleSpec
    """

    def __init__(
        self,
        vehicles: tuple[VehicleSpec, ...],
        obstacles: tuple[ObstacleSpec, ...],
        contact_release: float = CONTACT_RELEASE,
        substeps: int = 4,
    ):
        self.space = pymunk.Space()
        self.space.collision_slop = COLLISION_SLOP
        self.space.sleep_time_threshold = float("inf")
        self.control_space = pymunk.Space()
        self.names = [v.name for v in vehicles]
        self.obstacle_names = [o.name for o in obstacles]
        #: The clock the ``begin`` callback reads (see :attr:`time`): ``[0]`` the start
        #: time of the substep being stepped [s], ``[1]`` raised (1.0) when the callback
        #: opens a contact episode. A batch's stepper shares one clock among its
        #: worlds and writes it from C (:mod:`sandbox.physics.stepping`).
        self._clock = np.zeros(2)
        self.contact_release = contact_release
        self._substeps = substeps
        self.events: list[CollisionEvent] = []
        #: Failure state of each vehicle in the current control period (set by the
        #: simulation loop): an episode that starts while one is set is not healthy.
        self.failed: np.ndarray | None = None
        #: Open episodes by pair: ``(kind, index a, index b) -> _Open``.
        self._open: dict[tuple[str, int, int], _Open] = {}
        self.obstacle_shapes: list[pymunk.Shape] = []
        self.radii: list[float] = []
        self.bodies: list[pymunk.Body] = []
        self.controls: list[pymunk.Body] = []
        self.joints: list[tuple[pymunk.PivotJoint, pymunk.GearJoint]] = []
        for i, v in enumerate(vehicles):
            self._add_vehicle(i, v)
        for k, o in enumerate(obstacles):
            self._add_obstacle(k, o)
        self.space.on_collision(
            VEHICLE, VEHICLE, begin=self._on_begin, separate=self._on_separate
        )
        self.space.on_collision(
            VEHICLE, OBSTACLE, begin=self._on_begin, separate=self._on_separate
        )
        self._read_buffer = pymunk.batch.Buffer()
        self._write_buffer = pymunk.batch.Buffer()
        self._rows = self._row_order(self.space, self.bodies)
        self._control_rows = self._row_order(self.control_space, self.controls)
        # Bodies are usually stored in insertion order: then no reordering is needed.
        # With obstacles the static body holds shapes and has a row of its own too.
        self._rows_in_order = not obstacles and np.array_equal(
            self._rows, np.arange(len(self.bodies))
        )
        self._control_in_order = np.array_equal(
            self._control_rows, np.arange(len(self.controls))
        )
        self._write = np.zeros((len(self.controls), 3))
        self._get = _BodyIterator(self.space, _READ, self._read_buffer, write=False)
        self._set = _BodyIterator(
            self.control_space, _WRITE, self._write_buffer, write=True
        )
        self.bind_commands(self._write)
        self._step_space, self.c_step = _space_stepper(self.space)
        n = len(self.bodies)
        # The motors: per vehicle, the joints' current force limits [N], [N m], and
        # the tracking motor's least ones; the velocities last read.
        self._mass = np.array([v.mass for v in vehicles], dtype=float)
        self._moment = np.array([b.moment for b in self.bodies], dtype=float)
        self._tracking = np.array([v.motor_accel is None for v in vehicles], bool)
        self._force = np.array([j[0].max_force for j in self.joints], dtype=float)
        self._torque = np.array([j[1].max_force for j in self.joints], dtype=float)
        self._least_force, self._least_torque = self._force.copy(), self._torque.copy()
        self._measured = np.zeros((n, 3))

    # ------------------------------------------------------------------ construction
    def _add_vehicle(self, index: int, v: VehicleSpec) -> None:
        radius = v.diameter / 2.0
        moment = pymunk.moment_for_circle(v.mass, 0.0, radius)
        body = pymunk.Body(v.mass, moment)
        body.position = (v.pose[0], v.pose[1])
        body.angle = v.pose[2]
        shape = pymunk.Circle(body, radius)
        shape.collision_type = VEHICLE
        shape.friction = FRICTION
        shape.elasticity = 0.0
        shape.sandbox_index = index
        control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        control.position = body.position
        control.angle = body.angle
        self.control_space.add(control)
        pivot = pymunk.PivotJoint(control, body, (0, 0), (0, 0))
        pivot.max_bias = 0.0
        accel = CONTACT_MOTOR_ACCEL if v.motor_accel is None else v.motor_accel
        pivot.max_force = v.mass * accel
        gear = pymunk.GearJoint(control, body, 0.0, 1.0)
        gear.max_bias = 0.0
        gear.max_force = moment * ANGULAR_MOTOR_FACTOR * accel / radius
        self.space.add(body, shape, pivot, gear)
        self.bodies.append(body)
        self.radii.append(radius)
        self.controls.append(control)
        self.joints.append((pivot, gear))

    def _add_obstacle(self, index: int, o: ObstacleSpec) -> None:
        body = self.space.static_body
        if o.type == "circle":
            shape = pymunk.Circle(body, o.radius, offset=o.center)
        elif o.type == "wall":
            shape = pymunk.Segment(body, o.start, o.end, o.thickness / 2.0)
        else:
            shape = pymunk.Poly(body, [tuple(p) for p in o.outline()])
        shape.collision_type = OBSTACLE
        shape.friction = FRICTION
        shape.elasticity = 0.0
        shape.sandbox_index = index
        self.space.add(shape)
        self.obstacle_shapes.append(shape)

    @staticmethod
    def _row_order(space: pymunk.Space, bodies: list[pymunk.Body]) -> np.ndarray:
        """Rows of the bulk buffer that hold each body, in the order of ``bodies``."""
        buf = pymunk.batch.Buffer()
        pymunk.batch.get_space_bodies(space, pymunk.batch.BodyFields.BODY_ID, buf)
        ids = list(memoryview(buf.int_buf()).cast("P"))
        where = {body_id: row for row, body_id in enumerate(ids)}
        return np.array([where[b.id] for b in bodies], dtype=np.intp)

    @property
    def time(self) -> float:
        """Start time of the substep being stepped [s]; stamped on collision events.

        Set before each substep by :meth:`step`, or by the stepper of a batch, which
        writes the clock its worlds share.
        """
        return float(self._clock[0])

    @time.setter
    def time(self, value: float) -> None:
        self._clock[0] = value

    # ------------------------------------------------------------------ collisions
    @staticmethod
    def _pair(arbiter: pymunk.Arbiter) -> tuple[str, int, int]:
        """``(kind, a, b)`` of an arbiter: vehicle indices, or vehicle and obstacle."""
        first, second = arbiter.shapes
        if first.collision_type == VEHICLE and second.collision_type == VEHICLE:
            a, b = sorted((first.sandbox_index, second.sandbox_index))
            return "vehicle_vehicle", a, b
        if first.collision_type != VEHICLE:
            first, second = second, first
        return "vehicle_obstacle", first.sandbox_index, second.sandbox_index

    def _on_begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        key = self._pair(arbiter)
        episode = self._open.get(key)
        if episode is not None:  # back in contact within the release gap
            episode.touching = True
            return
        kind, a, b = key
        vehicles = (a, b) if kind == "vehicle_vehicle" else (a,)
        healthy = self.failed is None or not any(bool(self.failed[i]) for i in vehicles)
        other = self.names[b] if kind == "vehicle_vehicle" else self.obstacle_names[b]
        event = CollisionEvent(self.time, self.names[a], other, kind, None, healthy)
        self.events.append(event)
        self._open[key] = _Open(event)
        self._clock[1] = 1.0

    def _on_separate(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        episode = self._open.get(self._pair(arbiter))
        if episode is not None:
            episode.touching = False

    def _gap(self, key: tuple[str, int, int]) -> float:
        """Distance between the two surfaces of a pair [m] (negative: overlap)."""
        kind, a, b = key
        pa = self.bodies[a].position
        if kind == "vehicle_vehicle":
            pb = self.bodies[b].position
            dist = math.hypot(pa.x - pb.x, pa.y - pb.y)
            return dist - self.radii[a] - self.radii[b]
        return self.obstacle_shapes[b].point_query(pa).distance - self.radii[a]

    def _update_episodes(self, t_end: float) -> None:
        """After a substep: deepest overlap of each open episode; close the released.

        An episode closes when its pair no longer touches (``separate`` fired) and
        the gap exceeds :attr:`contact_release`; ``end`` is the end of this substep.
        """
        released = []
        for key, episode in self._open.items():
            gap = self._gap(key)
            event = episode.event
            if -gap > event.penetration:
                event.penetration = -gap
            if not episode.touching and gap > self.contact_release:
                event.end = t_end
                released.append(key)
        for key in released:
            del self._open[key]

    def in_contact(self) -> np.ndarray:
        """Whether each vehicle is in an open contact episode, shape (n,) bool."""
        out = np.zeros(len(self.bodies), dtype=bool)
        for kind, a, b in self._open:
            out[a] = True
            if kind == "vehicle_vehicle":
                out[b] = True
        return out

    # ------------------------------------------------------------------ bulk I/O
    def read_rows(self, measure: bool = True) -> np.ndarray:
        """The bulk read of every body, rows in vehicle order, shape (n, 6).

        Columns ``x1, x2, x3, v_x1, v_x2, omega``; a view of the read buffer, valid
        until the next read. The velocities are kept for :meth:`_size_motors` unless
        ``measure`` is False (the caller keeps ``_measured`` itself).
        """
        rows = self._get.read()
        if not self._rows_in_order:
            rows = rows[self._rows]
        if measure:
            self._measured[:, :2] = rows[:, 3:5]
            self._measured[:, 2] = rows[:, 5]
        return rows

    def read_state(self) -> PhysicalState:
        """Read every vehicle's pose and velocity from the physics (one bulk call)."""
        rows = self.read_rows()
        return PhysicalState(
            pos=rows[:, 0:2].copy(),
            theta=rows[:, 2].copy(),
            vel=rows[:, 3:5].copy(),
            omega=rows[:, 5].copy(),
        )

    def write_commands(
        self, theta: np.ndarray, v1: np.ndarray, v2: np.ndarray, dt: float
    ):
        """Set the control bodies' velocities from unicycle commands (one bulk call).

        The velocity is directed along ``x3 + v2 dt / 2``, the mean heading over the
        period, so that a constant ``(v1, v2)`` traces the arc of eq. (1). The tracking
        motors are then sized for the period (:meth:`_size_motors`).
        """
        heading = theta + 0.5 * v2 * dt
        out = np.empty((len(self.controls), 3))
        out[:, 0] = v1 * np.cos(heading)
        out[:, 1] = v1 * np.sin(heading)
        out[:, 2] = v2
        if self._tracking.any():
            self._size_motors(out, dt)
        self.write_rows(out)

    def write_rows(self, velocity: np.ndarray | None = None) -> None:
        """Set the control bodies' velocities ``(v_x1, v_x2, omega)``, shape (n, 3).

        None: the rows already in the array given to :meth:`bind_commands`.
        """
        if velocity is not None:
            rows = slice(None) if self._control_in_order else self._control_rows
            self._write[rows] = velocity
        self._set.write()

    def bind_commands(self, array: np.ndarray) -> None:
        """Read the control bodies' velocities from ``array`` (n, 3) from now on.

        ``array`` is C-contiguous float64, rows in the control space's body order
        (vehicle order when ``_control_in_order``); it is used in place, not copied.
        """
        self._write = array
        self._write_buffer.set_float_buf(array)

    def _size_motors(self, command: np.ndarray, dt: float) -> None:
        """Force limits of the tracking motors for the period about to start.

        A free vehicle (in no open contact episode) gets the force that takes its body
        from the velocity just read to the commanded one within one substep (the
        first of the period), with :data:`MOTOR_HEADROOM`: eq. (1) then holds whatever
        the command. A vehicle in contact gets the contact motor
        (:data:`CONTACT_MOTOR_ACCEL`), so that contacts still win over a vehicle
        pushing into them. Joints are touched only where the limit must grow, or can
        shrink by half.
        """
        rows, force, torque = motor_limits(
            command,
            self._measured,
            ~self.in_contact(),
            dt / self._substeps,
            self,
        )
        for i in rows:
            pivot, gear = self.joints[i]
            pivot.max_force = self._force[i] = force[i]
            gear.max_force = self._torque[i] = torque[i]

    def step(self, dt: float, substeps: int, t0: float) -> None:
        """Advance the physics from ``t0`` by one period ``dt`` [s] in ``substeps``.

        Collision events are stamped with the start time of the substep they occur in;
        open contact episodes are updated after every substep.
        """
        h = dt / substeps
        self._substeps = substeps
        step = self._step_space
        for s in range(substeps):
            self.time = t0 + s * h
            step(h)
            if self._open:
                self._update_episodes(t0 + (s + 1) * h)

    def joint_handles(self) -> list[tuple[Any, Any]]:
        """Each vehicle's (pivot, gear) joints, as :data:`MAX_FORCE_SETTER` takes."""
        return [(_handle(pivot), _handle(gear)) for pivot, gear in self.joints]

    # ------------------------------------------------------------------ failures
    def immobilize(self, index: int) -> None:
        """Make a vehicle an immovable wreck (the ``crash`` failure).

        Its motors get unlimited force against a control body at rest, so contacts can
        no
        longer move it; it still collides (and counts) as a vehicle.
        """
        pivot, gear = self.joints[index]
        self._tracking[index] = False
        pivot.max_force = math.inf
        gear.max_force = math.inf
        self.controls[index].velocity = (0.0, 0.0)
        self.controls[index].angular_velocity = 0.0
        self.bodies[index].velocity = (0.0, 0.0)
        self.bodies[index].angular_velocity = 0.0
