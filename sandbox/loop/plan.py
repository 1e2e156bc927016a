"""What a control period plans (:class:`Plan`), and which runs may share one loop.

:func:`structure_key` is what the scenarios stepped together by
:meth:`Simulation.stacked <sandbox.loop.simulation.Simulation.stacked>` must share:
the vehicle count and leader, the time step, duration, substeps and recording, the
reference, the law, the strategy and its parameters but ``beta``, the obstacles, the
gains and limits, which sections are switched on (sensing, a safety filter, a
detector, a reconfiguration) and every scenario section not named free below. Free,
world by world: poses, offsets, sizes, masses, motors, ``beta``, failures, seeds,
the sensing, filter and detector values, the metrics settings. A fleet above
:data:`~sandbox.geometry.neighbours.BRUTE_FORCE_MAX` vehicles is a structure of its
own (its neighbours come from a Verlet list). Range sensors are cast world by world
in the one loop, each world in its own physics, and several platoons
(``platoons:``) are planned world by world, each world's platoons its own (their
references free).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from sandbox.geometry.neighbours import BRUTE_FORCE_MAX
from sandbox.run.record import MODE_AVOID, MODE_FAILED, MODE_FORMATION
from sandbox.scenario import Scenario

#: Scenario fields that may differ between the worlds of one loop (read per world),
#: or that enter :func:`structure_key` through what is derived from them.
FREE_FIELDS = frozenset(
    {
        "name",
        "description",
        "seed",
        "vehicles",
        "failures",
        "metrics",
        "platoon",
        "source",
        "warnings",
        "expect",
        "sensing",
        "safety",
        "detection",
        "recovery",
        "diameter",
    }
)


def structure_key(sc: Scenario, reference: bool = True) -> str:
    """What the scenarios of one loop share (see the module docstring), as a string.

    ``reference=False`` leaves the reference out (a platoon's: each world evaluates
    its own platoons' references).
    """
    vs = sc.vehicles
    n = len(vs)
    if n > BRUTE_FORCE_MAX:
        return f"large fleet {id(sc)}"
    rec = sc.recovery
    sensing = sc.sensing
    if sc.platoons:  # the platoons' references are each world's own
        reference = False
    parts = [
        (f.name, getattr(sc, f.name))
        for f in dataclasses.fields(sc)
        if f.name not in FREE_FIELDS | {"platoons"}
        and (reference or f.name != "reference")
    ]
    # Each platoon's structure, as a scenario's (its starts and seed free).
    parts.append(
        tuple(
            (g.name, tuple(g.rows), structure_key(g.scenario, reference=False))
            for g in sc.platoons
        )
    )
    parts += [
        n,
        sc.leader_index,
        tuple(v.drive.type for v in vs),
        tuple(v.leader for v in vs),
        rec.strategy,
        rec.R,
        rec.leader_avoids,
        rec.target_derivatives,
        rec.obstacles,
        tuple(sc.range_specs()),
        sorted((k, v) for k, v in rec.params.items() if k != "beta"),
        bool(
            sensing.position_noise
            or sensing.heading_noise
            or sensing.delay
            or sensing.loss
        ),
        sc.sensing.delay,
        sc.safety.filter,
        sc.detection.method,
    ]
    if sc.safety.filter != "none":  # one filter call: the fleet-wide values shared
        parts += [sc.safety, tuple(v.diameter for v in vs), sc.sensing]
    for key in ("k1", "k2", "k3", "k4", "kp"):
        parts.append(_same(getattr(v.gains, key) for v in vs))
    for key in ("v1_max", "v2_max", "max_accel"):
        parts.append(_same(getattr(v, key) for v in vs))
    return repr(parts)


def _same(values) -> object:
    """One value when all are equal (a fleet-wide setting), else the tuple."""
    values = tuple(values)
    return values[0] if all(v == values[0] for v in values) else values


@dataclass
class Plan:
    """What the built-in stack plans for one period, arrays indexed by row.

    Attributes
    ----------
    slot, target : ndarray, shape (N, 2) [m]
        Formation slots, and the slots shifted by recovery; NaN where undefined.
    v_ref, a_ref : ndarray, shape (N, 2) [m/s], [m/s^2]
        The feed-forward of ``target``: the law's ``x_ref'``, ``x_ref''`` (plus the
        shift's, when estimated).
    point : ndarray, shape (2,) or (K, 2) [m]
        The reference point (NaN without a reference).
    active : ndarray, shape (N,), bool
        Vehicles whose target recovery shifts.
    failing : ndarray, shape (N,), bool
        Vehicles with an active failure.
    slot_vel, slot_acc : ndarray, shape (N, 2) [m/s], [m/s^2], or None
        The law's ``x_ref'``, ``x_ref''`` alone, the slot's motion (None: ``v_ref``
        and ``a_ref``, no shift's added).
    """

    slot: np.ndarray
    target: np.ndarray
    v_ref: np.ndarray
    a_ref: np.ndarray
    point: np.ndarray
    active: np.ndarray
    failing: np.ndarray
    slot_vel: np.ndarray | None = None
    slot_acc: np.ndarray | None = None

    def slot_motion(self) -> tuple[np.ndarray, np.ndarray]:
        """The slot's velocity and acceleration, (N, 2) each [m/s], [m/s^2]."""
        if self.slot_vel is None:
            return self.v_ref, self.a_ref
        return self.slot_vel, self.slot_acc

    @classmethod
    def undefined(cls, n: int, failed: np.ndarray) -> Plan:
        """The plan of a diverged state: nothing defined."""
        nan = np.full((n, 2), np.nan)
        return cls(
            nan, nan, nan, nan, np.full(2, np.nan), np.zeros(n, bool), failed.copy()
        )

    def mode(self, n: int) -> np.ndarray:
        """Planned ``run.MODE_*`` codes, shape (n,), int8."""
        mode = np.full(n, MODE_FORMATION, dtype=np.int8)
        mode[self.active] = MODE_AVOID
        mode[self.failing] = MODE_FAILED
        return mode
