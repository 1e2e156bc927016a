"""The CBF filter's counters of one world (``metrics.json`` ``safety``).

Split from :mod:`sandbox.behaviour.safety.cbf`, which adds each step of the filter's
rows of a world to that world's counters through :func:`account`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.safety.qp import TOLERANCE

if TYPE_CHECKING:
    from sandbox.behaviour.safety.cbf import FilterStep


def account(
    stats: dict, t: float, braking: bool, step: FilterStep, rows: slice, least: float
) -> None:
    """Add one step of the filter's rows ``rows`` to a world's counters ``stats``."""
    active, slack = step.active[rows], step.slack[rows]
    stats["active_steps"] = stats.get("active_steps", 0) + int(active.sum())
    bad = slack > TOLERANCE
    stats["infeasible_steps"] = stats.get("infeasible_steps", 0) + int(bad.sum())
    worst = float(slack.max()) if len(slack) else 0.0
    stats["max_slack"] = max(stats.get("max_slack", 0.0), worst)
    if np.isfinite(least):
        known = stats.get("min_barrier")
        stats["min_barrier"] = least if known is None else min(known, least)
    if braking:
        braking_steps = int(step.fallback[rows].sum())
        stats["fallback_steps"] = stats.get("fallback_steps", 0) + braking_steps
    if "unsafe_start" not in stats:  # the first step: reported, never silently
        stats["unsafe_start"] = {
            "t": float(t),
            "min_barrier": least if np.isfinite(least) else None,
            "unsafe": bool(least < -TOLERANCE),
        }
