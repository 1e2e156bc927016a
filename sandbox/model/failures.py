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

from typing import TYPE_CHECKING

import numpy as np

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


class FailureSchedule:
    """The failures of a scenario, resolved to vehicle indices and kinds.

    The loop applies the schedules of all its worlds at once
    (:class:`~sandbox.loop.worlds.StackedFailures`).

    Parameters
    ----------
    specs : sequence of FailureSpec
    names : list of str
        Vehicle names, in fleet order.
    """

    def __init__(self, specs: tuple[FailureSpec, ...], names: list[str]) -> None:
        index = {name: i for i, name in enumerate(names)}
        self.specs = specs
        self.vehicle = np.array([index[s.vehicle] for s in specs], dtype=np.intp)
        self.start = np.array([s.at for s in specs], dtype=float)
        self.end = np.array(
            [s.until if s.until is not None else np.inf for s in specs], dtype=float
        )
        self.kinds = [get("failure", s.kind) for s in specs]
        #: The failure functions as the loop calls them (a user's code guarded).
        self.funcs = [runnable(kind) for kind in self.kinds]
        self.names = list(names)
        self.n = len(names)
