"""The physics of a batch of worlds stepped with a few Python calls per substep.

:class:`~sandbox.loop.stepping.LoopPhysics` steps K independent pymunk worlds each
control period: write every world's commands to its control bodies, call Chipmunk's
``cpSpaceStep`` ``substeps`` times per world, update the open contact episodes, read
every world's bodies back. Done world by world in Python this costs about as much as
the physics itself (a dozen calls and attribute look-ups per world and period).
:class:`BatchStepper` makes the same C calls with the same arguments, in C-level loops
(``map`` over prepared handles), and lets Chipmunk's bulk iterators write and read the
batch's stacked arrays in place:

- the commands: each world's control space reads its rows of the batch's command array
  (``pymunk.batch``'s set iterator, one call per world);
- the state: each world's get iterator writes its bodies straight into its rows of one
  array of shape ``(K, bodies, 6)``: no per-world copy;
- the substeps: the clock the live worlds share (``World.time``, which a ``begin``
  callback stamps on the collision event) is set, then every live world is stepped;
  only worlds with open contact episodes (:meth:`World._update_episodes`) are visited
  in Python.

Where the compiled path ``stepping`` is on (:mod:`sandbox.accel`; ``_cstep.c``) and
no world has an open contact episode, a whole period is one C call: the commands
written, each substep's clock written and every live world stepped, the state read,
through the addresses of pymunk's own ``cpSpaceStep``, ``cpSpaceEachBody`` and
batched iterators (``ffi.addressof``; nothing is linked against Chipmunk), which the
extension's ``prepare`` takes by name once for the live worlds. The clock is a numpy
array of two doubles that the worlds' ``begin`` callbacks read and that the C loop
writes; a callback that opens a contact episode raises its second value, and the C
loop then returns after that substep, so that the episodes are updated and the
period finished by the Python path: the same calls, in the same order, with the
same arguments. Where the path is off, every period takes the Python path.

Worlds are independent (each its own Space; a callback touches only its own world), so
stepping substep by substep across the worlds, rather than world by world, computes
exactly the same numbers: results stay bit-identical to single runs. Where this
pymunk lacks the internals used, or the worlds differ in body layout,
:meth:`BatchStepper.build` returns None and the batch steps world by world.
"""

from __future__ import annotations

from collections import deque
from itertools import repeat
from typing import Any

import numpy as np

from sandbox import accel
from sandbox.physics.world import World

#: Fields of one body in the bulk read: x1, x2, x3, v_x1, v_x2, omega.
FIELDS = 6


def _exhaust(iterator: Any) -> None:
    """Run an iterator of C calls to its end, keeping nothing."""
    deque(iterator, maxlen=0)


class BatchStepper:
    """Writes, steps and reads K worlds of one batch (see the module docstring).

    Build it with :meth:`build`; call :meth:`advance` once per control period. The
    worlds stepped share one clock (``World._clock``) from then on.

    Parameters
    ----------
    worlds : list of World
        The batch's worlds, each stepped at least once (its bodies checked in).
    commands : ndarray, shape (K * n, 3)
        The batch's command array ``(v_x1, v_x2, omega)``, C-contiguous, rows in
        vehicle order world after world (each world's control bodies in that order).
    state : ndarray, shape (K, n, 6)
        Where each period's state is read to, rows in vehicle order.
    substeps : int
        Physics substeps per control period.
    internals : tuple
        What :meth:`build` found: pymunk's ``ffi`` and ``lib``, the bodies read per
        world, and their rows' order (None: vehicle order).
    """

    def __init__(
        self,
        worlds: list[World],
        commands: np.ndarray,
        state: np.ndarray,
        substeps: int,
        internals: tuple[Any, ...],
    ) -> None:
        ffi, lib, bodies, order = internals
        K, n = state.shape[:2]
        self._ffi = ffi
        self.worlds = worlds
        self._clock = np.zeros(2)
        self.substeps = substeps
        self._state = state
        # The rows the get iterator fills: the state itself when each world's bodies
        # come in vehicle order, else a buffer reordered into it after every read.
        self._order = order
        self._read = state if order is None else np.zeros((K, bodies, FIELDS))
        self._each = lib.cpSpaceEachBody
        self._c_step = lib.cpSpaceStep
        self._get = ffi.addressof(lib, "pmSpaceBodyGetIteratorFuncBatched")
        self._set = ffi.addressof(lib, "pmSpaceBodySetIteratorFuncBatched")
        fields_read = worlds[0]._get.fields.value
        fields_write = worlds[0]._set.fields.value
        # Our own pmFloatArray records (int num, int max, double *arr) over the
        # batch's arrays; their ``num`` fields, viewed by numpy, are reset at once.
        self._read_arrays = ffi.new("pmFloatArray[]", K)
        self._write_arrays = ffi.new("pmFloatArray[]", K)
        self._read_data = ffi.new("pmBatchedData[]", K)
        self._write_data = ffi.new("pmBatchedData[]", K)
        per_read, per_write = bodies * FIELDS, n * 3
        for w, world in enumerate(worlds):
            rd = self._read_arrays[w]
            rd.arr = ffi.cast("double *", self._read[w].ctypes.data)
            # One more than the values read: pymunk grows an array (realloc) only
            # when a push would reach ``max - 1``, never here (the bodies are fixed).
            rd.max, rd.num = per_read + 1, 0
            wr = self._write_arrays[w]
            wr.arr = ffi.cast("double *", commands[w * n : (w + 1) * n].ctypes.data)
            wr.max, wr.num = per_write, 0
            for data, array, fields, buf in (
                (self._read_data[w], self._read_arrays + w, fields_read, "_read"),
                (self._write_data[w], self._write_arrays + w, fields_write, "_write"),
            ):
                data.fields = fields
                data.floatArray = array
                data.intArray = getattr(world, buf + "_buffer")._int_arr
        self._read_num = np.frombuffer(ffi.buffer(self._read_arrays), np.int32)[::4]
        self._write_num = np.frombuffer(ffi.buffer(self._write_arrays), np.int32)[::4]
        self._keep = (commands, self._read)  # the memory the records point into
        #: The compiled path's module and its prepared batch (None: Python path).
        self._cstep = accel.module("stepping")
        self._batch: Any = None
        if self._cstep is not None:
            address = self._address
            self._functions = {
                key: address(ffi.addressof(lib, name))
                for key, name in (
                    ("step", "cpSpaceStep"),
                    ("each", "cpSpaceEachBody"),
                    ("set", "pmSpaceBodySetIteratorFuncBatched"),
                    ("get", "pmSpaceBodyGetIteratorFuncBatched"),
                )
            }
        self.live(list(range(K)))

    def _address(self, pointer: Any) -> int:
        """The address a cffi pointer holds, as an int."""
        return int(self._ffi.cast("uintptr_t", pointer))

    @classmethod
    def build(
        cls,
        worlds: list[World],
        commands: np.ndarray,
        state: np.ndarray,
        substeps: int,
    ) -> BatchStepper | None:
        """The stepper of these worlds, or None where the fast path cannot be used.

        None when this pymunk lacks the C functions and records used, when a world
        has bodies still to be checked in by ``Space.step`` or control bodies out of
        vehicle order, or when the worlds differ in how their bodies are read.
        """
        try:
            from pymunk._chipmunk import ffi, lib

            for name in ("cpSpaceEachBody", "cpSpaceStep"):
                getattr(lib, name)
            for name in ("Get", "Set"):
                ffi.addressof(lib, f"pmSpaceBody{name}IteratorFuncBatched")
            if (
                ffi.sizeof("pmFloatArray") != 16
                or ffi.offsetof("pmFloatArray", "num") != 0
                or ffi.offsetof("pmFloatArray", "arr") != 8
            ):
                return None
        except (ImportError, AttributeError, TypeError):  # pragma: no cover
            return None
        n = state.shape[1]
        first = worlds[0]
        if not commands.flags.c_contiguous or not state.flags.c_contiguous:
            return None
        for world in worlds:
            if world.c_step is None or world.c_step[2] or world.space.threaded:
                return None
            if not world._control_in_order or len(world.controls) != n:
                return None
            if not np.array_equal(world._rows, first._rows):
                return None
            if world._get._call is None or world._set._call is None:
                return None
        bodies = len(first._get.read())
        if any(len(world._get.read()) != bodies for world in worlds):
            return None
        in_order = bodies == n and np.array_equal(first._rows, np.arange(n))
        order = None if in_order else np.asarray(first._rows, dtype=np.intp)
        return cls(worlds, commands, state, substeps, (ffi, lib, bodies, order))

    def live(self, worlds: list[int]) -> None:
        """Step only these worlds from now on (the others have stopped)."""
        ws = self.worlds
        for world in ws:  # a stopped world keeps its own clock
            if world._clock is self._clock:
                world._clock = self._clock.copy()
        self._live = [ws[w] for w in worlds]
        self._spaces = [ws[w].space._space for w in worlds]
        self._controls = [ws[w].control_space._space for w in worlds]
        self._reads = [self._read_data + w for w in worlds]
        self._writes = [self._write_data + w for w in worlds]
        self._opens = [ws[w]._open for w in worlds]
        for world in self._live:
            world._substeps = self.substeps
            world._clock = self._clock
        if self._cstep is not None:
            # The C loop's arrays of addresses, in the order of the Python path's.
            lists = (self._spaces, self._controls, self._writes, self._reads)
            self._pointers = [
                np.array([self._address(p) for p in pointers], dtype=np.uintp)
                for pointers in lists
            ]
            spaces, controls, writes, reads = (
                int(a.ctypes.data) for a in self._pointers
            )
            ffi = self._ffi
            # the clock, and the pmFloatArray records whose num the call resets
            self._batch = self._cstep.prepare(
                **self._functions,
                spaces=spaces,
                controls=controls,
                writes=writes,
                reads=reads,
                count=len(worlds),
                substeps=self.substeps,
                clock=int(self._clock.ctypes.data),
                write_arrays=self._address(self._write_arrays),
                read_arrays=self._address(self._read_arrays),
                arrays=len(ws),
                size=ffi.sizeof("pmFloatArray"),
                num_at=ffi.offsetof("pmFloatArray", "num"),
            )

    def advance(self, t0: float, h: float) -> None:
        """One control period ``h`` [s] of every live world from ``t0`` [s].

        Writes the commands, steps :attr:`substeps` times (the clock and the open
        contact episodes as :meth:`World.step` keeps them), reads the state: in one
        C call while no world has an open contact episode, else in Python.
        """
        each, c_step, spaces = self._each, self._c_step, self._spaces
        substeps = self.substeps
        step = h / substeps
        opens, clock = self._opens, self._clock
        first = 0
        if self._batch is not None and not any(opens):
            # the counters and clock[1] reset by the call itself
            first = self._cstep.advance(self._batch, t0, step)
            if not clock[1]:  # every substep stepped, the state read
                if self._order is not None:
                    self._state[:] = self._read[:, self._order]
                return
            # A contact episode opened in substep first - 1: its end as below.
            self._update_episodes(t0 + first * step)
        else:
            self._write_num[:] = 0
            _exhaust(map(each, self._controls, repeat(self._set), self._writes))
        for s in range(first, substeps):
            clock[0] = t0 + s * step
            _exhaust(map(c_step, spaces, repeat(step)))
            if any(opens):
                self._update_episodes(t0 + (s + 1) * step)
        self._read_num[:] = 0
        _exhaust(map(each, spaces, repeat(self._get), self._reads))
        if self._order is not None:
            self._state[:] = self._read[:, self._order]

    def _update_episodes(self, end: float) -> None:
        """After a substep ending at ``end`` [s]: each world's open episodes."""
        for world, episodes in zip(self._live, self._opens, strict=True):
            if episodes:
                world._update_episodes(end)
