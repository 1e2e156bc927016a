"""Which parts of the plan stage run as C calls: chosen once, when the loop is built.

Every period :meth:`Simulation._plan <sandbox.loop.simulation.Simulation._plan>`
evaluates the formation law (with the loop's overwrite of the reference-tracking and
commanded rows) and the recovery strategy (with ``target = slot + shift``). With
numpy these are some thirty small calls, most of a small fleet's plan. Two optional
C calls do the same, where they cover the loop's configuration:

- the law, :class:`~sandbox.model.law_kernel.LawKernel`: a built-in law class of
  all worlds (one law, one leader index; not the re-forming worlds of
  :mod:`sandbox.loop.stacked_law`, not a world's own law, not several platoons),
  with the reference's table (every built-in reference) or none;
- the strategy, :class:`~sandbox.behaviour.pair_field.ShiftKernel`: the built-in
  ``discontinuous`` and ``continuous`` strategies called once for all worlds,
  without the tangential term and without obstacles to avoid (an empty map).

Everything else keeps the numpy path: plug-in laws and strategies, the ``smooth``
weight, the tangential term, obstacles, platoons and reconfiguration. Each C call
is used only where its compiled path (``laws``, ``pair_field``; :mod:`sandbox.accel`)
is on; the two agree with the numpy path within rtol 1e-12
(``tests/test_compiled_paths.py`` compares whole runs).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sandbox import accel
from sandbox.behaviour import pair_field
from sandbox.behaviour.pair_field import ShiftKernel
from sandbox.model.kernels import c_float64
from sandbox.model.law_kernel import LawKernel
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.registration import get

if TYPE_CHECKING:
    from sandbox.loop.simulation import Simulation

#: The strategies :class:`~sandbox.behaviour.pair_field.ShiftKernel` computes.
_KINDS = {
    "discontinuous": pair_field.DISCONTINUOUS,
    "continuous": pair_field.CONTINUOUS,
}


def law_kernel_of(sim: Simulation) -> LawKernel | None:
    """The C call of the loop's law, or None where the numpy path runs."""
    if (
        sim.law is None
        or sim._law_per_world
        or sim._stacked_law is not None
        or sim.platoons is not None
        or not sim._law_inputs
        or (sim.reference is not None and sim._ref_table is None)
    ):
        return None
    return LawKernel.make(sim.law, sim.leader)


def shift_kernel_of(sim: Simulation) -> ShiftKernel | None:
    """The C call of the loop's strategy, or None where the numpy path runs."""
    name = sim.scenario.recovery.strategy
    params = sim.strategy_params
    field = sim._avoid_field
    if (
        name not in _KINDS
        or sim._strategy_per_world
        or not sim._strategy_built_in
        or not get("strategy", name).origin.startswith("built-in")
        or sim.platoons is not None
        or params.get("tangential", 0.0) != 0.0
        or type(field) is not ObstacleField
        or not field.empty
        or sim.neighbours is None
        or accel.module("pair_field") is None
    ):
        return None
    return ShiftKernel(
        sim.neighbours,
        sim.rec.R,
        params.get("r"),
        _KINDS[name],
        params["beta"],
        accel.module("pair_field"),
    )


def reference_table(sim: Simulation) -> tuple | None:
    """The reference's table as the law's C call reads it (C-contiguous float64)."""
    if sim._ref_table is None:
        return None
    return tuple(c_float64(a) for a in sim._ref_table)
