"""Failures of a vehicle, selected by name (``failures:`` in a scenario).

A failure kind maps the controller's commands of the failed vehicle to the commands it
really applies. Kinds:

- ``stuck_steering``: v2 frozen (at its value at onset, or the given ``v2``); v1 still
  controlled;
- ``stop``: the drive stops, v1 = v2 = 0: the vehicle brakes to rest within its own
  limits (see below), and can still be shoved by a contact stronger than its motor
  (mass x ``motor_accel``; measured: a pusher with twice the motor force moves it at
  the pusher's own speed, one with an equal force at about half of it, one with half
  the force not at all);
- ``spin``: v1 = 0, v2 = the given rate (default 1 rad/s);
- ``uncontrolled``: constant commands ``v1``, ``v2`` (default 0);
- ``crash``: the vehicle is wrecked: it stops at once and becomes immovable (permanent).

Every kind but a ``crash`` is a fault of the vehicle's controller or drive, and the
drive executes what the failure asks for as it executes any command: the speed v1 it
applies moves from the last period's by at most ``max_accel h`` (the vehicle's declared
acceleration limit; at once when it declares none, as the report's robot), and the
physical motor (``motor_accel``) bounds it further. A stop from 1 m/s at ``max_accel:
5`` therefore takes 0.2 s and 0.1 m. A ``crash`` is an impact, not a command: the
vehicle stops within one physics substep, a deceleration no drive makes, which is how
a detector tells a crash from a stop (:mod:`sandbox.behaviour.detection`).

When a failure clears (``until``), the vehicle resumes its law from where it is.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from sandbox.errors import PluginRunError
from sandbox.plugins.registration import (
    FailureContext,
    Param,
    get,
    register_failure,
    runnable,
)

if TYPE_CHECKING:
    from sandbox.scenario import FailureSpec

#: ``v2`` of stuck_steering: the frozen turn rate (default: its value at onset).
_V2 = Param("number", None, unit="rad/s", doc="Frozen turn rate (default: at onset)")


@register_failure("stuck_steering", {"v2": _V2}, controlled_speed=True)
def stuck_steering(ctx: FailureContext) -> tuple[float, float]:
    """Steering frozen: v2 held at its onset value (or ``v2``); v1 controlled."""
    v2 = ctx.params.get("v2")
    return ctx.v1, (v2 if v2 is not None else ctx.v2_onset)


@register_failure("stop")
def stop(ctx: FailureContext) -> tuple[float, float]:
    """Motors stopped: the vehicle brakes to rest."""
    return 0.0, 0.0


@register_failure("spin", {"v2": Param("number", 1.0, unit="rad/s", doc="Turn rate")})
def spin(ctx: FailureContext) -> tuple[float, float]:
    """Spinning in place at ``v2`` [rad/s] (default 1)."""
    return 0.0, ctx.params["v2"]


@register_failure(
    "uncontrolled",
    {
        "v1": Param("number", unit="m/s", doc="Constant speed"),
        "v2": Param("number", 0.0, unit="rad/s", doc="Turn rate"),
    },
)
def uncontrolled(ctx: FailureContext) -> tuple[float, float]:
    """Running away with constant commands ``v1`` (required), ``v2`` (default 0)."""
    return ctx.params["v1"] or 0.0, ctx.params["v2"] or 0.0


@register_failure("crash", immovable=True, permanent=True)
def crash(ctx: FailureContext) -> tuple[float, float]:
    """Wrecked: at rest for good."""
    return 0.0, 0.0


#: The built-in kinds as elementwise rules (:func:`ruled_commands`), by function.
_RULES = {stuck_steering: 1, stop: 2, crash: 2, spin: 3, uncontrolled: 4}


def rule_of(func, params: dict) -> tuple[int, float, float]:
    """``(rule, v1, v2)`` of a failure for :func:`ruled_commands`; rule 0: none.

    A built-in kind's function has a rule, its parameters given as numbers (NaN: a
    ``stuck_steering`` without ``v2``); any other function is called as it is.
    """
    rule = _RULES.get(func, 0)
    v1 = (params.get("v1") or 0.0) if rule == 4 else 0.0
    v2 = params.get("v2")
    if rule == 1:
        v2 = np.nan if v2 is None else v2
    else:
        v2 = (v2 or 0.0) if rule in (3, 4) else 0.0
    return rule, float(v1), float(v2)


def ruled_commands(
    rule: np.ndarray,
    v1_param: np.ndarray,
    v2_param: np.ndarray,
    v1: np.ndarray,
    v2_onset: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The commands of many built-in failures at once, the numbers of their functions.

    ``rule``, ``v1_param``, ``v2_param`` as :func:`rule_of` gives them, ``v1`` the
    controller's speed and ``v2_onset`` the turn rate at onset, one entry per failure.
    """
    out_v1 = np.where(rule == 1, v1, np.where(rule == 4, v1_param, 0.0))
    held = np.where(np.isnan(v2_param), v2_onset, v2_param)  # stuck_steering
    out_v2 = np.where(rule == 1, held, np.where(rule >= 3, v2_param, 0.0))
    return out_v1, out_v2


def within_drive(v1: float, last_v1: float, step: float) -> float:
    """The speed [m/s] a drive applies when a failure asks for ``v1`` [m/s].

    Within ``step`` = ``max_accel h`` [m/s] of the last period's ``last_v1``.

    >>> within_drive(0.0, 1.0, 0.05), within_drive(0.0, 1.0, float("inf"))
    (0.95, 0.0)
    """
    return min(max(v1, last_v1 - step), last_v1 + step)


def within_drives(v1: np.ndarray, last_v1: np.ndarray, step: np.ndarray) -> np.ndarray:
    """:func:`within_drive` elementwise: the numbers of Python's ``min`` and ``max``."""
    low, high = last_v1 - step, last_v1 + step
    v1 = np.where(low > v1, low, v1)  # max(v1, low): low only when strictly greater
    return np.where(high < v1, high, v1)


#: From this many active failures on, the built-in kinds are applied at once.
RULED_FROM = 4


class Failures:
    """The failures of K worlds of ``n`` vehicles, a row per failure (world by world).

    Each world's failures are resolved to its vehicles' stacked rows (``w n + i``)
    and kinds. The built-in kinds of every world are applied at once by their
    elementwise rules (:func:`ruled_commands`, from :data:`RULED_FROM` active
    failures on), a plug-in kind's function failure after failure (and all of them
    when one vehicle has two at once): the onsets, commands and acceleration limit
    of each world alone.

    Parameters
    ----------
    worlds : sequence of (sequence of FailureSpec, list of str)
        Each world's failures and its vehicle names, in fleet order.
    n : int
        Vehicles per world.
    """

    def __init__(
        self, worlds: Sequence[tuple[Sequence[FailureSpec], list[str]]], n: int
    ) -> None:
        world, vehicle, local, kinds, specs = [], [], [], [], []
        for w, (failures, names) in enumerate(worlds):
            index = {name: i for i, name in enumerate(names)}
            for spec in failures:
                world.append(w)
                local.append(index[spec.vehicle])
                vehicle.append(w * n + index[spec.vehicle])
                kinds.append(get("failure", spec.kind))
                specs.append(spec)
        self.world = np.array(world, dtype=np.intp)
        self.vehicle = np.array(vehicle, dtype=np.intp)
        self.local = np.array(local, dtype=np.intp)
        self.kinds, self.specs = kinds, specs
        #: The failure functions as the loop calls them (a user's code guarded).
        self.funcs = [runnable(kind) for kind in kinds]
        self.start = np.array([s.at for s in specs], dtype=float)
        self.end = np.array(
            [s.until if s.until is not None else np.inf for s in specs], dtype=float
        )
        self.started = np.zeros(len(specs), dtype=bool)
        self.v2_onset = np.zeros(len(specs))
        self.params = [dict(s.params) for s in specs]
        self.controlled = np.array(
            [k.options["controlled_speed"] for k in kinds], dtype=bool
        )
        self.immovable = np.array([k.options["immovable"] for k in kinds], dtype=bool)
        self.N = len(worlds) * n
        # The built-in kinds' elementwise rules (rule 0: the function is called).
        rules = [rule_of(f, p) for f, p in zip(self.funcs, self.params, strict=True)]
        self.rule = np.array([r[0] for r in rules], dtype=np.intp)
        self.v1_param = np.array([r[1] for r in rules], dtype=float)
        self.v2_param = np.array([r[2] for r in rules], dtype=float)
        # One failure a vehicle at most: every set of active failures is one a vehicle.
        self._one_each = len(np.unique(self.vehicle)) == len(self.vehicle)
        # The onsets and ends in order: between two of them the schedule is the same.
        self._bounds = sorted({*self.start.tolist(), *self.end.tolist()})
        self._on_at = -1
        self._on = np.zeros(len(specs), dtype=bool)
        self._waiting = len(specs)  # failures not started yet
        #: No vehicle of any world (read-only: the flags of a period without failures).
        self.none = np.zeros(self.N, dtype=bool)
        self.none.flags.writeable = False

    def __len__(self) -> int:
        return len(self.specs)

    def active(self, t: float, live: np.ndarray) -> np.ndarray:
        """Active failures of the live worlds at ``t`` [s] (one flag per failure)."""
        u = t + 1e-12
        at = bisect_right(self._bounds, u)  # the same flags between two bounds
        if at != self._on_at:
            self._on = (self.start <= u) & (u < self.end)
            self._on_at = at
        return self._on & live[self.world]

    def active_vehicles(self, t: float, live: np.ndarray) -> np.ndarray:
        """Rows with an active failure at ``t`` [s], shape (N,) bool."""
        out = np.zeros(self.N, dtype=bool)
        out[self.vehicle[self.active(t, live)]] = True
        return out

    def start_new(self, t: float, live: np.ndarray, last_v2: np.ndarray) -> np.ndarray:
        """The failures that start at ``t`` (each reported once), their onset noted."""
        if not self._waiting:
            return np.zeros(0, dtype=np.intp)
        new = (self.active(t, live) & ~self.started).nonzero()[0]
        self._waiting -= len(new)
        self.started[new] = True
        self.v2_onset[new] = last_v2[self.vehicle[new]]
        return new

    def apply(
        self,
        t: float,
        live: np.ndarray,
        v1: np.ndarray,
        v2: np.ndarray,
        last_v1: np.ndarray,
        accel_step: float | np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list]:
        """Every world's active failures applied: commands, failed and frozen rows.

        Also the ``(world, PluginRunError)`` of each world whose failure plug-in
        raised (that world's other failures are skipped; the caller ends it).
        """
        N = self.N
        errors: list[tuple[int, PluginRunError]] = []
        if not len(self.specs):  # no vehicle ever fails: shared read-only flags
            return v1, v2, self.none, self.none, errors
        failed = np.zeros(N, dtype=bool)
        frozen = np.zeros(N, dtype=bool)
        v1, v2 = v1.copy(), v2.copy()
        broken: set[int] = set()
        active = self.active(t, live).nonzero()[0]
        rows = self.vehicle[active]
        # Built-in kinds only, one a vehicle, enough of them to pay the numpy calls:
        # at once; else one after the other (the same numbers either way).
        if (
            len(active) >= RULED_FROM
            and self.rule[active].all()
            and (self._one_each or len(np.unique(rows)) == len(rows))
        ):
            self._apply_rules(active, v1, v2, last_v1, accel_step, failed, frozen)
            return v1, v2, failed, frozen, errors
        for k in active:
            w = int(self.world[k])
            if w in broken:
                continue
            i, spec = self.vehicle[k], self.specs[k]
            ctx = FailureContext(
                t=t,
                since=t - spec.at,
                vehicle=spec.vehicle,
                index=int(self.local[k]),
                v1=float(v1[i]),
                v2=float(v2[i]),
                v2_onset=float(self.v2_onset[k]),
                params=dict(self.params[k]),
            )
            try:
                v1[i], v2[i] = self.funcs[k](ctx)
            except PluginRunError as exc:
                broken.add(w)
                errors.append((w, exc))
                continue
            if not self.immovable[k]:  # within the drive's max_accel, as alone
                step = float(accel_step if np.ndim(accel_step) == 0 else accel_step[i])
                v1[i] = within_drive(float(v1[i]), float(last_v1[i]), step)
            failed[i] = True
            frozen[i] |= not self.controlled[k]
        return v1, v2, failed, frozen, errors

    def _apply_rules(self, ruled, v1, v2, last_v1, accel_step, failed, frozen) -> None:
        """The built-in failures ``ruled`` at once, each on its own vehicle."""
        i = self.vehicle[ruled]
        out_v1, out_v2 = ruled_commands(
            self.rule[ruled],
            self.v1_param[ruled],
            self.v2_param[ruled],
            v1[i],
            self.v2_onset[ruled],
        )
        step = np.broadcast_to(accel_step, (self.N,))[i]
        movable = ~self.immovable[ruled]  # within the drive's max_accel, as alone
        v1[i] = np.where(movable, within_drives(out_v1, last_v1[i], step), out_v1)
        v2[i] = out_v2
        failed[i] = True
        frozen[i] |= ~self.controlled[ruled]
