"""Fleet: the struct-of-arrays state of all vehicles of all worlds of a loop.

One array per quantity, indexed by row (``K n`` rows, world after world); one numpy
expression updates the whole fleet. No per-vehicle Python object is touched on the
hot path.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from sandbox.model.flatness import TRAVEL_NONE, Gains
from sandbox.scenario import Scenario


@dataclass
class Fleet:
    """State and parameters of ``n`` vehicles.

    Attributes
    ----------
    pos : ndarray, shape (n, 2) [m]
        Positions (x1, x2), read back from the physics every control step.
    theta : ndarray, shape (n,) [rad]
        Headings x3 (unwrapped).
    vel : ndarray, shape (n, 2) [m/s]
        Measured velocities.
    chi : ndarray, shape (n, 2) [m/s]
        Extension states of eqs. (4)/(6).
    travel : ndarray, shape (n,), int8
        The controllers' directions of travel along the heading
        (:func:`~sandbox.model.flatness.travel_direction`; ``TRAVEL_NONE`` before
        they set off).
    v1, v2 : ndarray, shape (n,) [m/s], [rad/s]
        Commands applied during the current control period.
    mode : ndarray, shape (n,), int8
        ``run.MODE_*`` codes.
    failed : ndarray, shape (n,), bool
    offset : ndarray, shape (n, 2) [m]
        Offsets (delta1, delta2) of each vehicle's slot.
    diameter, v1_max, v2_max, accel_max : ndarray, shape (n,)
        ``inf`` where a limit is not set.
    gains : Gains
        With arrays of shape (n,).
    commanded : ndarray, shape (n,), bool
        Vehicles driven open-loop by a command schedule.
    bicycle : ndarray, shape (n,), bool
        Cars (``model: bicycle``, :mod:`sandbox.model.bicycle`); the others are
        unicycles.
    wheelbase, max_steer, max_steer_rate : ndarray, shape (n,) [m], [rad], [rad/s]
        A car's; NaN for a unicycle, ``inf`` where a steering rate is not limited.
    steer : ndarray, shape (n,) [rad]
        A car's steering angle delta during the current control period (0 for a
        unicycle).
    """

    pos: np.ndarray
    theta: np.ndarray
    vel: np.ndarray
    chi: np.ndarray
    travel: np.ndarray
    v1: np.ndarray
    v2: np.ndarray
    mode: np.ndarray
    failed: np.ndarray
    offset: np.ndarray
    diameter: np.ndarray
    v1_max: np.ndarray
    v2_max: np.ndarray
    accel_max: np.ndarray
    gains: Gains
    commanded: np.ndarray
    bicycle: np.ndarray
    wheelbase: np.ndarray
    max_steer: np.ndarray
    max_steer_rate: np.ndarray
    steer: np.ndarray

    @property
    def n(self) -> int:
        """Number of vehicles."""
        return len(self.theta)

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> Fleet:
        """Initial fleet: vehicles at rest at their scenario poses (chi = 0)."""
        vs = scenario.vehicles
        n = len(vs)

        def limit(values: list[float | None]) -> np.ndarray:
            return np.array([np.inf if v is None else v for v in values], dtype=float)

        def car(values: list[float | None], unset: float) -> np.ndarray:
            bicycle = [v.model == "bicycle" for v in vs]
            return np.array(
                [
                    x if b and x is not None else unset
                    for x, b in zip(values, bicycle, strict=True)
                ],
                dtype=float,
            )

        gains = Gains(
            **{
                k: np.array([getattr(v.gains, k) for v in vs], dtype=float)
                for k in ("k1", "k2", "k3", "k4", "kp")
            }
        )
        return cls(
            pos=np.array([v.pose[:2] for v in vs], dtype=float).reshape(n, 2),
            theta=np.array([v.pose[2] for v in vs], dtype=float),
            vel=np.zeros((n, 2)),
            chi=np.zeros((n, 2)),
            travel=np.full(n, TRAVEL_NONE, dtype=np.int8),
            v1=np.zeros(n),
            v2=np.zeros(n),
            mode=np.zeros(n, dtype=np.int8),
            failed=np.zeros(n, dtype=bool),
            offset=np.array([v.offset for v in vs], dtype=float).reshape(n, 2),
            diameter=np.array([v.diameter for v in vs], dtype=float),
            v1_max=limit([v.v1_max for v in vs]),
            v2_max=limit([v.v2_max for v in vs]),
            accel_max=limit([v.max_accel for v in vs]),
            gains=gains,
            commanded=np.array([v.drive.type == "commands" for v in vs], dtype=bool),
            bicycle=np.array([v.model == "bicycle" for v in vs], dtype=bool),
            wheelbase=car([v.wheelbase for v in vs], np.nan),
            max_steer=car([v.max_steer for v in vs], np.nan),
            max_steer_rate=car([v.max_steer_rate for v in vs], np.inf),
            steer=np.zeros(n),
        )

    @classmethod
    def stack(cls, fleets: list[Fleet]) -> Fleet:
        """The fleets of K worlds as one, rows world after world (copies)."""

        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(f, name) for f in fleets])

        keys = ("k1", "k2", "k3", "k4", "kp")
        gains = Gains(
            **{k: np.concatenate([getattr(f.gains, k) for f in fleets]) for k in keys}
        )
        names = [f.name for f in dataclasses.fields(cls) if f.name != "gains"]
        return cls(**{name: cat(name) for name in names}, gains=gains)


def uniform(values: np.ndarray) -> float | np.ndarray:
    """``values[0]`` as a scalar when every entry equals it, else ``values`` itself.

    Parameters shared by a whole fleet are used as scalars on the hot path (the same
    values, broadcast, without streaming (n,) arrays through every step).
    """
    first = values[0]
    return float(first) if np.all(values == first) else values


def limits(
    fleet: Fleet, rows: slice = slice(None)
) -> tuple[float | np.ndarray, float | np.ndarray, float | np.ndarray]:
    """The ``v1_max``, ``v2_max``, ``accel_max`` of ``rows`` (:func:`uniform` each).

    [m/s], [rad/s], [m/s^2]: scalars where equal over the rows, else row arrays.
    """
    return (
        uniform(fleet.v1_max[rows]),
        uniform(fleet.v2_max[rows]),
        uniform(fleet.accel_max[rows]),
    )
