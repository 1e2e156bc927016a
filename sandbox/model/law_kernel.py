"""A built-in formation law's targets of one period, eqs. (7)-(20), in one C call.

A built-in law class (:mod:`sandbox.model.laws`) computes a period's slots, ``x_ref'``
and ``x_ref''`` in about ten numpy calls (the rotating law with its leader's backward
differences, about fifteen), and the loop then gives the rows that track the
reference the reference's own point and derivatives and the commanded rows a NaN
slot (:func:`overwrite_rows`): for a small fleet the fixed cost of those calls (half
a microsecond each) is most of the period's law. Where the compiled path ``laws`` is
on (:mod:`sandbox.accel`; ``_laws.c``), :class:`LawKernel` does the same for K worlds
in one C call: the law's numbers row by row, the backward differences of eqs.
(8)-(9) and (18)-(19) advanced in place in the law's own estimator, and the tangent
angle of eq. (15) returned to the law, so the law object holds the state the numpy
path leaves in it. The law classes stay the reference; the two agree within rtol
1e-12 (``tests/test_compiled_paths.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox import accel
from sandbox.model.laws import (
    BackwardDifference,
    FixedFormation,
    LeaderReferenceFormation,
    OwnEstimateFormation,
    RotatingFormation,
    VirtualLeaderFormation,
)

#: The law classes the C loop computes, by the number it knows them by.
KINDS: dict[type, int] = {
    FixedFormation: 0,
    RotatingFormation: 1,
    VirtualLeaderFormation: 2,
    LeaderReferenceFormation: 3,
    OwnEstimateFormation: 4,
}
#: The estimator of each law class with one (eqs. (8)-(9) or (18)-(19)).
_MOTION = {0: "leader_motion", 1: "leader_motion", 4: "slot_motion"}


def overwrite_rows(
    triple: list[np.ndarray],
    ref: tuple | None,
    track: np.ndarray,
    commanded: np.ndarray,
) -> list[np.ndarray]:
    """The loop's targets from the law's: reference-tracking and commanded rows.

    The rows ``track`` (indices) take the reference's point and derivatives ``ref``
    (when there is one), the rows ``commanded`` (open loop) a NaN slot; on copies
    of the law's arrays, which it may keep. Without such rows the law's arrays
    themselves are returned (float64 (N, 2) rows, read-only downstream).
    """
    if (ref is not None and len(track)) or len(commanded):
        slot = np.array(triple[0], dtype=float)
        v_ref = np.array(triple[1], dtype=float)
        a_ref = np.array(triple[2], dtype=float)
        if ref is not None:
            slot[track], v_ref[track], a_ref[track] = ref[0], ref[1], ref[2]
        slot[commanded] = np.nan
        return [slot, v_ref, a_ref]
    return triple


class LawKernel:
    """A built-in law of K worlds, its period's targets in one C call.

    Parameters
    ----------
    law : FormationLaw
        A law of exactly one of the classes of :data:`KINDS`, with offsets of shape
        (K, n, 2), whose estimator is a :class:`~sandbox.model.laws.
        BackwardDifference` of all worlds (one history).
    leader : int
        The leader's row in each world (negative: none, for ``virtual`` only).
    """

    def __init__(self, law: Any, leader: int, c: Any) -> None:
        self.law = law
        self._c = c
        self.kind = KINDS[type(law)]
        self.leader = max(int(leader), 0)
        self.turns = bool(law.rotate) and self.kind in (2, 3)
        self._motion = getattr(law, _MOTION.get(self.kind, ""), None)
        K, n = law.delta.shape[:2]
        self.n = n
        self._shape = (K, 1, 2) if self.kind in (0, 1) else (K, n, 2)
        self._prev: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def make(cls, law: Any, leader: int) -> LawKernel | None:
        """The kernel of ``law``; None where the path is off or does not cover it."""
        c = accel.module("laws")
        if c is None or not covers(law, leader):
            return None
        return cls(law, leader, c)

    def targets(
        self,
        pose: np.ndarray,
        theta: np.ndarray | None,
        table: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
        row: int,
        track: np.ndarray,
        commanded: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Slots, ``x_ref'``, ``x_ref''`` of every row, (K n, 2) each, new arrays.

        The numbers of ``law.targets`` followed by :func:`overwrite_rows` (whose
        ``ref`` is the reference's row ``row`` of ``table``), the law's state
        advanced as its own call advances it.

        Parameters
        ----------
        pose : ndarray, shape (K n, 2) or (K n, 3)
            The positions the law reads the leader's from [m]; (K n, 3): with the
            heading [rad] as third column (the believed poses).
        theta : ndarray, shape (K n,), or None
            The headings [rad] beside positions of shape (K n, 2).
        table : tuple of 3 ndarrays of shape (T, 2), or None
            The reference's points and derivatives (None: no reference).
        row : int
            The row of ``table`` of this period.
        track, commanded : ndarray of intp
            The rows that track the reference, the rows without a slot.

        Raises
        ------
        TypeError, ValueError, BufferError
            An array that is not what the C loop reads (nothing is changed then).
        """
        law = self.law
        motion = self._motion
        if motion is None:
            count, prev_x, prev_v = 0, None, None
        else:
            count = motion.count
            if self._prev is None or motion.prev_x is not self._prev[0]:
                self._adopt(motion)
            prev_x, prev_v = self._prev
        p, dp, ddp = (None, None, None) if table is None else table
        c = self._c
        # None: the call makes its own outputs (a build with numpy's C API)
        out = (None, None, None) if c.ALLOCATES else _outputs(len(pose))
        slot, v_ref, a_ref, tangent = c.law_targets(
            kind=self.kind,
            delta=law.delta,
            n=self.n,
            pose=pose,
            theta=theta,
            leader=self.leader,
            ref_p=p,
            ref_dp=dp,
            ref_ddp=ddp,
            row=row,
            rotate=self.turns,
            tangent=law._tangent,
            h=law.h,
            count=count,
            prev_x=prev_x,
            prev_v=prev_v,
            track=track,
            commanded=commanded,
            slot=out[0],
            v_ref=out[1],
            a_ref=out[2],
        )
        if motion is not None:
            motion.count = count + 1
        if self.turns:
            law._tangent = tangent
        return slot, v_ref, a_ref

    def _adopt(self, motion: BackwardDifference) -> None:
        """Give the estimator a history of its values that the C loop writes into.

        New arrays (the ones it had may have been handed out as a period's
        estimates), the values it holds (zeros before its first update).
        """
        if motion.prev_x is None:
            prev_x, prev_v = np.zeros(self._shape), np.zeros(self._shape)
        else:
            prev_x = np.array(motion.prev_x, dtype=float).reshape(self._shape)
            prev_v = np.array(motion.prev_v, dtype=float).reshape(self._shape)
        motion.prev_x, motion.prev_v = prev_x, prev_v
        self._prev = (prev_x, prev_v)


def _outputs(N: int) -> tuple[np.ndarray, ...]:
    """The C call's outputs, (N, 2) each, made here (a build that cannot make them)."""
    return np.empty((N, 2)), np.empty((N, 2)), np.empty((N, 2))


def covers(law: Any, leader: int) -> bool:
    """Whether :class:`LawKernel` computes ``law`` with the leader's row ``leader``.

    The five built-in classes themselves (not a subclass), offsets of shape
    (K, n, 2) in C-contiguous float64, one tangent angle, a leader for the laws
    that read one, and one history of the estimator for all worlds.
    """
    kind = KINDS.get(type(law))
    if kind is None:
        return False
    delta = law.delta
    if not (
        type(delta) is np.ndarray
        and delta.ndim == 3
        and delta.shape[2] == 2
        and delta.dtype == np.float64
        and delta.flags.c_contiguous
        and isinstance(law._tangent, float)
    ):
        return False
    if kind != 2 and leader < 0:
        return False
    motion = getattr(law, _MOTION.get(kind, ""), None)
    return kind not in _MOTION or type(motion) is BackwardDifference
