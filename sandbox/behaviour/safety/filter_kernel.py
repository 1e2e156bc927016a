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

from dataclasses import replace
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
from sandbox.geometry.neighbours import AllPairsByWorld
from sandbox.model.barriers import MIN_DIST, MIN_SPEED
from sandbox.model.kernels import c_float64

if TYPE_CHECKING:
    from sandbox.behaviour.safety.state import CBFState
    from sandbox.plugins.contexts import FilterContext


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
        self.v1_max, self.lateral, self.accel = (
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

    Every pair of each small world (whatever the positions given); a larger single
    world's kept list is brought up to date on the seen look-ahead points, as
    ``near`` does (when some vehicle is filtered).
    """
    search = state.neighbours
    if isinstance(search, AllPairsByWorld):
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
    pairs = _candidates(state, ctx)
    out = (np.empty(n), np.empty(n), np.empty(n, dtype=bool), np.empty(n), np.empty(n))
    try:  # the arrays as they are, where each is C-contiguous of its type
        count, least, pending = _call(
            state, ctx, args, pairs, (rows, signed, away), out
        )
    except (TypeError, ValueError, BufferError):
        count, least, pending = _call(
            state, _contiguous(ctx), args, pairs, (rows, signed, away), out
        )
    v1, v2, active, slack, by_vehicle = out
    fallback = np.zeros(n, dtype=bool)
    if count < 0:  # no vehicle is filtered
        return v1, v2, FilterStep(active, slack, 0, np.inf, fallback)
    if pending:
        _settle(state, ctx, args, pending, v1, v2, active, slack)
    return v1, v2, FilterStep(active, slack, count, least, fallback, by_vehicle)


def _contiguous(ctx: FilterContext) -> FilterContext:
    """``ctx`` with its arrays C-contiguous float64 (bool for the flags)."""
    return replace(
        ctx,
        **{
            name: _floats(getattr(ctx, name))
            for name in ("pos", "theta", "vel", "v1", "v2", "diameter", "seen")
        },
        v1_prev=_floats(ctx.v1_prev),
        v2_prev=_floats(ctx.v2_prev),
        known_failed=_bools(ctx.known_failed),
        commanded=_bools(ctx.commanded),
    )


def _call(
    state: CBFState,
    ctx: FilterContext,
    args: Arguments,
    pairs: tuple[np.ndarray, np.ndarray],
    obstacles: tuple[np.ndarray | None, ...],
    out: tuple[np.ndarray, ...],
) -> tuple[int, float, int]:
    """The C loop's step: its kept rows (-1: none filtered), least ``h``, pending.

    Parameters
    ----------
    state : CBFState
    ctx : FilterContext
    args : Arguments
    pairs : tuple of 2 ndarray of intp
        The neighbour search's candidates.
    obstacles : tuple of 3 ndarray or None
        The obstacles' rows: the vehicles, the signed distances [m] and the unit
        vectors away (:func:`~sandbox.behaviour.safety.braking.obstacle_normals`).
    out : tuple of 5 ndarray (n,)
        ``v1``, ``v2``, ``active``, ``slack``, ``by_vehicle``: written.

    Raises
    ------
    TypeError, ValueError, BufferError
        An array that is not C-contiguous of its type (nothing is written then).
    """
    v1, v2, active, slack, by_vehicle = out
    return args.c.velocity_step(
        pos=ctx.pos,
        theta=ctx.theta,
        vel=ctx.vel,
        v1=ctx.v1,
        v2=ctx.v2,
        diameter=ctx.diameter,
        v1_prev=ctx.v1_prev,
        v2_prev=ctx.v2_prev,
        known_failed=ctx.known_failed,
        commanded=ctx.commanded,
        seen=ctx.seen,
        v1_max=args.v1_max,
        lateral=args.lateral,
        accel=args.accel,
        cand_i=pairs[0],
        cand_j=pairs[1],
        obs_rows=obstacles[0],
        obs_signed=obstacles[1],
        obs_away=obstacles[2],
        gamma=state.gamma,
        look=state.look,
        margin=state.margin,
        radius=state.neighbours.radius,
        dt=ctx.dt,
        pass_right=state.pass_right,
        tolerance=TOLERANCE,
        min_dist=MIN_DIST,
        min_speed=MIN_SPEED,
        stall_start=STALL_START,
        stall_full=STALL_FULL,
        stall_speed=STALL_SPEED,
        reverse=state.reverse,
        speed_only=state.speed_only,
        broadcast=state.broadcast,
        max_rows=state.max_rows,
        v1_out=v1,
        v2_out=v2,
        active=active,
        slack=slack,
        by_vehicle=by_vehicle,
        pending=args.pending,
        pending_m=args.pending_m,
        pending_mat=args.pending_mat,
        pending_off=args.pending_off,
    )


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
