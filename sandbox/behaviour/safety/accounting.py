"""The CBF filter's counters of each world (``metrics.json`` ``safety``).

Split from :mod:`sandbox.behaviour.safety.cbf`, which adds each step of the filter
(:class:`FilterStep`) to the counters of each of its K stacked worlds (one for a
single run) through :func:`account_worlds`: each world's reductions taken at once
over a ``(K, n)`` view of the rows.

Where the compiled path ``filter`` is on (:mod:`sandbox.accel`), the reductions of
:func:`account_worlds` and the choice of the worlds it writes are one C loop over
the rows (``world_counts`` in ``_filter.c``: counts, maxima and minima), and only the
worlds whose counters change are touched from Python; :func:`account_worlds_numpy`
is the reference (``tests/test_compiled_paths.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox import accel
from sandbox.behaviour.safety.constrained import record_episodes
from sandbox.behaviour.safety.qp import TOLERANCE

if TYPE_CHECKING:
    from sandbox.plugins.contexts import FilterContext

#: What a step changed of a world's counters (``world_counts``' flags).
RAISED, LOWERED = 1, 2


@dataclass
class FilterStep:
    """What the filter did at one step (kept in the filter's memory as ``last``).

    Attributes
    ----------
    active : ndarray, shape (n,), bool
        Vehicles whose commands it changed.
    slack : ndarray, shape (n,) [m/s]
        The least largest violation of a barrier condition (0: feasible).
    rows : int
        Barrier conditions that could bind (after pruning).
    min_barrier : float
        The least barrier value of the step (``inf`` with none): [m] for
        ``braking`` (the least clearance if every vehicle brakes); [m^2] for
        ``velocity``.
    fallback : ndarray, shape (n,), bool
        Vehicles whose braking conditions had no common point (rounding only: the
        braking command keeps them all), which brake.
    by_vehicle : ndarray, shape (n,), or None
        Each vehicle's least barrier value (None: no vehicle filtered), whose
        least over a world's rows is the world's.
    """

    active: np.ndarray
    slack: np.ndarray
    rows: int
    min_barrier: float = np.inf
    fallback: np.ndarray | None = None
    by_vehicle: np.ndarray | None = None


def _add(
    stats: dict,
    t: float,
    braking: bool,
    active: int,
    bad: int,
    worst: float,
    least: float,
    fallen: int,
) -> None:
    """Add one step of a world to its counters ``stats``.

    The step's counts of vehicles (active, without a common point, fallen back to
    braking), its largest slack and its least barrier.
    """
    stats["active_steps"] = stats.get("active_steps", 0) + active
    stats["infeasible_steps"] = stats.get("infeasible_steps", 0) + bad
    stats["max_slack"] = max(stats.get("max_slack", 0.0), worst)
    finite = math.isfinite(least)
    if finite:
        known = stats.get("min_barrier")
        stats["min_barrier"] = least if known is None else min(known, least)
    if braking:
        stats["fallback_steps"] = stats.get("fallback_steps", 0) + fallen
    if "unsafe_start" not in stats:  # the first step: reported, never silently
        stats["unsafe_start"] = {
            "t": float(t),
            "min_barrier": least if finite else None,
            "unsafe": bool(least < -TOLERANCE),
        }


class RunningExtremes:
    """Each of K worlds' largest slack and least barrier so far, kept between steps.

    Copies of the worlds' counters ``max_slack`` and ``min_barrier``: with them a
    step finds, for all worlds at once, which world's counters it changes, and
    writes only those (most steps change few of them).

    Parameters
    ----------
    world_stats : list of dict
        The K worlds' counters as they stand (usually empty).
    """

    def __init__(self, world_stats: list[dict]) -> None:
        self.max_slack = np.array([s.get("max_slack", 0.0) for s in world_stats])
        known = [s.get("min_barrier") for s in world_stats]
        self.min_barrier = np.array([np.inf if m is None else m for m in known])
        self.started = False
        #: The C loop's outputs of a step (made at its first step).
        self.out: tuple[np.ndarray, ...] | None = None


def account_step(ctx: FilterContext, step: FilterStep, braking: bool) -> None:
    """A filter's step in its worlds' counters and constrained episodes.

    The step is kept as the filter's ``last`` (``ctx.memory``), added to each world's
    counters (:func:`account_worlds`, with the worlds' running extremes kept in the
    memory too) and its active vehicles to the episodes of
    :func:`~sandbox.behaviour.safety.constrained.record_episodes`. ``braking``: whether
    the filter's barrier is the braking one (its fallback steps counted).
    """
    ctx.memory["last"] = step
    # each world's own counters (one world's: ctx.stats, where no list is given)
    world_stats = [ctx.stats] if ctx.world_stats is None else ctx.world_stats
    extremes = ctx.memory.get("extremes")
    if extremes is None:
        extremes = ctx.memory["extremes"] = RunningExtremes(world_stats)
    n = len(ctx.pos) // ctx.worlds
    account_worlds(world_stats, ctx.t, braking, step, n, extremes)
    record_episodes(ctx.memory, world_stats, ctx.t, step.active, n)


def account_worlds(
    world_stats: list[dict],
    t: float,
    braking: bool,
    step: FilterStep,
    n: int,
    extremes: RunningExtremes,
) -> None:
    """Add one step of the filter to the counters of each of its K worlds.

    Each world's counters are those of its rows ``w n : (w + 1) n`` alone (counts,
    exact maxima and minima, as :func:`_add` adds a world's step); the reductions are
    taken for all worlds at once, and a world's counters are written where the step
    changes them (every world's at the first step).

    Parameters
    ----------
    world_stats : list of dict
        The K worlds' counters, in the order of their rows.
    t : float [s]
    braking : bool
        Whether the filter's barrier is ``braking`` (its fallback steps counted).
    step : FilterStep
        The step of the stacked rows, shape ``(K n,)`` each.
    n : int
        Vehicles per world.
    extremes : RunningExtremes
        The worlds' largest slack and least barrier so far (updated).
    """
    c = accel.module("filter")
    if c is not None and _account_c(c, world_stats, t, braking, step, extremes):
        return
    account_worlds_numpy(world_stats, t, braking, step, n, extremes)


def account_worlds_numpy(
    world_stats: list[dict],
    t: float,
    braking: bool,
    step: FilterStep,
    n: int,
    extremes: RunningExtremes,
) -> None:
    """:func:`account_worlds` by numpy (the reference)."""
    k = len(world_stats)
    active = step.active.reshape(k, n).sum(axis=1)
    slack = step.slack.reshape(k, n)
    bad = (slack > TOLERANCE).sum(axis=1)
    worst = slack.max(axis=1, initial=0.0)  # (0 when a world has no vehicle)
    if step.by_vehicle is None:
        least = np.full(k, np.inf)
    else:
        least = step.by_vehicle.reshape(k, n).min(axis=1, initial=np.inf)
    finite = np.isfinite(least)
    fallen = step.fallback.reshape(k, n).sum(axis=1) if braking else np.zeros(k, int)
    raised = worst > extremes.max_slack
    lowered = finite & (least < extremes.min_barrier)
    if extremes.started:
        touched = np.flatnonzero(
            (active > 0) | (bad > 0) | raised | lowered | (fallen > 0)
        )
    else:
        touched = np.arange(k)
    extremes.max_slack[raised] = worst[raised]
    extremes.min_barrier[lowered] = least[lowered]
    if len(touched) == 0:
        extremes.started = True
        return
    active, bad, worst = active.tolist(), bad.tolist(), worst.tolist()
    least, fallen = least.tolist(), fallen.tolist()
    for w in touched.tolist():
        _add(
            world_stats[w], t, braking, active[w], bad[w], worst[w], least[w], fallen[w]
        )
    extremes.started = True


def _account_c(
    c: Any,
    world_stats: list[dict],
    t: float,
    braking: bool,
    step: FilterStep,
    extremes: RunningExtremes,
) -> bool:
    """:func:`account_worlds` with its reductions in C; False where it cannot run.

    It cannot where an array is not C-contiguous of its type (bool, float64), the
    extremes' included (the numpy path takes them as they are). After the first
    step, which writes every counter of every world (:func:`_add`), a world's
    counters all exist, and ``extremes`` holds its largest slack and least barrier:
    what :func:`_add` then changes is the sums it adds to and the slack and barrier
    the step raised or lowered, and so the C path changes only those.
    """
    k = len(world_stats)
    if extremes.out is None or len(extremes.out[0]) != k:
        counts = tuple(np.zeros(k, dtype=np.intp) for _ in range(5))
        extremes.out = (*counts, np.zeros(k), np.zeros(k))
    active, bad, fallen, changes, touched, worst, least = extremes.out
    try:  # the C loop holds every buffer before it writes any
        count = c.world_counts(
            worlds=k,
            active=step.active,
            slack=step.slack,
            by_vehicle=step.by_vehicle,
            fallback=step.fallback if braking else None,
            max_slack=extremes.max_slack,
            min_barrier=extremes.min_barrier,
            started=extremes.started,
            out_active=active,
            out_bad=bad,
            out_worst=worst,
            out_least=least,
            out_fallen=fallen,
            out_changes=changes,
            touched=touched,
            tolerance=TOLERANCE,
        )
    except (TypeError, ValueError, BufferError):
        return False
    started, extremes.started = extremes.started, True
    if not count:
        return True
    rows = touched[:count]
    each = zip(
        rows.tolist(),
        active[rows].tolist(),
        bad[rows].tolist(),
        worst[rows].tolist(),
        least[rows].tolist(),
        fallen[rows].tolist(),
        changes[rows].tolist(),
        strict=True,
    )
    if not started:
        for w, on, failed, big, small, fell, _ in each:
            _add(world_stats[w], t, braking, on, failed, big, small, fell)
        return True
    for w, on, failed, big, small, fell, changed in each:
        stats = world_stats[w]
        if on:
            stats["active_steps"] += on
        if failed:
            stats["infeasible_steps"] += failed
        if changed & RAISED:
            stats["max_slack"] = big
        if changed & LOWERED:
            stats["min_barrier"] = small
        if fell:
            stats["fallback_steps"] += fell
    return True
