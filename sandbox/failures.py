"""Failures of a vehicle, selected by name (``failures:`` in a scenario).

A failure kind maps the controller's commands of the failed vehicle to the commands it
really applies. Kinds:

- ``stuck_steering``: v2 frozen (at its value at onset, or the given ``v2``); v1 still
  controlled;
- ``stop``: motors stop, v1 = v2 = 0: the vehicle brakes with its motor's force
  (mass x ``motor_accel``, not the controller's ``max_accel``), and can still be shoved
  by a contact stronger than that (measured: a pusher with twice the motor force moves
  it at the pusher's own speed, one with an equal force at about half of it, one with
  half the force not at all);
- ``spin``: v1 = 0, v2 = the given rate (default 1 rad/s);
- ``uncontrolled``: constant commands ``v1``, ``v2`` (default 0);
- ``crash``: the vehicle is wrecked: it stops at once and becomes immovable (permanent).

When a failure clears (``until``), the vehicle resumes its law from where it is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sandbox.scenario import FailureSpec

#: ``commands(v1_ctrl, v2_ctrl, v2_onset, spec) -> (v1, v2)``, scalars for one vehicle.
Commands = Callable[[float, float, float, FailureSpec], tuple[float, float]]


@dataclass(frozen=True)
class FailureKind:
    """How a failure kind acts on a vehicle.

    Attributes
    ----------
    commands : callable
        Maps the controller's ``(v1, v2)``, the ``v2`` at onset and the spec to the
        applied
        ``(v1, v2)``.
    controlled_speed : bool
        Whether the controller still drives v1 (its extension states keep integrating).
    immovable : bool
        Whether the vehicle becomes a fixed obstacle.
    """

    commands: Commands
    controlled_speed: bool = False
    immovable: bool = False


FAILURE_KINDS: dict[str, FailureKind] = {}


def register_failure(
    name: str, *, controlled_speed: bool = False, immovable: bool = False
) -> Callable[[Commands], Commands]:
    """Decorator adding a failure kind by name."""

    def add(func: Commands) -> Commands:
        if name in FAILURE_KINDS:
            raise ValueError(f"failure kind {name!r} is already registered")
        FAILURE_KINDS[name] = FailureKind(func, controlled_speed, immovable)
        return func

    return add


@register_failure("stuck_steering", controlled_speed=True)
def stuck_steering(v1: float, v2: float, v2_onset: float, spec: FailureSpec):
    """Steering frozen: v2 held at its onset value (or ``spec.v2``); v1 controlled."""
    return v1, (spec.v2 if spec.v2 is not None else v2_onset)


@register_failure("stop")
def stop(v1: float, v2: float, v2_onset: float, spec: FailureSpec):
    """Motors stopped: the vehicle brakes to rest."""
    return 0.0, 0.0


@register_failure("spin")
def spin(v1: float, v2: float, v2_onset: float, spec: FailureSpec):
    """Spinning in place at ``spec.v2`` [rad/s]."""
    return 0.0, spec.v2 if spec.v2 is not None else 1.0


@register_failure("uncontrolled")
def uncontrolled(v1: float, v2: float, v2_onset: float, spec: FailureSpec):
    """Running away with constant commands ``spec.v1``, ``spec.v2``."""
    return spec.v1 or 0.0, spec.v2 or 0.0


@register_failure("crash", immovable=True)
def crash(v1: float, v2: float, v2_onset: float, spec: FailureSpec):
    """Wrecked: at rest for good."""
    return 0.0, 0.0


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
        self.kinds = [FAILURE_KINDS[s.kind] for s in specs]
        self.v2_onset = np.zeros(len(specs))
        self.started = np.zeros(len(specs), dtype=bool)
        self.n = len(names)

    def active(self, t: float) -> np.ndarray:
        """Which failures are active at time ``t`` [s], shape (k,), bool."""
        return (self.start <= t + 1e-12) & (t + 1e-12 < self.end)

    def start_new(self, t: float, last_v2: np.ndarray) -> np.ndarray:
        """Indices of the failures that start at this step (each reported once).

        Records the steering command each had at onset (``last_v2``, shape (n,)).
        """
        new = np.flatnonzero(self.active(t) & ~self.started)
        self.started[new] = True
        self.v2_onset[new] = last_v2[self.vehicle[new]]
        return new

    def apply(
        self, t: float, v1: np.ndarray, v2: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Apply the active failures to the fleet's commands.

        Parameters
        ----------
        t : float [s]
        v1, v2 : ndarray, shape (n,)
            The controller's commands.

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
            kind = self.kinds[k]
            v1[i], v2[i] = kind.commands(v1[i], v2[i], self.v2_onset[k], self.specs[k])
            failed[i] = True
            frozen[i] |= not kind.controlled_speed
        return v1, v2, failed, frozen

    def immovable(self, onsets: np.ndarray) -> list[int]:
        """Vehicles that become immovable among the given failure indices."""
        return [int(self.vehicle[k]) for k in onsets if self.kinds[k].immovable]
