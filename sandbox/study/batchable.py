"""Which runs may share a batch of :mod:`sandbox.study.batch`, and with which others.

:func:`batch_reason` says why a freshly built simulation cannot run in a batch (what
the batch does not implement: a plug-in law or strategy, sensing, a safety filter, a
detector, command schedules, many vehicles, a record on disk, any scenario section it
does not know set to a non-default value); :func:`batch_key` is what the runs of one
batch must share (their structure).
"""

from __future__ import annotations

import dataclasses

from sandbox.geometry.neighbours import BRUTE_FORCE_MAX
from sandbox.loop.simulation import Simulation
from sandbox.model.laws import (
    FixedFormation,
    LeaderReferenceFormation,
    OwnEstimateFormation,
    RotatingFormation,
    VirtualLeaderFormation,
)
from sandbox.model.references import CircleReference, LineReference, PointReference
from sandbox.physics.world import World

#: The laws the batch evaluates (the built-in classes; a plug-in runs alone).
BATCH_LAWS = (
    FixedFormation,
    RotatingFormation,
    VirtualLeaderFormation,
    LeaderReferenceFormation,
    OwnEstimateFormation,
)
#: References evaluated for all step times at once (elementwise in t).
TABULATED_REFERENCES = (PointReference, LineReference, CircleReference)
#: The built-in strategies (functions of :mod:`sandbox.behaviour.recovery`).
BATCH_STRATEGIES = ("none", "discontinuous", "continuous", "smooth")
#: Most vehicles per world: all pairs are then the neighbour candidates, as alone.
MAX_VEHICLES = BRUTE_FORCE_MAX
#: The scenario keys the batch implements; any other key must hold its default.
KNOWN_FIELDS = frozenset(
    {
        "name",
        "description",
        "duration",
        "dt",
        "substeps",
        "seed",
        "record_every",
        "vehicles",
        "reference",
        "formation",
        "recovery",
        "failures",
        "obstacles",
        "platoon",
        "metrics",
        "diameter",
        "source",
        "warnings",
        "plugins",
        "expect",
        "sensing",
    }
)


def batch_reason(sim: Simulation) -> str | None:
    """Why ``sim`` cannot run in a batch, or None when it can.

    ``sim`` is a freshly built :class:`~sandbox.loop.simulation.Simulation` (step 0
    sensed and planned, nothing stepped).
    """
    sc = sim.scenario
    if type(sim) is not Simulation or type(sim.world) is not World:
        return "a custom simulation or physics"
    if sim.k != 0 or sim.done:
        return "not a fresh run"
    for f in dataclasses.fields(sc):
        if f.name in KNOWN_FIELDS:
            continue
        default = f.default
        if f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        if default is dataclasses.MISSING or getattr(sc, f.name) != default:
            return f"the {f.name!r} section"
    if sim.broadcast is not None:
        return "sensing"
    if getattr(sim, "range_sensor", None) is not None:
        return "range sensors"
    if getattr(sim, "_filter", None) is not None:
        return "the safety filter"
    if getattr(sim, "detection", None) is not None:
        return "detection"
    if sc.plugins:
        return "plug-ins"
    if sim.fleet.commanded.any():
        return "command schedules"
    if sim.law is not None and type(sim.law) not in BATCH_LAWS:
        return f"the law {sc.formation.law!r}"
    strategy = sc.recovery.strategy
    if (
        strategy not in BATCH_STRATEGIES
        or sim.strategy.__module__ != "sandbox.behaviour.recovery"
    ):
        return f"the strategy {strategy!r}"
    for kind in sim.failures.kinds:
        if kind.obj.__module__ != "sandbox.model.failures":
            return f"the failure {kind.name!r}"
    if sim.fleet.n > MAX_VEHICLES:
        return f"more than {MAX_VEHICLES} vehicles"
    if sim.recorder.on_disk:
        return "a record on disk"
    return None


def batch_key(sim: Simulation) -> str:
    """What runs of one batch must share (structure); they may differ in the rest.

    Shared: vehicle count and leader, time step, duration, substeps, recording, the
    reference, the law, the strategy and its parameters but ``beta``, the obstacles,
    and the gains and limits. Free: poses, offsets, sizes, masses, motors, ``beta``,
    failures, seeds, metrics settings.
    """
    sc, rec = sim.scenario, sim.scenario.recovery
    params = {k: v for k, v in sorted(sim.strategy_params.items()) if k != "beta"}
    parts = (
        sim.fleet.n,
        sim.leader,
        sc.dt,
        sim.steps,
        sc.substeps,
        sc.record_every,
        sc.reference,
        sc.formation,
        rec.strategy,
        params,
        rec.R,
        rec.leader_avoids,
        rec.target_derivatives,
        sc.obstacles,
        sim._gains,
        sim._v1_max,
        sim._v2_max,
        sim._accel_max,
        sim._turn_max is None,
        sim.tracks_reference.tobytes(),
        sim._avoid_candidates.tobytes(),
    )
    return repr(parts)
