"""How a loop is built: K worlds of one structure, their values and their stages.

:func:`build` makes, from the scenarios of one structure
(:func:`~sandbox.loop.plan.structure_key`), everything a
:class:`~sandbox.loop.simulation.Simulation` steps: the layout of its worlds, the
stacked fleet, the physics of every world, the stages (formation, perception,
avoidance, safety, detection, failures, acting; which of the plan's C calls run is
chosen here, :mod:`sandbox.loop.plan_kernel`), the worlds' liveness and
descriptions, the record and the loop metrics (:class:`LoopParts`).
"""

from __future__ import annotations

from dataclasses import dataclass

from sandbox.loop.acting import Acting
from sandbox.loop.avoidance import Avoidance
from sandbox.loop.detecting import Detecting
from sandbox.loop.formation import Formation
from sandbox.loop.layout import Layout
from sandbox.loop.liveness import Liveness
from sandbox.loop.perception import Perception
from sandbox.loop.plan import structure_key
from sandbox.loop.plan_kernel import law_kernel_of, reference_table, shift_kernel_of
from sandbox.loop.platoon_sections import PlatoonSections
from sandbox.loop.recording import LoopRecord
from sandbox.loop.run_info import run_description
from sandbox.loop.safety import Safety
from sandbox.loop.state import Fleet, limits
from sandbox.loop.steering import SteeringRecord
from sandbox.loop.stepping import LoopPhysics
from sandbox.loop.tally import LoopTally
from sandbox.model.failures import Failures
from sandbox.model.laws import BatchDifference
from sandbox.model.obstacle_field import ObstacleField
from sandbox.physics.interface import Physics
from sandbox.physics.world import World
from sandbox.scenario import Scenario


@dataclass(frozen=True)
class LoopParts:
    """What a loop is made of (see the module docstring), each part its own owner.

    Attributes
    ----------
    layout : Layout
    fleet : Fleet
    physics : LoopPhysics
    formation : Formation
    perception : Perception
    avoidance : Avoidance
    safety : Safety
    detecting : Detecting
    failures : Failures
    acting : Acting
    liveness : Liveness
    record : LoopRecord
    steering : SteeringRecord or None
        The cars' steering angles of the record's samples (None: no car).
    tally : LoopTally
    shift_motion : BatchDifference
        The backward differences of the recovery shift (eqs. (18)-(19)), a history
        per world.
    """

    layout: Layout
    fleet: Fleet
    physics: LoopPhysics
    formation: Formation
    perception: Perception
    avoidance: Avoidance
    safety: Safety
    detecting: Detecting
    failures: Failures
    acting: Acting
    liveness: Liveness
    record: LoopRecord
    steering: SteeringRecord | None
    tally: LoopTally
    shift_motion: BatchDifference


def build(scenarios: list[Scenario], worlds: list[Physics | None]) -> LoopParts:
    """The parts of a loop of ``scenarios``, each world's physics ``worlds[w]``.

    A world's physics defaults to a pymunk :class:`~sandbox.physics.world.World` of
    its scenario's vehicles and obstacles.

    Raises
    ------
    ValueError
        The scenarios differ in structure.
    """
    if len({structure_key(sc) for sc in scenarios}) > 1:
        raise ValueError(
            "Simulation.stacked: the scenarios differ in structure; "
            "use Simulation.batch, which groups them"
        )
    layout = Layout.of(scenarios)
    K, n, h = layout.K, layout.n, layout.h
    physics = [
        w
        if w is not None
        else World(sc.vehicles, sc.obstacles, sc.metrics.contact_release, sc.substeps)
        for sc, w in zip(scenarios, worlds, strict=True)
    ]
    fleet = Fleet.stack([Fleet.from_scenario(sc) for sc in scenarios])
    loop_physics = LoopPhysics(physics, n, layout.substeps)
    obstacles = ObstacleField(scenarios[0].obstacles)
    perception = Perception(layout, physics, obstacles)
    formation = Formation(layout, fleet, perception.context)
    world_limits = [limits(fleet, layout.rows(w)) for w in range(K)]
    safety = Safety(layout, perception, obstacles, limits(fleet), world_limits)
    sections = None
    platoons = formation.platoons
    if platoons is not None:  # each platoon's recovery and filter on its rows
        sections = PlatoonSections.build(
            platoons, perception.sensing, safety.world_stats
        )
        safety.use_platoons(
            sections, [p.filter if p.filtered else None for p in platoons]
        )
    avoidance = Avoidance(
        layout,
        perception,
        obstacles,
        None if sections is None else sections.strategy,
        None if platoons is None else [p.strategy for p in platoons],
    )
    detecting = Detecting(layout, perception, loop_physics)
    failures = Failures(
        [
            (sc.failures, list(names))
            for sc, names in zip(scenarios, layout.names, strict=True)
        ],
        n,
    )
    acting = Acting(layout, fleet, safety, detecting, failures)
    info = []
    for w, sc in enumerate(scenarios):
        reference = sc.reference.build() if sc.reference else None
        description = run_description(sc, reference)
        if platoons is not None:
            description.update(platoons[w].records())
        reconfiguration = formation.reconfigurations[w]
        if reconfiguration is not None:
            description.update(reconfiguration.records())
        info.append(description)
    # the plan's law and strategy as C calls where they cover them (plan_kernel)
    formation.kernel = law_kernel_of(formation, platoons is not None)
    formation.kernel_table = reference_table
    avoidance.kernel = shift_kernel_of(avoidance, platoons is not None)
    avoidance.kernel_strategy = avoidance.strategy  # what the C call replaces
    capacity = layout.steps // layout.record_every + 1
    return LoopParts(
        layout=layout,
        fleet=fleet,
        physics=loop_physics,
        formation=formation,
        perception=perception,
        avoidance=avoidance,
        safety=safety,
        detecting=detecting,
        failures=failures,
        acting=acting,
        liveness=Liveness(info),
        record=LoopRecord(capacity, K, n),
        steering=SteeringRecord.build(fleet, capacity, K, n),
        tally=LoopTally(K, n, h),
        shift_motion=BatchDifference(h, K),
    )
