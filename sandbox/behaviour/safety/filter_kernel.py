"""The velocity barrier's step of the CBF filter in one C call.

:func:`~sandbox.behaviour.safety.cbf.filter_commands` with ``barrier: velocity`` (the
default) makes every barrier condition of the step, prunes them, orders and cuts each
vehicle's, and solves each vehicle's QP: with numpy that is about a hundred calls a
period, whose fixed cost (half a microsecond each) is most of the filter's time for
small fleets, however many worlds a batched call holds. Where the compiled path
``filter`` is on (:mod:`sandbox.accel`; ``_filter.c``), :func:`velocity_step` does the
whole step as one C loop over the vehicles of every world: the boxes and each
vehicle's reach, the neighbour search's filter on its candidates, the exact pruning
of pairs that cannot bind, both directions of the rest (cooperative or not,
``broadcast`` or ``zero``, with or without sensing), the least barrier and each
vehicle's, the rotation into ``z = (v1, l v2)``, the prune by reach, each vehicle's
rows cut at ``max_constraints`` (the least ``b`` first), the exact QP (the projection
of :mod:`~sandbox.behaviour.safety.qp`, in C), the right-hand rule and the commands
written back. The obstacles' rows are made by numpy
(:func:`~sandbox.behaviour.safety.braking.obstacle_normals`) and handed in. A vehicle
whose problem (or turned problem) has no common point, which needs
:func:`~sandbox.behaviour.safety.qp.min_violation` (LAPACK's solves), is handed back
with its problem and solved by numpy (:func:`_settle`). The numpy step of
:func:`~sandbox.behaviour.safety.cbf.filter_commands` stays the reference; the two
agree within 1e-9 [m/s] (``tests/test_compiled_paths.py``).

The C path covers ``barrier: velocity`` without ``priority`` (every projection,
neighbour velocity, ``reverse`` and ``pass_right``, sensing, failed and open-loop
vehicles, obstacles, one world or K); ``barrier: braking``, a ``priority``, and
:func:`~sandbox.behaviour.safety.cbf.filter_commands` called with ``prune=False`` keep
the numpy path, as does every run where the path is off.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox import accel
from sandbox.behaviour.safety.accounting import FilterStep
from sandbox.behaviour.safety.braking import (
    columns,
    look_ahead_points,
    obstacle_normals,
)
from sandbox.behaviour.safety.qp import TOLERANCE, solve
from sandbox.behaviour.safety.right_hand import (
    STALL_FULL,
    STALL_SPEED,
    STALL_START,
    pass_right,
)
from sandbox.geometry.neighbours import BRUTE_FORCE_MAX, WorldPairs
from sandbox.model.barriers import MIN_DIST, MIN_SPEED
from sandbox.model.kernels import c_float64

if TYPE_CHECKING:
    from sandbox.behaviour.safety.state import CBFState
    from sandbox.plugins.contexts import FilterContext

#: The flags of the C loop: ``reverse: true``, ``projection: speed``,
#: ``neighbour_velocity: broadcast``.
REVERSE, SPEED_ONLY, BROADCAST = 1, 2, 4


def covers(state: CBFState) -> bool:
    """Whether the C loop does this step (the velocity barrier, no priority)."""
    return not state.braking and state.priority == "none"


def usable() -> bool:
    """Whether :func:`velocity_step` may run (the compiled path ``filter``)."""
    return accel.module("filter") is not None


class Arguments:
    """The C loop's arguments that hold from one step to the next, and its buffers.

    Parameters
    ----------
    state : CBFState
    n : int
        Rows (vehicles of every world).
    dt : float [s]
    """

    def __init__(self, state: CBFState, n: int, dt: float) -> None:
        self.c = accel.module("filter")
        self.n, self.dt = n, dt
        self.params = np.array(
            [
                state.gamma,
                state.look,
                state.margin,
                state.neighbours.radius,
                dt,
                state.pass_right,
                TOLERANCE,
                MIN_DIST,
                MIN_SPEED,
                STALL_START,
                STALL_FULL,
                STALL_SPEED,
            ],
            dtype=float,
        )
        self.flags = (
            (REVERSE if state.reverse else 0)
            | (SPEED_ONLY if state.speed_only else 0)
            | (BROADCAST if state.broadcast else 0)
        )
        self.limits = tuple(
            c_float64(np.broadcast_to(a, (n,)))
            for a in (state.v1_max, state.lateral, state.accel)
        )
        width = 4 + state.max_rows
        #: Vehicles handed back to numpy, their row counts and problems.
        self.pending = np.zeros(n, dtype=np.intp)
        self.pending_m = np.zeros(n, dtype=np.intp)
        self.pending_mat = np.zeros((n, width, 2))
        self.pending_off = np.zeros((n, width))


def _bools(a: np.ndarray | None) -> np.ndarray | None:
    if a is None or (a.dtype == np.bool_ and a.flags.c_contiguous):
        return a
    return np.ascontiguousarray(a, dtype=bool)


def _floats(a: Any) -> Any:
    if a is None or isinstance(a, np.ndarray):
        return None if a is None else c_float64(a)
    return np.ascontiguousarray(a, dtype=float)


def _filtered(ctx: FilterContext) -> np.ndarray:
    """The vehicles the filter drives (``filter_commands``' ``filtered``)."""
    filtered = np.ones(len(ctx.pos), dtype=bool)
    if ctx.known_failed is not None:
        filtered &= ~ctx.known_failed
    if ctx.commanded is not None:
        filtered &= ~ctx.commanded
    return filtered


def _any_filtered(ctx: FilterContext) -> bool:
    return bool(_filtered(ctx).any())


def _candidates(state: CBFState, ctx: FilterContext) -> tuple[np.ndarray, ...]:
    """The neighbour search's candidate pairs, those ``near`` filters by distance.

    Every pair of each world up to :data:`BRUTE_FORCE_MAX` vehicles (whatever the
    positions given); a larger single world's kept list is brought up to date on
    the seen look-ahead points, as ``near`` does (when some vehicle is filtered).
    """
    search = state.neighbours
    if isinstance(search, WorldPairs) or len(ctx.pos) <= BRUTE_FORCE_MAX:
        return search.candidates(ctx.pos)
    if not _any_filtered(ctx):
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    return search.candidates(look_ahead_points(ctx, state.look)[3])


def velocity_step(
    state: CBFState, ctx: FilterContext
) -> tuple[np.ndarray, np.ndarray, FilterStep]:
    """:func:`~sandbox.behaviour.safety.cbf.filter_commands` of the velocity barrier.

    Parameters
    ----------
    state : CBFState
        A filter :func:`covers`.
    ctx : FilterContext

    Returns
    -------
    v1 : ndarray, shape (n,) [m/s]
    v2 : ndarray, shape (n,) [rad/s]
    step : FilterStep
    """
    n, look = len(ctx.pos), state.look
    args = state.c_args
    if args is None or args.n != n or args.dt != ctx.dt:
        args = state.c_args = Arguments(state, n, ctx.dt)
    rows = signed = away = None
    field = ctx.obstacle_field
    if field is not None and not field.empty and _any_filtered(ctx):
        p = look_ahead_points(ctx, look)[1]  # (numpy's step makes no rows for none)
        near = obstacle_normals(state, ctx, p, _filtered(ctx))
        if near is not None:
            rows = np.ascontiguousarray(near[0], dtype=np.intp)
            signed, away = c_float64(near[1]), c_float64(near[2])
    i, j = _candidates(state, ctx)
    v1, v2, slack = np.empty(n), np.empty(n), np.empty(n)
    active = np.empty(n, dtype=bool)
    by_vehicle = np.empty(n) if ctx.worlds > 1 else None
    given = (
        ctx.pos, ctx.theta, ctx.vel, ctx.v1, ctx.v2, ctx.diameter, ctx.v1_prev,
        ctx.v2_prev, ctx.known_failed, ctx.commanded, ctx.seen,
    )  # fmt: skip
    rest = (
        *args.limits, i, j, rows, signed, away, args.params, args.flags,
        state.max_rows, v1, v2, active, slack, by_vehicle, args.pending,
        args.pending_m, args.pending_mat, args.pending_off,
    )  # fmt: skip
    try:  # the arrays as they are, where each is C-contiguous of its type
        count, least, pending = args.c.velocity_step(*given, *rest)
    except (TypeError, ValueError, BufferError):
        floats = [_floats(a) for a in given]
        floats[8], floats[9] = _bools(given[8]), _bools(given[9])
        count, least, pending = args.c.velocity_step(*floats, *rest)
    fallback = np.zeros(n, dtype=bool)
    if count < 0:  # no vehicle is filtered
        return v1, v2, FilterStep(active, slack, 0, np.inf, fallback)
    if pending:
        _settle(state, ctx, args, pending, v1, v2, active, slack)
    return v1, v2, FilterStep(active, slack, count, least, fallback, by_vehicle)


def _settle(
    state: CBFState,
    ctx: FilterContext,
    args: Arguments,
    count: int,
    v1: np.ndarray,
    v2: np.ndarray,
    active: np.ndarray,
    slack: np.ndarray,
) -> None:
    """Solve by numpy the problems the C loop handed back, and write their commands.

    Each vehicle's problem as :func:`~sandbox.behaviour.safety.qp.bounded_problems`
    makes it, solved (:func:`~sandbox.behaviour.safety.qp.solve`) and turned right
    (:func:`~sandbox.behaviour.safety.right_hand.pass_right`) as ``filter_commands``
    does for the vehicles with as many rows.
    """
    look = state.look
    who, sizes = args.pending[:count], args.pending_m[:count]
    v1_in = np.asarray(ctx.v1, dtype=float)
    v2_in = np.asarray(ctx.v2, dtype=float)
    for m in np.unique(sizes).tolist():
        sel = (sizes == m).nonzero()[0]
        group, width = who[sel], 4 + m
        mat, off = args.pending_mat[sel, :width], args.pending_off[sel, :width]
        soft = np.zeros((len(group), width), dtype=bool)
        soft[:, 4:] = True
        z0 = columns(v1_in[group], look * v2_in[group])
        z, s = solve(z0, mat, off, soft)
        if state.pass_right > 0 and not state.speed_only:
            z, s = pass_right(state, z0, z, s, mat, off, soft)
        changed = np.any(z != z0, axis=1)
        moved = group[changed]
        v1[moved] = z[changed, 0]
        if not state.speed_only:
            v2[moved] = z[changed, 1] / look
        active[group] = changed
        slack[group] = s
