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


def within_drive(v1: float, last_v1: float, step: float) -> float:
    """The speed [m/s] a drive applies when a failure asks for ``v1`` [m/s].

    Within ``step`` = ``max_accel h`` [m/s] of the last period's ``last_v1``.

    >>> within_drive(0.0, 1.0, 0.05), within_drive(0.0, 1.0, float("inf"))
    (0.95, 0.0)
    """
    return min(max(v1, last_v1 - step), last_v1 + step)


class FailureSchedule:
    """The failures of a scenario, resolved to vehicle indices.

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
        self.v2_onset = np.zeros(len(specs))
        self.started = np.zeros(len(specs), dtype=bool)
        self.n = len(names)

    def active(self, t: float) -> np.ndarray:
        """Which failures are active at time ``t`` [s], shape (k,), bool."""
        return (self.start <= t + 1e-12) & (t + 1e-12 < self.end)

    def active_vehicles(self, t: float) -> np.ndarray:
        """Which vehicles have an active failure at time ``t`` [s], shape (n,) bool."""
        out = np.zeros(self.n, dtype=bool)
        out[self.vehicle[self.active(t)]] = True
        return out

    def start_new(self, t: float, last_v2: np.ndarray) -> np.ndarray:
        """Indices of the failures that start at this step (each reported once).

        Records the steering command each had at onset (``last_v2``, shape (n,)).
        """
        new = np.flatnonzero(self.active(t) & ~self.started)
        self.started[new] = True
        self.v2_onset[new] = last_v2[self.vehicle[new]]
        return new

    def apply(
        self,
        t: float,
        v1: np.ndarray,
        v2: np.ndarray,
        last_v1: np.ndarray | None = None,
        accel_step: float | np.ndarray = np.inf,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Apply the active failures to the fleet's commands.

        Parameters
        ----------
        t : float [s]
        v1, v2 : ndarray, shape (n,)
            The controller's commands.
        last_v1 : ndarray, shape (n,), optional
            The speeds applied in the last period [m/s] (None: no limit).
        accel_step : float or ndarray (n,)
            The most the drive changes v1 in one period [m/s], ``max_accel h``
            (inf: unlimited). A failure's v1 is held within ``last_v1 +-
            accel_step``, except for an immovable kind (a crash).

        Returns
        -------
        v1, v2 : ndarray, shape (n,)
            Applied commands.
        failed : ndarray, shape (n,), bool
            Vehicles with an active failure.
        frozen : ndarray, shape (n,), bool
            Failed vehicles whose speed the controller no longer drives.
        """
        failed = np.zeros(self.n, dtype=bool)
        frozen = np.zeros(self.n, dtype=bool)
        if not len(self.specs):
            return v1, v2, failed, frozen
        v1, v2 = v1.copy(), v2.copy()
        for k in np.flatnonzero(self.active(t)):
            i = self.vehicle[k]
            kind, spec = self.kinds[k], self.specs[k]
            ctx = FailureContext(
                t=t,
                since=t - spec.at,
                vehicle=spec.vehicle,
                index=int(i),
                v1=float(v1[i]),
                v2=float(v2[i]),
                v2_onset=float(self.v2_onset[k]),
                params=dict(spec.params),
            )
            v1[i], v2[i] = self.funcs[k](ctx)
            if last_v1 is not None and not kind.options["immovable"]:
                step = float(np.broadcast_to(accel_step, (self.n,))[i])
                v1[i] = within_drive(float(v1[i]), float(last_v1[i]), step)
            failed[i] = True
            frozen[i] |= not kind.options["controlled_speed"]
        return v1, v2, failed, frozen

    def immovable(self, onsets: np.ndarray) -> list[int]:
        """Vehicles that become immovable among the given failure indices."""
        return [
            int(self.vehicle[k]) for k in onsets if self.kinds[k].options["immovable"]
        ]
