"""The velocity barrier's step of the CBF filter in one C call.

:func:`~sandbox.behaviour.safety.cbf.filter_commands` with ``barrier: velocity`` (the
default) makes every barrier condition of the step, prunes them, orders and cuts each
vehicle's, and solves each vehicle's QP: with numpy that is about a hundred calls a
period, whose fixed cost (half a microsecond each) is most of the filter's time for
small fleets, however many worlds a batched call holds. Where the optional extension
``sandbox.behaviour.safety._filter`` (``_filter.c``) is built, :func:`velocity_step`
does the whole step as one C loop over the vehicles of every world: the boxes and
each vehicle's reach, the neighbour search's filter on its candidates, the exact
pruning of pairs that cannot bind, both directions of the rest (cooperative or not,
``broadcast`` or ``zero``, with or without sensing), the least barrier and each
vehicle's, the rotation into ``z = (v1, l v2)``, the prune by reach, each vehicle's
rows in ``np.lexsort((b, veh))``'s order cut at ``max_constraints``, the exact QP
(the projection of :mod:`~sandbox.behaviour.safety.qp`, in C), the right-hand rule and
the commands written back, with numpy's operations in numpy's order: the same numbers
to the bit. The obstacles' rows are made by numpy
(:func:`~sandbox.behaviour.safety.braking.obstacle_normals`) and handed in. A vehicle
whose problem (or turned problem) has no common point, which needs
:func:`~sandbox.behaviour.safety.qp.min_violation` (LAPACK's solves), is handed back
with its problem and solved by numpy (:func:`_settle`).

The C path covers ``barrier: velocity`` without ``priority`` (every projection,
neighbour velocity, ``reverse`` and ``pass_right``, sensing, failed and open-loop
vehicles, obstacles, one world or K); ``barrier: braking``, a ``priority``, and
:func:`~sandbox.behaviour.safety.cbf.filter_commands` called with ``prune=False`` keep
the numpy path, as does every run where the extension is not built (no C compiler),
:data:`USE_KERNEL` is False, or the check fails.

The loop takes the C library's ``sin``, ``cos`` and ``hypot``: at the first use
:func:`kernel_agrees` requires :func:`~sandbox.model.kernels.kernels_agree` (those
functions against numpy's), that ``np.einsum("kd,kd->k")`` sums its two products from
0 as the loop does and that ``np.hypot`` is even (a pair's two directions share one
distance), and then compares the two paths of ``filter_commands`` on a few
dozen random steps (every option above, infeasible and stalled vehicles, rows beyond
the cut) bit for bit; the C loop is used only if every result is the same.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

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
from sandbox.model.kernels import c_float64, kernels_agree

if TYPE_CHECKING:
    from sandbox.behaviour.safety.cbf import CBFState
    from sandbox.plugins.contexts import FilterContext

try:
    from sandbox.behaviour.safety import _filter
except ImportError:  # pragma: no cover - built without a C compiler
    _filter = None

#: Use the C loop where it is built and agrees with numpy (False: numpy only).
USE_KERNEL = True
_agreed: bool | None = None
#: The flags of the C loop: ``reverse: true``, ``projection: speed``,
#: ``neighbour_velocity: broadcast``.
REVERSE, SPEED_ONLY, BROADCAST = 1, 2, 4


def covers(state: CBFState) -> bool:
    """Whether the C loop does this step (the velocity barrier, no priority)."""
    return not state.braking and state.priority == "none"


def usable() -> bool:
    """Whether :func:`velocity_step` may run (built, agreeing, not switched off)."""
    return USE_KERNEL and kernel_agrees()


def kernel_agrees() -> bool:
    """Whether the C loop gives the numpy path's bits here (checked once)."""
    global _agreed
    if _agreed is None:
        _agreed = _filter is not None and kernels_agree() and _check()
    return _agreed


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
        count, least, pending = _filter.velocity_step(*given, *rest)
    except (TypeError, ValueError, BufferError):
        floats = [_floats(a) for a in given]
        floats[8], floats[9] = _bools(given[8]), _bools(given[9])
        count, least, pending = _filter.velocity_step(*floats, *rest)
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


def _check() -> bool:
    """Both paths of ``filter_commands`` on random steps, bit for bit."""
    from sandbox.behaviour.safety.cbf import CBFState, filter_commands

    global USE_KERNEL
    if not _numpy_as_assumed():
        return False
    saved = USE_KERNEL
    try:
        for ctx in random_steps(np.random.default_rng(20261207), 40):
            USE_KERNEL = False
            want = filter_commands(CBFState(ctx), ctx)
            USE_KERNEL = saved
            if not same_step(velocity_step(CBFState(ctx), ctx), want):
                return False
    finally:
        USE_KERNEL = saved
    return True


def random_steps(rng: np.random.Generator, count: int) -> list[FilterContext]:
    """Steps of the velocity barrier on random fleets, for the check and the tests.

    One world or three of one to five vehicles, close enough for barriers to bind
    and to conflict (infeasible problems, stalls, more rows than the cut), with and
    without the last period's commands, sensing, failed and open-loop vehicles,
    obstacles, each option of the filter, a fleet with none filtered and one with a
    position unknown (NaN).
    """
    from sandbox.behaviour.safety.cbf import PARAMS
    from sandbox.model.obstacle_field import ObstacleField
    from sandbox.model.obstacles import ObstacleSpec
    from sandbox.plugins.contexts import FilterContext

    walls = (
        ObstacleSpec("circle", "c", center=(0.3, -0.2), radius=0.3),
        ObstacleSpec("wall", "w", start=(-1.5, 1.0), end=(1.5, 1.2), thickness=0.1),
    )
    out = []
    for trial in range(count):
        worlds = 1 if trial % 3 == 0 else 3
        n = int(rng.integers(1, 4 if trial % 2 else 6))
        size = worlds * n
        params = {k: p.default for k, p in PARAMS.items()}
        params.update(
            gamma=float(rng.uniform(0.5, 4.0)),
            margin=float(rng.choice([0.05, 0.2])),
            look_ahead=float(rng.choice([0.1, 0.25])),
            neighbour_velocity="zero" if trial % 4 == 1 else "broadcast",
            projection="speed" if trial % 5 == 2 else "look_ahead",
            reverse=trial % 3 != 1,
            pass_right=0.0 if trial % 7 == 3 else 1.5708,
            max_constraints=int(rng.integers(1, 4)) if trial % 2 else 8,
            range=None if trial % 4 else float(rng.uniform(0.5, 3.0)),
        )
        if trial % 2:  # crowded: overlapping barriers, empty polygons
            pos = rng.uniform(-1.2, 1.2, (size, 2))
            theta = rng.uniform(-np.pi, np.pi, size)
            v1 = rng.uniform(-2.0, 2.0, size)
            v2 = rng.uniform(-4.0, 4.0, size)
        else:  # apart, each heading for its world's centre: stalls
            pos = rng.uniform(-1.0, 1.0, (size, 2)) * (0.3 + 0.25 * n)
            centre = np.repeat(pos.reshape(worlds, n, 2).mean(axis=1), n, axis=0)
            aim = centre - pos
            theta = np.arctan2(aim[:, 1], aim[:, 0]) + rng.normal(0.0, 0.2, size)
            v1 = rng.uniform(0.3, 2.0, size)
            v2 = rng.normal(0.0, 0.3, size)
        first = trial % 6 == 0
        failed = rng.random(size) < (1.0 if trial == 5 else 0.15)
        if trial == 7:
            pos[0] = np.nan
        seen = None
        if trial % 4 == 3:
            seen = np.column_stack((pos, theta)) + rng.normal(0.0, 0.05, (size, 3))
        out.append(
            FilterContext(
                t=0.0,
                dt=0.01,
                pos=pos,
                theta=theta,
                vel=rng.normal(0.0, 0.8, (size, 2)),
                v1=v1,
                v2=v2,
                diameter=rng.uniform(0.3, 0.6, size),
                params=params,
                v1_prev=None if first else v1 + rng.normal(0.0, 0.05, size),
                v2_prev=None if first else v2 + rng.normal(0.0, 0.2, size),
                v1_max=2.0,
                v2_max=np.inf if trial % 8 == 6 else 4.0,
                accel_max=5.0 if trial % 2 else float(rng.choice([50.0, np.inf])),
                known_failed=failed,
                commanded=rng.random(size) < 0.1,
                obstacle_field=ObstacleField(walls if trial % 5 == 4 else ()),
                seen=seen,
                worlds=worlds,
                substeps=4,
            )
        )
    return out


def _numpy_as_assumed() -> bool:
    """Whether numpy here does what the loop assumes beyond the C library's functions.

    ``einsum("kd,kd->k")`` is ``0 + a0 b0 + a1 b1``, and ``hypot(-x, -y)`` is
    ``hypot(x, y)`` (a pair's two directions share one distance).
    """
    rng = np.random.default_rng(7)
    a = rng.normal(0.0, 1.0, (512, 2))
    b = rng.normal(0.0, 1.0, (512, 2))
    a[:64] = np.where(rng.random((64, 2)) < 0.5, -0.0, 0.0)
    b[32:96] = np.where(rng.random((64, 2)) < 0.5, -0.0, 0.0)
    a[96:128] *= np.exp(rng.uniform(-700.0, 700.0, (32, 1)))
    want = 0.0 + a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]
    got = np.einsum("kd,kd->k", a, b)
    turned = np.hypot(-a[:, 0], -a[:, 1])
    return bool(
        np.array_equal(got.view(np.uint64), want.view(np.uint64))
        and np.array_equal(
            turned.view(np.uint64), np.hypot(a[:, 0], a[:, 1]).view(np.uint64)
        )
    )


def same_step(
    got: tuple[np.ndarray, np.ndarray, FilterStep],
    want: tuple[np.ndarray, np.ndarray, FilterStep],
) -> bool:
    """Whether two results of a step are the same, bit for bit."""

    def bits(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a, dtype=float).view(np.uint64)

    (v1, v2, s), (w1, w2, t) = got, want
    pairs = [(v1, w1), (v2, w2), (s.slack, t.slack)]
    if (s.by_vehicle is None) != (t.by_vehicle is None):
        return False
    if s.by_vehicle is not None:
        pairs.append((s.by_vehicle, t.by_vehicle))
    return (
        all(np.array_equal(bits(a), bits(b)) for a, b in pairs)
        and np.array_equal(s.active, t.active)
        and np.array_equal(s.fallback, t.fallback)
        and s.rows == t.rows
        and bits(np.array([s.min_barrier])).tolist()
        == bits(np.array([t.min_barrier])).tolist()
    )
