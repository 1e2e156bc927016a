"""The vehicles' terms of the avoidance field, eqs. (22)-(27), in one C call.

:func:`~sandbox.behaviour.recovery.weighted_shift` sums, for every pair of vehicles
within the safe zone, each vehicle's term ``alpha(dist) u / dist`` (eqs. (23)-(25)):
with numpy that is about twenty calls a period, whose fixed cost (half a microsecond
each) is most of the strategy's time for a small fleet. Where the optional extension
``sandbox.behaviour._pair_field`` (``_pair_field.c``) is built, :func:`add_pair_terms`
does the same for the discontinuous and continuous weights without the tangential
term, as one loop over the neighbour search's candidate pairs: the search's filter,
the weights and the sums in numpy's order (each vehicle's terms as ``np.bincount``
adds them), with the same double operations, so the numbers are numpy's to the bit.

The loop takes the C library's ``sqrt``; at the first use :func:`kernel_agrees`
compares the two paths on a few hundred random fleets (true and broadcast positions,
coincident and NaN ones included), and the C loop is used only if every result has
the same bits (``tests/test_pair_field.py`` compares whole runs). :data:`USE_KERNEL`
False forces the numpy path.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.model.kernels import c_float64

try:
    from sandbox.behaviour import _pair_field
except ImportError:  # pragma: no cover - built without a C compiler
    _pair_field = None

#: Use the C loop where it is built and agrees with numpy (False: numpy only).
USE_KERNEL = True
#: The weights the C loop computes: ``kind`` 0 and 1.
DISCONTINUOUS, CONTINUOUS = 0, 1
_agreed: bool | None = None
_shift_agreed: bool | None = None


def usable() -> bool:
    """Whether :func:`add_pair_terms` may run (built, agreeing, not switched off)."""
    return USE_KERNEL and kernel_agrees()


def kernel_agrees() -> bool:
    """Whether the C loop gives the numpy path's bits here (checked once)."""
    global _agreed
    if _agreed is None:
        _agreed = _pair_field is not None and _check()
    return _agreed


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
    """Write the pairs' terms of the field (before ``beta``) into ``shift``, ``active``.

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
    neighbours : NeighbourList or WorldPairs
        The search (its ``candidates``, ``radius`` and ``remember``).
    R, r : float [m]
        The weight's radii (``r`` unused by the discontinuous weight).
    kind : int
        :data:`DISCONTINUOUS` or :data:`CONTINUOUS`.
    shift : ndarray, shape (n, 2), float64, C-contiguous, zeros
    active : ndarray, shape (n,), bool, C-contiguous
        Set where a term weighs above zero.
    beta : float, optional
        The aggressiveness [m^2], with ``avoiders``.
    avoiders : ndarray, shape (n,), bool, optional
        The vehicles that apply the strategy.
    """
    i, j = neighbours.candidates(pos)
    d2 = np.empty(len(i))
    _pair_field.pair_field(
        c_float64(pos),
        None if seen is None else c_float64(seen),
        i,
        j,
        float(neighbours.radius),
        float(R),
        0.0 if r is None else float(r),
        kind,
        shift,
        active,
        d2,
        0.0 if beta is None else float(beta),
        None if avoiders is None else np.ascontiguousarray(avoiders, dtype=bool),
    )
    neighbours.remember(pos, d2)


class ShiftKernel:
    """A weighted strategy's shifted targets of a period in one C call.

    What the loop does with a built-in discontinuous or continuous strategy without
    static obstacles and without the tangential term: the shift of
    :func:`~sandbox.behaviour.recovery.weighted_shift` (eqs. (22)-(27)), zero for
    the vehicles that do not avoid, and the targets ``slot + shift`` of eq. (22) /
    (26), the numbers of those numpy calls (checked once: :func:`shift_agrees`).

    Parameters
    ----------
    neighbours : NeighbourList or WorldPairs
        The loop's neighbour search (its candidates, radius and ``remember``).
    R, r : float [m]
        The weight's radii (``r`` unused by the discontinuous weight).
    kind : int
        :data:`DISCONTINUOUS` or :data:`CONTINUOUS`.
    beta : float or ndarray
        One aggressiveness [m^2], or each row's (shape (N, 1) or (N,)).
    """

    def __init__(
        self, neighbours: Any, R: float, r: float | None, kind: int, beta: Any
    ) -> None:
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
        if _pair_field.ALLOCATES:  # the call makes its outputs
            out = (None, None, None, None)
        else:
            N = len(pos)
            out = (
                np.empty((N, 2)),
                np.empty((N, 2)),
                np.empty(N, bool),
                np.empty(len(i)),
            )
        target, shift, active, d2 = _pair_field.shifted_targets(
            pos, seen, i, j, self.radius, self.R, self.r, self.kind, self.beta,
            avoiders, slot, *out,
        )  # fmt: skip
        neighbours.remember(pos, d2)
        return target, shift, active


def shift_agrees() -> bool:
    """Whether :class:`ShiftKernel` gives the numpy path's bits here (checked once).

    The pair terms' check (:func:`kernel_agrees`), then whole periods of random
    fleets: :func:`~sandbox.behaviour.recovery.weighted_shift` by numpy and
    ``slot + shift`` against the one call, one beta and each row's, with the true
    and the broadcast positions (in rows of 2 and of 3).
    """
    global _shift_agreed
    if _shift_agreed is None:
        _shift_agreed = kernel_agrees() and _shift_check()
    return _shift_agreed


def _shift_check() -> bool:
    from sandbox.behaviour import recovery
    from sandbox.geometry.neighbours import NeighbourList, WorldPairs
    from sandbox.model.obstacle_field import ObstacleField
    from sandbox.plugins.contexts import StrategyContext

    global USE_KERNEL
    rng = np.random.default_rng(20261208)
    weights = {DISCONTINUOUS: recovery.discontinuous, CONTINUOUS: recovery.continuous}
    saved = USE_KERNEL
    try:
        for trial in range(80):
            K, n = int(rng.integers(1, 4)), int(rng.integers(1, 8))
            N = K * n
            pos = rng.uniform(-2.0, 2.0, (N, 2))
            if trial % 5 == 0 and n > 1:
                pos[1] = pos[0]  # coincident vehicles: eq. (25)'s least distance
            if trial % 7 == 0:
                pos[-1] = np.nan  # a vehicle whose position is unknown
            poses = np.concatenate((pos, rng.normal(0.0, 1.0, (N, 1))), axis=1)
            poses[:, :2] += rng.normal(0.0, 0.05, (N, 2))
            seen = (None, poses, np.ascontiguousarray(poses[:, :2]))[trial % 3]
            slot = rng.normal(0.0, 3.0, (N, 2))
            slot[rng.random(N) < 0.2] = np.nan
            avoiders = rng.random(N) < (0.0 if trial % 11 == 0 else 0.8)
            kind = (DISCONTINUOUS, CONTINUOUS)[(trial // 3) % 2]
            beta = 0.3 if trial % 2 else rng.uniform(0.0, 1.0, (N, 1))
            R, r = 1.5, (None, 0.5)[kind]
            ctx = StrategyContext(
                t=0.0,
                dt=0.01,
                pos=pos,
                theta=np.zeros(N),
                vel=np.zeros((N, 2)),
                slot=slot,
                diameter=np.zeros(N),
                may_avoid=avoiders,
                failed=np.zeros(N, dtype=bool),
                params={},
                R=R,
                obstacle_field=ObstacleField(()),
                neighbours=WorldPairs(K, n, R) if trial % 4 else NeighbourList(R),
                seen_pos=None if seen is None else np.array(seen[:, :2]),
            )
            USE_KERNEL = False
            shift, active = recovery.weighted_shift(
                ctx, weights[kind], beta, r, 2.0, 0.0
            )
            USE_KERNEL = True
            search = WorldPairs(K, n, R) if trial % 4 else NeighbourList(R)
            kernel = ShiftKernel(search, R, r, kind, beta)
            got = kernel.shifted(pos, seen, avoiders, slot)
            want = (slot + shift, shift, active)
            if not all(_bits_equal(a, b) for a, b in zip(got, want, strict=True)):
                return False
    finally:
        USE_KERNEL = saved
    return True


def _bits_equal(a: np.ndarray, b: np.ndarray) -> bool:
    """Same shape, dtype and bytes."""
    return (
        a.shape == b.shape
        and a.dtype == b.dtype
        and bool(np.array_equal(a.view(np.uint8), b.view(np.uint8)))
    )


def _check() -> bool:
    """Both paths of ``weighted_shift`` on random fleets, bit for bit."""
    from sandbox.behaviour import recovery
    from sandbox.geometry.neighbours import NeighbourList
    from sandbox.model.obstacle_field import ObstacleField
    from sandbox.plugins.contexts import StrategyContext

    global USE_KERNEL, _agreed
    _agreed = True  # provisionally, so that the C path runs within the check
    rng = np.random.default_rng(20261206)
    weights = (recovery.discontinuous, recovery.continuous)
    saved, _agreed_now = USE_KERNEL, True
    try:
        for trial in range(200):
            n = int(rng.integers(2, 12))
            pos = rng.uniform(-2.0, 2.0, (n, 2))
            if trial % 5 == 0:
                pos[1] = pos[0]  # coincident vehicles: eq. (25)'s least distance
            if trial % 7 == 0:
                pos[-1] = np.nan  # a vehicle whose position is unknown
            seen = pos + rng.normal(0.0, 0.05, (n, 2)) if trial % 2 else None
            ctx = StrategyContext(
                t=0.0,
                dt=0.01,
                pos=pos,
                theta=np.zeros(n),
                vel=np.zeros((n, 2)),
                slot=np.full((n, 2), np.nan),
                diameter=np.zeros(n),
                may_avoid=rng.random(n) < 0.8,
                failed=np.zeros(n, dtype=bool),
                params={},
                R=1.5,
                obstacle_field=ObstacleField(()),
                seen_pos=seen,
            )
            weight = weights[(trial // 2) % 2]  # each with and without sensing
            got = []
            for use in (True, False):
                USE_KERNEL = use
                neighbours = NeighbourList(1.5)
                got.append(
                    recovery.weighted_shift(
                        _with(ctx, neighbours), weight, 0.3, 0.5, 2.0
                    )
                )
            (s1, a1), (s2, a2) = got
            if not (
                np.array_equal(s1.view(np.uint64), s2.view(np.uint64))
                and np.array_equal(a1, a2)
            ):
                _agreed_now = False
                break
    finally:
        USE_KERNEL = saved
    return _agreed_now


def _with(ctx: Any, neighbours: Any) -> Any:
    from dataclasses import replace

    return replace(ctx, neighbours=neighbours)
