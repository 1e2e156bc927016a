"""The run-away backup of the braking barrier, toward vehicles that do not brake.

A vehicle believed failed or driven open loop keeps its commands for ever
(:func:`sandbox.model.barriers.driven_path`); a vehicle that brakes in its path is run
into once it has stopped. Toward such a vehicle the braking barrier
(:mod:`sandbox.behaviour.safety.braking`) offers a second backup, the *run*: turn rate
0 and the speed moved ``max_accel dt`` a period toward ``v1_max`` in the direction of
travel (forward from rest), then kept, straight along the heading, for ever. Its
barrier ``H^r`` is the least clearance of the look-ahead point along the run from the
failed vehicle's centre along its path, beyond ``D'``: period by period, exactly, for
the run's first :data:`RUN_HORIZON` seconds at full speed, then a lower bound
(:func:`ray_floor`). Each vehicle takes, toward its failed neighbours, the better of
the two backups (the larger least ``H``); its conditions toward them are then
linearised at the run's command ``z_r = (v1^ + sign max_accel dt, 0)`` (clipped to
``v1_max``). What this keeps and what it gives up is in ``docs/concepts/safety.md``
(guarantees 1, 2 and 6).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.safety.state import Brakings
from sandbox.model.barriers import MIN_DIST, STRAIGHT

if TYPE_CHECKING:
    from sandbox.behaviour.safety.state import CBFState
    from sandbox.plugins.contexts import FilterContext

#: How long the run is sampled at full speed [s], period by period, before its
#: lower bound (:func:`ray_floor`) takes over.
RUN_HORIZON = 2.0
#: How long the bound of a straight path follows the two constant velocities [s]:
#: the run at the runaway's own speed and heading closes at a rounding's speed
#: (1e-13 m/s), which for ever would close any gap.
RAY_TAIL = 60.0


def run_target(state: CBFState, ctx: FilterContext) -> np.ndarray:
    """The speed [m/s] each vehicle's run heads for: ``v1_max`` the way it drives.

    Forward from rest (and where the filter may not reverse).
    """
    last = np.zeros(len(ctx.pos)) if ctx.v1_prev is None else ctx.v1_prev
    way = np.where((last < 0.0) & state.reverse, -1.0, 1.0)
    return way * state.v1_max


def run_speeds(
    first: np.ndarray, step: np.ndarray, target: np.ndarray, periods: int
) -> np.ndarray:
    """Speeds [m/s] of the periods of a run: ``first``, then ``step`` nearer ``target``.

    ``s_m = target - sign(target - first) max(|target - first| - m step, 0)``.

    >>> run_speeds(np.array([1.0]), np.array([0.25]), np.array([1.5]), 4).tolist()
    [[1.0, 1.25, 1.5, 1.5]]
    """
    m = np.arange(periods)
    gap = (target - first)[:, None]
    left = np.maximum(np.abs(gap) - m[None, :] * step[:, None], 0.0)
    return target[:, None] - np.sign(gap) * left


def run_ends(state: CBFState, ctx: FilterContext, start: np.ndarray) -> np.ndarray:
    """The sample [1] at which each run from the speeds ``start`` [m/s] is bounded.

    The periods to full speed, one more (the drive's lag), then
    :data:`RUN_HORIZON` at full speed; each vehicle's own (a batch of worlds gives
    each world's values alone). A command up to two steps' worth slower (the
    check's) is at full speed two periods later: its end is two samples later.
    """
    step = state.accel * ctx.dt
    gap = np.abs(run_target(state, ctx) - start) / step
    full = np.ceil(gap - 1e-9).astype(np.intp).clip(0)
    return full + 2 + int(round(RUN_HORIZON / ctx.dt))


def runs(ctx: FilterContext, state: CBFState, theta: np.ndarray, like: Brakings):
    """Every vehicle's run from this state on (the layout of ``Brakings``).

    As the braking (``like``, for the lag and the headings), with the speeds of
    :func:`run_speeds` from the run's first command; ``slope`` is ``d travel / d
    v1`` of that command (1 a period until the run is at full speed), and ``moves``
    the sample at which each run's sampling ends (:func:`run_ends`).
    """
    n, dt, lag = len(ctx.pos), ctx.dt, like.lag
    step = state.accel * dt
    last = np.zeros(n) if ctx.v1_prev is None else ctx.v1_prev
    target = run_target(state, ctx)
    first = run_speeds(last, step, target, 2)[:, 1]
    moves = run_ends(state, ctx, first)  # each run's own end
    count = int(moves.max(initial=0)) + 1
    speeds = run_speeds(first, step, target, count)
    before = np.concatenate((last[:, None], speeds[:, :-1]), axis=1)
    run = (1.0 - lag) * speeds + lag * before
    moving = (speeds != target[:, None]).astype(float)
    moving[:, 0] = 1.0
    was = np.concatenate((np.zeros((n, 1)), moving[:, :-1]), axis=1)
    grows = (1.0 - lag) * moving + lag * was
    travel, slope = np.zeros_like(speeds), np.zeros_like(speeds)
    travel[:, 1:] = dt * np.cumsum(run[:, :-1], axis=1)
    slope[:, 1:] = dt * np.cumsum(grows[:, :-1], axis=1)
    return Brakings(
        first, run, travel, slope, like.heading, like.side, like.path,
        like.path_side, moves, lag,
    )  # fmt: skip


def ray_floor(
    q: np.ndarray,
    velocity: np.ndarray,
    start: np.ndarray,
    course: np.ndarray,
    speed: np.ndarray,
    turn: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """A lower bound [m] of the distance from a ray to a driven path, for ever.

    A point from ``q`` at the constant ``velocity`` [m/s] against the driven path of
    :func:`sandbox.model.barriers.driven_path` from its vertex ``start`` on. Straight
    (``beta = 0``) both move at constant velocities, and the least of ``|r + t (u_q -
    u_c)|`` over ``0 <= t <=`` :data:`RAY_TAIL` is exact. Turning, the path stays
    within its annulus (radii ``r cos(beta / 2)`` and ``r`` about ``C``), and the
    ray's distance to ``C`` takes every value from ``rho = |q - C|`` (moving away
    from ``C``) or the line's distance to ``C`` (moving nearer) on: the bound is
    ``max(rho - r, 0)``, as if the path were where the ray meets the annulus,
    whatever the timing. Returns the bound and its unit gradient in ``q``.

    >>> d, n = ray_floor(np.array([[0.0, 3.0]]), np.array([[1.0, 0.0]]),
    ...                  np.zeros((1, 2)), np.zeros(1), np.ones(1),
    ...                  np.array([1.0]), 1e-3)  # past a unit circle about (0, 1)
    >>> round(float(d[0]), 6), np.round(n[0], 6).tolist()
    (1.0, [0.0, 1.0])
    """
    beta = turn * dt
    half = np.sin(0.5 * beta)
    straight = np.abs(half) < STRAIGHT
    heading = np.stack((np.cos(course), np.sin(course)), -1)
    # straight: the exact closest approach of two constant velocities
    rel = q - start
    closing = velocity - speed[:, None] * heading
    cc = np.einsum("kd,kd->k", closing, closing)
    t = np.maximum(-np.einsum("kd,kd->k", rel, closing), 0.0) / np.maximum(cc, 1e-30)
    t = np.minimum(t, RAY_TAIL)
    near = rel + t[:, None] * closing
    flat = np.hypot(near[:, 0], near[:, 1])
    flat_n = near / np.maximum(flat, MIN_DIST)[:, None]
    # turning: the annulus
    big_r = speed * dt / (2.0 * np.where(straight, 1.0, half))
    centre = start + big_r[:, None] * (heading[:, ::-1] * [-1.0, 1.0])
    w = q - centre
    vv = np.hypot(velocity[:, 0], velocity[:, 1])
    unit = velocity / np.maximum(vv, MIN_DIST)[:, None]
    ahead = np.einsum("kd,kd->k", w, unit)
    foot = np.where(ahead >= 0.0, 0.0, -ahead)
    low = w + foot[:, None] * unit  # the ray's point nearest to C
    rho = np.hypot(low[:, 0], low[:, 1])
    ring = np.maximum(rho - np.abs(big_r), 0.0)
    ring_n = low / np.maximum(rho, MIN_DIST)[:, None]
    dist = np.where(straight, flat, ring)
    return dist, np.where(straight[:, None], flat_n, ring_n)
