"""The vehicles' terms of the avoidance field, eqs. (22)-(27), in one C call.

:func:`~sandbox.behaviour.recovery.weighted_shift` sums, for every pair of vehicles
within the safe zone, each vehicle's term ``alpha(dist) u / dist`` (eqs. (23)-(25)):
with numpy that is about twenty calls a period, whose fixed cost (half a microsecond
each) is most of the strategy's time for a small fleet. Where the compiled path
``pair_field`` is on (:mod:`sandbox.accel`; ``_pair_field.c``), :func:`add_pair_terms`
does the same for the discontinuous and continuous weights without the tangential
term, as one loop over the neighbour search's candidate pairs: the search's filter,
the weights and the sums. ``weighted_shift``'s numpy stays the reference; the two
agree within rtol 1e-12 (``tests/test_compiled_paths.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox import accel
from sandbox.model.kernels import c_float64

#: The weights the C loop computes: ``kind`` 0 and 1.
DISCONTINUOUS, CONTINUOUS = 0, 1


def usable() -> bool:
    """Whether :func:`add_pair_terms` may run (the compiled path ``pair_field``)."""
    return accel.module("pair_field") is not None


def add_pair_terms(
    pos: np.ndarray,
    seen: np.ndarray | None,
    neighbours: Any,
    R: float,
    r: float | None,
    kind: int,
    shift: np.ndarray,
    active: np.ndarray,
    beta: float | None = None,
    avoiders: np.ndarray | None = None,
) -> None:
    """Write the pairs' terms of the field (before ``beta``) to ``shift``, ``active``.

    With ``beta`` and ``avoiders`` the field is finished as
    :func:`~sandbox.behaviour.recovery.weighted_shift` finishes it without static
    obstacles: multiplied by ``beta``, zero and inactive for the vehicles that do
    not avoid.

    Parameters
    ----------
    pos : ndarray, shape (n, 2) [m]
        True positions: the pairs are those of the neighbour search over them.
    seen : ndarray, shape (n, 2) [m] or None
        The broadcast positions each vehicle sees of the others (None: ``pos``).
    neighbours : NeighbourList or AllPairsByWorld
        The search (its ``candidates``, ``radius`` and ``remember``).
    R, r : float [m]
        The weight's radii (``r`` unused by the discontinuous weight).
    kind : int
        :data:`DISCONTINUOUS` or :data:`CONTINUOUS`.
    shift : ndarray, shape (n, 2), float64, C-contiguous
        Written: the sums of the terms.
    active : ndarray, shape (n,), bool, C-contiguous
        Written: where a term weighs above zero.
    beta : float, optional
        The aggressiveness [m^2], with ``avoiders``.
    avoiders : ndarray, shape (n,), bool, optional
        The vehicles that apply the strategy.
    """
    i, j = neighbours.candidates(pos)
    finish = avoiders is not None
    d2 = np.empty(len(i))
    accel.module("pair_field").pair_terms(
        pos=c_float64(pos),
        seen=None if seen is None else c_float64(seen),
        cand_i=i,
        cand_j=j,
        radius=float(neighbours.radius),
        R=float(R),
        r=0.0 if r is None else float(r),
        kind=kind,
        beta=float(beta) if finish else None,
        avoid=np.ascontiguousarray(avoiders, dtype=bool) if finish else None,
        shift=shift,
        active=active,
        d2=d2,
    )
    neighbours.remember(pos, d2)


class ShiftKernel:
    """A weighted strategy's shifted targets of a period in one C call.

    What the loop does with a built-in discontinuous or continuous strategy without
    static obstacles and without the tangential term: the shift of
    :func:`~sandbox.behaviour.recovery.weighted_shift` (eqs. (22)-(27)), zero for
    the vehicles that do not avoid, and the targets ``slot + shift`` of eq. (22) /
    (26), within rtol 1e-12 of those numpy calls.

    Parameters
    ----------
    neighbours : NeighbourList or AllPairsByWorld
        The loop's neighbour search (its candidates, radius and ``remember``).
    R, r : float [m]
        The weight's radii (``r`` unused by the discontinuous weight).
    kind : int
        :data:`DISCONTINUOUS` or :data:`CONTINUOUS`.
    beta : float or ndarray
        One aggressiveness [m^2], or each row's (shape (N, 1) or (N,)).
    c : module
        The compiled path ``pair_field``'s extension.
    """

    def __init__(
        self,
        neighbours: Any,
        R: float,
        r: float | None,
        kind: int,
        beta: Any,
        c: Any,
    ) -> None:
        self._c = c
        self.neighbours = neighbours
        self.R, self.r, self.kind = float(R), 0.0 if r is None else float(r), kind
        self.radius = float(neighbours.radius)
        self.beta = np.ascontiguousarray(np.reshape(beta, -1), dtype=float)

    def shifted(
        self,
        pos: np.ndarray,
        seen: np.ndarray | None,
        avoiders: np.ndarray,
        slot: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The targets, the shift and the avoiding vehicles of a period.

        Parameters
        ----------
        pos : ndarray, shape (N, 2) [m]
            True positions.
        seen : ndarray, shape (N, 2) or (N, 3), or None
            The broadcast positions (first two columns) each vehicle sees of the
            others (None: ``pos``).
        avoiders : ndarray, shape (N,), bool
            The vehicles that may avoid.
        slot : ndarray, shape (N, 2) [m]

        Returns
        -------
        target, shift : ndarray, shape (N, 2) [m]
        active : ndarray, shape (N,), bool

        Raises
        ------
        TypeError, ValueError, BufferError
            An array that is not what the C loop reads (nothing is changed then).
        """
        neighbours = self.neighbours
        i, j = neighbours.candidates(pos)
        N = len(pos)
        # None: the call makes its own outputs (a build with numpy's C API)
        out = _NO_OUTPUTS if self._c.ALLOCATES else _outputs(N, len(i))
        target, shift, active, d2 = self._c.pair_terms(
            pos=pos,
            seen=seen,
            cand_i=i,
            cand_j=j,
            radius=self.radius,
            R=self.R,
            r=self.r,
            kind=self.kind,
            beta=self.beta,
            avoid=avoiders,
            slot=slot,
            shift=out[0],
            target=out[1],
            active=out[2],
            d2=out[3],
        )
        neighbours.remember(pos, d2)
        return target, shift, active


#: The C call's outputs where it makes them: ``shift``, ``target``, ``active``, ``d2``.
_NO_OUTPUTS = (None, None, None, None)


def _outputs(N: int, pairs: int) -> tuple[np.ndarray, ...]:
    """The C call's outputs, made here (a build that cannot make them)."""
    return np.empty((N, 2)), np.empty((N, 2)), np.empty(N, bool), np.empty(pairs)
