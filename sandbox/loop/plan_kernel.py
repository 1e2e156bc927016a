"""Which parts of the plan stage run as C calls: chosen once, when the loop is built.

Every period the formation stage (:class:`~sandbox.loop.formation.Formation`)
evaluates the formation law (with the loop's overwrite of the reference-tracking and
commanded rows) and the avoidance stage (:class:`~sandbox.loop.avoidance.Avoidance`)
the recovery strategy (with ``target = slot + shift``). With numpy these are some
thirty small calls, most of a small fleet's plan. Two optional C calls do the same,
where they cover the loop's configuration:

- the law, :class:`~sandbox.model.law_kernel.LawKernel`: a built-in law class of
  all worlds (one law, one leader index; not the re-forming worlds of
  :mod:`sandbox.loop.reforming`, not a world's own law, not several platoons),
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

from typing import TYPE_CHECKING, Any

from sandbox import accel
from sandbox.behaviour import pair_field
from sandbox.behaviour.pair_field import ShiftKernel
from sandbox.model.kernels import c_float64
from sandbox.model.law_kernel import LawKernel
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.registration import get

if TYPE_CHECKING:
    from sandbox.loop.avoidance import Avoidance
    from sandbox.loop.formation import Formation

#: The strategies :class:`~sandbox.behaviour.pair_field.ShiftKernel` computes.
KINDS = {
    "discontinuous": pair_field.DISCONTINUOUS,
    "continuous": pair_field.CONTINUOUS,
}


def law_kernel_of(formation: Formation, platoons: bool) -> LawKernel | None:
    """The C call of the formation stage's law, or None where numpy runs.

    Parameters
    ----------
    formation : Formation
        The stage as built: its law, whether each world has its own law
        (``per_world``) or re-forms apart (``reforming``), whether the law is a
        built-in class of :class:`~sandbox.model.laws.LawInputs` (``inputs``), the
        reference and its rows, the worlds' leaders.
    platoons : bool
        Whether the worlds have several platoons (``platoons:``).
    """
    if (
        formation.law is None
        or formation.per_world
        or formation.reforming is not None
        or platoons
        or not formation.inputs
        or (formation.reference is not None and formation.rows is None)
    ):
        return None
    return LawKernel.make(formation.law, int(formation.leaders[0]))


def shift_kernel_of(avoidance: Avoidance, platoons: bool) -> ShiftKernel | None:
    """The C call of the avoidance stage's strategy, or None where numpy runs.

    Parameters
    ----------
    avoidance : Avoidance
        The stage as built: the ``recovery:`` section (``rec``), the strategy's
        values (``params``), where it finds the static obstacles (``field``),
        whether it is called world by world (``per_world``) and a built-in one
        (``built_in``), the neighbour search.
    platoons : bool
        Whether the worlds have several platoons (``platoons:``).
    """
    name = avoidance.rec.strategy
    params = avoidance.params
    field = avoidance.field
    c = accel.module("pair_field")
    if (
        name not in KINDS
        or avoidance.per_world
        or not avoidance.built_in
        or not get("strategy", name).origin.startswith("built-in")
        or platoons
        or params.get("tangential", 0.0) != 0.0
        or type(field) is not ObstacleField
        or not field.empty
        or avoidance.neighbours is None
        or c is None
    ):
        return None
    return ShiftKernel(
        avoidance.neighbours,
        avoidance.rec.R,
        params.get("r"),
        KINDS[name],
        params["beta"],
        c,
    )


def reference_table(chunk: tuple[Any, ...] | None) -> tuple[Any, ...] | None:
    """A chunk of the reference's rows as the law's C call reads them.

    Parameters
    ----------
    chunk : tuple of 3 ndarray (T, 2), or None
        The reference's points and their first and second derivatives.
    """
    if chunk is None:
        return None
    return tuple(c_float64(a) for a in chunk)
