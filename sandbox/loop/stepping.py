"""The physics of K worlds as the loop reaches it: read all, write all, step all.

:class:`LoopPhysics` holds one physics back-end per world. When every world is a
pymunk :class:`~sandbox.physics.world.World` the worlds are read, written and stepped
together: their motor arrays become views of stacked ones (sized at once by
:func:`~sandbox.physics.world.motor_limits`), their control bodies read their
velocities straight from one stacked command array, and from the second period on
:class:`~sandbox.physics.stepping.BatchStepper` calls Chipmunk for all of them with no
Python between worlds (one C call per period where its extension is built and no
contact episode is open). Any other back-end (``Simulation(scenario, world=...)``) is
reached through the :class:`~sandbox.physics.Physics` interface only. Both give the
numbers of each world stepped alone (``tests/test_batch.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sandbox import accel
from sandbox.physics.interface import Physics
from sandbox.physics.stepping import BatchStepper
from sandbox.physics.world import MAX_FORCE_SETTER, World, motor_limits

#: The motor arrays of a World that become views of stacked ones.
_MOTOR_ARRAYS = (
    "_measured",
    "_mass",
    "_moment",
    "_tracking",
    "_force",
    "_torque",
    "_least_force",
    "_least_torque",
)


class LoopPhysics:
    """K worlds of ``n`` vehicles each, stepped together (see the module docstring).

    Parameters
    ----------
    worlds : sequence of Physics
    n : int
        Vehicles per world.
    substeps : int
    """

    def __init__(self, worlds: Sequence[Physics], n: int, substeps: int) -> None:
        self.worlds = list(worlds)
        self.K = K = len(self.worlds)
        self.n, self.N, self.substeps = n, K * n, substeps
        self.live = list(range(K))
        self.pymunk = all(type(w) is World for w in self.worlds)
        #: Each world's failure flags, a view of one array (``World.failed``).
        self.failed = np.zeros(self.N, dtype=bool)
        for w, world in enumerate(self.worlds):
            world.failed = self.failed[w * n : (w + 1) * n]
        self._stepper: BatchStepper | None = None
        if not self.pymunk:
            return
        for name in _MOTOR_ARRAYS:
            stacked = np.concatenate([getattr(w, name) for w in self.worlds])
            setattr(self, name, stacked)
            for k, w in enumerate(self.worlds):
                setattr(w, name, stacked[k * n : (k + 1) * n])
        self._rows = np.empty((K, n, 6))
        for w, world in enumerate(self.worlds):
            self._rows[w] = world.read_rows(measure=False)
        # The control bodies read their velocities straight from the stacked commands.
        self._out = np.zeros((self.N, 3))
        self._bound = [w._control_in_order for w in self.worlds]
        for k, world in enumerate(self.worlds):
            if self._bound[k]:
                world.bind_commands(self._out[k * n : (k + 1) * n])
        self._episodes = [w._open for w in self.worlds]
        # Where the motors' limits of a period are written (read at once).
        self._limits = (np.empty(self.N), np.empty(self.N), np.empty(self.N, bool))
        # The contact flags of a period without any open episode, and their negation
        # (read-only: every period shares them).
        self._no_contact = np.zeros(self.N, dtype=bool)
        self._all_free = np.ones(self.N, dtype=bool)
        self._no_contact.flags.writeable = self._all_free.flags.writeable = False
        # The motors' joints as Chipmunk's handles, row by row (max_force's setter).
        self._set_max_force = MAX_FORCE_SETTER
        self._joint_handles = [h for w in self.worlds for h in w.joint_handles()]

    # ------------------------------------------------------------------ reading
    def read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions (N, 2), headings (N,), velocities (N, 2) at the present time.

        The rows of stopped worlds hold a harmless state (zeros), never used.
        """
        K, n = self.K, self.n
        if not self.pymunk:
            states = [w.read_state() for w in self.worlds]
            return (
                np.concatenate([s.pos for s in states]),
                np.concatenate([s.theta for s in states]),
                np.concatenate([s.vel for s in states]),
            )
        rows = self._rows
        period = accel.module("period")
        if len(self.live) == K and period is not None:  # the copies in one C call
            if period.ALLOCATES:  # the call makes the three arrays
                out = (None, None, None)
            else:
                N = self.N
                out = (np.empty((N, 2)), np.empty(N), np.empty((N, 2)))
            try:
                return period.read_state(rows, self._measured, *out)
            except (BufferError, TypeError, ValueError):  # not such arrays: numpy
                pass
        self._measured.reshape(K, n, 3)[...] = rows[..., 3:6]  # (v_x1, v_x2, omega)
        if len(self.live) < K:
            rows = rows.copy()
            dead = np.ones(K, dtype=bool)
            dead[self.live] = False
            rows[dead] = 0.0
        rows = rows.reshape(self.N, 6)
        return rows[:, 0:2].copy(), rows[:, 2].copy(), rows[:, 3:5].copy()

    def in_contact(self) -> np.ndarray | None:
        """Rows in an open contact episode (N,) bool; None if a world cannot say.

        Read-only where no episode is open (the same array every such period).
        """
        if not self.pymunk:
            parts = []
            for world in self.worlds:
                contact = getattr(world, "in_contact", None)
                if contact is None:
                    return None
                parts.append(contact())
            return np.concatenate(parts)
        if not any(self._episodes):  # no open contact episode in any world
            return self._no_contact  # read-only
        out = np.zeros(self.N, dtype=bool)
        n = self.n
        for w, world in enumerate(self.worlds):
            if world._open:
                out[w * n : (w + 1) * n] = world.in_contact()
        return out

    def free_of(self, contact: np.ndarray | None) -> np.ndarray | None:
        """The rows in no open contact episode: ``~contact`` (None for None).

        Read-only where ``contact`` is :meth:`in_contact`'s array of no episode.
        """
        if contact is None:
            return None
        if self.pymunk and contact is self._no_contact:
            return self._all_free
        return ~contact

    # ------------------------------------------------------------------ writing
    def advance(
        self,
        theta: np.ndarray,
        v1: np.ndarray,
        v2: np.ndarray,
        commanded: np.ndarray | None,
        free: np.ndarray | None,
        t0: float,
        h: float,
        first: bool,
    ) -> None:
        """Write the commands of the period from ``t0`` and step every live world.

        ``commanded``: the velocities ``(v_x1, v_x2)`` along the mean heading, if the
        loop metrics computed them already (the same numbers); ``free``: the rows in
        no contact episode now (for the motors). ``first``: the first period (every
        body is checked in after it; the stepper is built then).
        """
        n, substeps = self.n, self.substeps
        if not self.pymunk:
            for w in self.live:
                rows = slice(w * n, (w + 1) * n)
                world = self.worlds[w]
                world.write_commands(theta[rows], v1[rows], v2[rows], h)
                world.step(h, substeps, t0)
            return
        out = self._out
        if commanded is not None:
            try:  # the copies in one C call
                accel.module("period").command_rows(commanded, v2, out)
            except (AttributeError, BufferError, TypeError, ValueError):  # numpy's
                out[:, :2] = commanded
                out[:, 2] = v2
        else:
            heading = theta + 0.5 * v2 * h
            out[:, 0] = v1 * np.cos(heading)
            out[:, 1] = v1 * np.sin(heading)
            out[:, 2] = v2
        # (the rows of motors that do not track never change)
        rows, force, torque = motor_limits(
            out, self._measured, free, h / substeps, self, self._limits
        )
        if len(rows):
            self._force[rows], self._torque[rows] = force[rows], torque[rows]
            set_max, joints = self._set_max_force, self._joint_handles
            for r in rows.tolist():  # Constraint.max_force's own C call
                pivot, gear = joints[r]
                set_max(pivot, force[r])
                set_max(gear, torque[r])
        if self._stepper is not None:  # every world at once
            self._stepper.advance(t0, h)
            return
        # One pass over the worlds: write, step (World.step's loop, Chipmunk called
        # directly: the same calls and times), read the state of t_k+1.
        hh = h / substeps
        times = [t0 + s * hh for s in range(substeps)]
        ends = [t0 + (s + 1) * hh for s in range(substeps)]
        worlds, state = self.worlds, self._rows
        for w in self.live:
            world = worlds[w]
            world.write_rows(None if self._bound[w] else out[w * n : (w + 1) * n])
            fast = world.c_step
            if fast is None or fast[2]:
                world.step(h, substeps, t0)
            else:
                c_step, handle = fast[0], fast[1]
                world._substeps = substeps
                for s in range(substeps):
                    world.time = times[s]
                    c_step(handle, hh)
                    if world._open:
                        world._update_episodes(ends[s])
            state[w] = world.read_rows(measure=False)
        if first:  # every body is checked in now
            self._stepper = BatchStepper.build(self.worlds, out, state, substeps)
            if self._stepper is not None:
                self._stepper.live(self.live)

    def stop(self, w: int) -> None:
        """Stop stepping world ``w`` (it has ended)."""
        self.live = [k for k in self.live if k != w]
        if self._stepper is not None:
            self._stepper.live(self.live)

    def immobilize(self, w: int, i: int) -> None:
        """Make vehicle ``i`` of world ``w`` immovable (a crash)."""
        self.worlds[w].immobilize(i)
