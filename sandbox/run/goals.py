"""A moving-target law measured against its goals (``metrics.json`` ``formation_goal``).

The laws ``potential`` and ``flocking`` (:mod:`sandbox.model.moving_target`) hand the
controller a moving target as each vehicle's slot, which the vehicle tracks closely
from the start: the run's formation errors, settling times, ``converged`` and
``deadlocks`` measure that tracking, not whether the formation formed. This module adds
the same metrics against the laws' goals, each vehicle's place on the virtual leader's
formation (eqs. (13)-(15) of the report: the reference point plus the offset, turned by
the reference's tangent with ``rotate``; the leader's is the reference point), under
the key ``formation_goal``: ``vehicles`` (each vehicle's ``formation_error`` and
``settling_time``), ``converged`` and ``deadlocks``, by
:func:`~sandbox.run.metrics.compute_metrics` itself on the run with its slots replaced
by the goals. Runs of other laws, and runs with ``platoons:`` or a reconfiguration
(whose goals change with events), get no such block.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from sandbox.model.laws import REST_SPEED, rotate_offsets
from sandbox.model.moving_target import MOVING_TARGET_LAWS
from sandbox.plugins.registration import register_metrics
from sandbox.run.metrics import compute_metrics
from sandbox.run.record import Run

#: Marks the copy of a run whose metrics are taken against the goals.
GOAL_COPY = "formation_goal_copy"


def goal_slots(run: Run) -> np.ndarray | None:
    """Each vehicle's goal at each sample [m], shape (T, n, 2); None where undefined.

    Undefined: another law, no reference, ``platoons:``, or a reconfiguration.
    """
    sc = run.scenario
    formation = getattr(sc, "formation", None)
    if formation is None or formation.law not in MOVING_TARGET_LAWS:
        return None
    if sc.reference is None or getattr(sc, "platoons", None):
        return None
    if run.info.get("reassignments") or run.info.get("leader_changes"):
        return None
    t = np.asarray(run.t, dtype=float)
    p, dp, _ = sc.reference.build().evaluate(t)
    p = np.asarray(p, dtype=float).reshape(len(t), 2)
    dp = np.asarray(dp, dtype=float).reshape(len(t), 2)
    offset = np.array([v.offset for v in sc.vehicles], dtype=float)
    if formation.params.get("rotate"):
        # eq. (15), its last defined angle held while the reference rests (0 at first)
        defined = np.hypot(dp[:, 0], dp[:, 1]) >= REST_SPEED
        angle = np.where(defined, np.arctan2(dp[:, 1], dp[:, 0]), 0.0)
        last = np.maximum.accumulate(np.where(defined, np.arange(len(t)), -1))
        angle = np.where(last >= 0, angle[np.maximum(last, 0)], 0.0)
        offset = rotate_offsets(offset[None, :, :], angle[:, None])  # eq. (14)
    goal = p[:, None, :] + offset
    if run.leader >= 0:  # the leader tracks the reference itself
        goal[:, run.leader] = p
    return goal


@register_metrics("formation_goal")
def goal_metrics(run: Run) -> dict[str, Any]:
    """The ``formation_goal`` block of a moving-target law's run (else nothing)."""
    if run.info.get(GOAL_COPY):
        return {}
    goal = goal_slots(run)
    if goal is None:
        return {}
    copy = replace(run, slot=goal, info={**run.info, GOAL_COPY: True})
    metrics = compute_metrics(copy)
    vehicles = {
        name: {
            "formation_error": m["formation_error"],
            "settling_time": m["settling_time"],
        }
        for name, m in metrics["vehicles"].items()
    }
    return {
        "formation_goal": {
            "vehicles": vehicles,
            "converged": metrics["converged"],
            "deadlocks": metrics["deadlocks"],
        }
    }
