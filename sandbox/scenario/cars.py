"""The car keys of a vehicle (``model``, ``wheelbase``, ``max_steer``, ...) and checks.

:data:`CAR_PARAMS` are keys of ``vehicle:``, of each listed vehicle and of a
platoon's ``vehicle:`` (they join ``VEHICLE_PARAMS``): ``model: bicycle`` makes the
vehicle a car, the kinematic bicycle of :mod:`sandbox.model.bicycle`, with its
``wheelbase`` and ``max_steer`` (both required for a car) and an optional
``max_steer_rate``. :func:`check_car` checks one vehicle's values once they are
merged; :func:`turning_warnings` tells, at validation, which cars are asked by their
formation for a path tighter than they can turn.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from sandbox.model.bicycle import VEHICLE_MODELS, min_turning_radius
from sandbox.plugins.registration import Param

#: Samples of the reference per second of the run for :func:`turning_warnings`.
SAMPLES_PER_SECOND = 50
#: At most this many samples of the reference (a long run is sampled more coarsely).
MAX_SAMPLES = 20_000
#: Below this speed [m/s] a slot's path has no curvature to speak of (it rests).
RESTING_SPEED = 1e-3

CAR_PARAMS: dict[str, Param] = {
    "model": Param(
        "choice",
        "unicycle",
        doc="unicycle: eq. (1), turns in place; bicycle: a car (the kinematic "
        "bicycle, rear axle at the body's centre), turn rate v1 tan(delta) / "
        "wheelbase with |delta| <= max_steer",
        choices=VEHICLE_MODELS,
    ),
    "wheelbase": Param(
        "number",
        None,
        "m",
        "model bicycle: distance L from the rear axle (the body's centre) to the "
        "front axle; required for a car",
        minimum=0.0,
        exclusive=True,
    ),
    "max_steer": Param(
        "number",
        None,
        "rad",
        "model bicycle: steering limit delta_max, less than pi/2 (least turning "
        "radius wheelbase / tan(max_steer)); required for a car",
        minimum=0.0,
        exclusive=True,
    ),
    "max_steer_rate": Param(
        "number",
        None,
        "rad/s",
        "model bicycle: limit on the steering angle's rate |delta'|; default: "
        "unlimited",
        minimum=0.0,
        exclusive=True,
    ),
}


class ProblemSink(Protocol):
    """Where the loader's checks record problems and warnings (its reader)."""

    problems: list[Any]

    def fail(
        self, path: str, what: str, got: str | None = None, expected: str | None = None
    ) -> None:
        """Record a problem at ``path``."""

    def warn(self, path: str, message: str) -> None:
        """Record a warning at ``path``."""


def check_steer_limit(rd: ProblemSink, values: dict[str, Any], path: str) -> None:
    """A ``max_steer`` at or beyond pi/2 is a problem (then left out of ``values``)."""
    steer = values.get("max_steer")
    if steer is not None and steer >= math.pi / 2:
        rd.fail(
            f"{path}.max_steer" if path else "max_steer",
            "must be less than pi/2",
            f"{steer:g}",
            "an angle in (0, 1.5708) [rad]",
        )
        values["max_steer"] = None


def check_car(rd: ProblemSink, values: dict[str, Any], path: str) -> bool:
    """Whether one vehicle's merged values make a valid car, or a unicycle.

    ``model: bicycle`` needs ``wheelbase`` and ``max_steer`` (from the vehicle or the
    shared ``vehicle:``); each one missing is a problem at ``path``, unless a value
    given for it was a problem already.
    """
    if values.get("model") != "bicycle":
        return True
    ok = True
    for key, kind in (
        ("wheelbase", "a number > 0 [m]"),
        ("max_steer", "an angle in (0, 1.5708) [rad]"),
    ):
        if values.get(key) is None:
            ok = False
            if any(p.path.endswith(f".{key}") for p in rd.problems):
                continue  # given, and wrong: said once
            where = f"{path}.{key}" if path else key
            rd.fail(where, "required with model: bicycle", "nothing", kind)
    return ok


def slot_paths(
    reference: Any,
    offsets: np.ndarray,
    rotate: bool,
    duration: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The paths the slots follow on the reference, and the sample times.

    A slot is the reference point plus its offset, turned by the reference's tangent
    (eqs. (14)-(15)) where the formation rotates; a follower of a leader that tracks
    the reference follows the same path.

    Parameters
    ----------
    reference : Reference
        A built reference (``evaluate(times)`` gives ``p, p', p''``).
    offsets : ndarray, shape (n, 2) [m]
    rotate : bool
        Whether the offsets turn with the reference's tangent.
    duration : float [s]

    Returns
    -------
    path : ndarray, shape (T, n, 2) [m]
    times : ndarray, shape (T,) [s]
    """
    count = int(min(MAX_SAMPLES, max(3, duration * SAMPLES_PER_SECOND + 1)))
    times = np.linspace(0.0, duration, count)
    p, dp, _ = reference.evaluate(times)
    p, dp = np.asarray(p, dtype=float), np.asarray(dp, dtype=float)
    angle = np.arctan2(dp[:, 1], dp[:, 0]) if rotate else np.zeros(count)  # eq. (15)
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    d1, d2 = offsets[None, :, 0], offsets[None, :, 1]
    shift = np.stack((c * d1 - s * d2, s * d1 + c * d2), axis=-1)  # eq. (14)
    return p[:, None, :] + shift, times


def path_radii(path: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The radius of curvature [m] of sampled paths, shape (T, n); inf where straight.

    ``|x'|^3 / |x1' x2'' - x2' x1''|`` with the derivatives by central differences
    (:func:`numpy.gradient`); inf where the path rests (below
    :data:`RESTING_SPEED`) or does not bend.

    >>> t = np.linspace(0.0, 2.0 * np.pi, 2001)
    >>> circle = 5.0 * np.stack((np.cos(t), np.sin(t)), axis=-1)[:, None, :]
    >>> round(float(np.median(path_radii(circle, t))), 3)
    5.0
    """
    vel = np.gradient(path, times, axis=0)
    acc = np.gradient(vel, times, axis=0)
    speed = np.hypot(vel[..., 0], vel[..., 1])
    cross = np.abs(vel[..., 0] * acc[..., 1] - vel[..., 1] * acc[..., 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = speed**3 / cross
    return np.where((speed < RESTING_SPEED) | ~np.isfinite(radius), np.inf, radius)


def turning_warnings(
    vehicles: Sequence[Any],
    reference: Any,
    frame: str,
    rotate: bool,
    duration: float,
    tracks_reference: Sequence[bool],
) -> list[tuple[int, str]]:
    """The cars whose slot's path on the reference is tighter than they can turn.

    Each car's slot path (:func:`slot_paths`: the reference itself for a vehicle
    that tracks it) is sampled over the run; where its least radius of curvature is
    below the car's least turning radius ``wheelbase / tan(max_steer)``, the car
    cannot hold its slot there (it falls outside the turn). The ends of the run are
    left out (their differences are one-sided).

    Parameters
    ----------
    vehicles : sequence of VehicleSpec
    reference : ReferenceSpec or None
    frame : str
        The formation law's ``frame`` (``register_law``): ``leader`` turns the
        offsets with the heading, ``reference`` and ``leader_reference`` with the
        tangent where ``rotate``, ``world`` never.
    rotate : bool
        The law's ``rotate``.
    duration : float [s]
    tracks_reference : sequence of bool
        Whether each vehicle tracks the reference itself (no offset).

    Returns
    -------
    list of (int, str)
        The vehicle's index and a one-line warning naming it and the radii.
    """
    cars = [i for i, v in enumerate(vehicles) if v.model == "bicycle"]
    if reference is None or not cars or duration <= 0.0:
        return []
    turned = frame == "leader" or (
        frame in ("reference", "leader_reference") and rotate
    )
    offsets = np.array(
        [(0.0, 0.0) if tracks_reference[i] else vehicles[i].offset for i in cars],
        dtype=float,
    ).reshape(-1, 2)
    path, times = slot_paths(reference.build(), offsets, turned, duration)
    radii = path_radii(path, times)[1:-1]
    out = []
    for k, i in enumerate(cars):
        v = vehicles[i]
        least = min_turning_radius(v.wheelbase, v.max_steer)
        column = radii[:, k]
        tight = np.flatnonzero(column < least)
        if len(tight):
            out.append(
                (
                    i,
                    f"vehicle {v.name} cannot hold its slot: on the reference its "
                    f"slot turns at radius {column.min():.2f} m (from t = "
                    f"{times[tight[0] + 1]:.2f} s), tighter than its least turning "
                    f"radius {least:.2f} m (wheelbase {v.wheelbase:g} m, max_steer "
                    f"{v.max_steer:g} rad)",
                )
            )
    return out
