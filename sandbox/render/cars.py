"""How a car is drawn: its chassis to the front axle and its wheels, the front turned.

A car (``model: bicycle``) is the pymunk disc of its diameter, like a unicycle, with
its rear axle at the disc's centre; the pictures add its chassis, a line from the rear
axle to the front axle ``wheelbase`` ahead along the heading, and two wheels: the rear
one along the heading at the centre, the front one at the front axle turned by the
steering angle of the sample (``Run.steer``). :func:`car_lines` gives those segments
in metres for the GIF (:mod:`sandbox.render.scene`), the figures
(:mod:`sandbox.render.figures`) and, through the replay's data, the browser page.
"""

from __future__ import annotations

import numpy as np

from sandbox.run.record import Run

__all__ = [
    "BODY_WIDTH",
    "OVERHANG",
    "WHEEL_FRACTION",
    "car_bodies",
    "car_lines",
    "car_wheelbases",
]

#: Length of a drawn wheel as a fraction of the vehicle's diameter.
WHEEL_FRACTION = 0.5
#: Width of a drawn car body, and its overhang beyond each axle, as fractions of the
#: vehicle's diameter.
BODY_WIDTH, OVERHANG = 0.8, 0.3


def car_wheelbases(run: Run) -> np.ndarray | None:
    """Each vehicle's wheelbase [m], NaN for a unicycle; None for a run without cars.

    Read from the run's scenario (``vehicles[i].wheelbase``); a run loaded without
    its scenario draws its cars with a wheelbase of one diameter.
    """
    if run.steer is None:
        return None
    cars = np.isfinite(np.asarray(run.steer, dtype=float)).any(axis=0)
    out = np.asarray(run.diameter, dtype=float).copy()
    vehicles = getattr(run.scenario, "vehicles", None)
    if vehicles is not None and len(vehicles) == run.n_vehicles:
        given = [np.nan if v.wheelbase is None else v.wheelbase for v in vehicles]
        out = np.where(np.isnan(given), out, np.asarray(given, dtype=float))
    return np.where(cars, out, np.nan)


def car_lines(
    pose: np.ndarray,
    steer: np.ndarray,
    wheelbase: np.ndarray,
    diameter: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The chassis and the wheels of the cars of one sample, in metres.

    Parameters
    ----------
    pose : ndarray, shape (n, 3) [m, m, rad]
    steer : ndarray, shape (n,) [rad]
        NaN for a unicycle (no lines).
    wheelbase, diameter : ndarray, shape (n,) [m]

    Returns
    -------
    chassis : ndarray, shape (m, 2, 2) [m]
        One segment per car: rear axle (the centre) to front axle.
    wheels : ndarray, shape (2 m, 2, 2) [m]
        Each car's rear wheel (along the heading) and front wheel (turned by the
        steering angle), centred on their axles.

    >>> chassis, wheels = car_lines(np.zeros((1, 3)), np.full(1, np.pi / 2),
    ...                             np.ones(1), np.ones(1))
    >>> chassis.tolist(), wheels[1].round(3).tolist()
    ([[[0.0, 0.0], [1.0, 0.0]]], [[1.0, -0.25], [1.0, 0.25]])
    """
    ok, p, th, ahead = _cars(pose, steer, wheelbase)
    delta = steer[ok]
    front = p + wheelbase[ok, None] * ahead
    half = 0.5 * WHEEL_FRACTION * diameter[ok, None]
    turned = np.stack((np.cos(th + delta), np.sin(th + delta)), axis=-1)
    chassis = np.stack((p, front), axis=1)
    rear = np.stack((p - half * ahead, p + half * ahead), axis=1)
    wheel = np.stack((front - half * turned, front + half * turned), axis=1)
    return chassis, np.concatenate((rear, wheel))


def car_bodies(
    pose: np.ndarray, steer: np.ndarray, wheelbase: np.ndarray, diameter: np.ndarray
) -> np.ndarray:
    """The outline of each car's body, a rectangle over both axles, in metres.

    :data:`BODY_WIDTH` of the diameter wide, reaching :data:`OVERHANG` of the
    diameter behind the rear axle and beyond the front one.

    Parameters
    ----------
    pose : ndarray, shape (n, 3) [m, m, rad]
    steer : ndarray, shape (n,) [rad]
        NaN for a unicycle (no outline).
    wheelbase, diameter : ndarray, shape (n,) [m]

    Returns
    -------
    ndarray, shape (m, 4, 2) [m]
        The corners of each car's rectangle, in order around it.

    >>> car_bodies(np.zeros((1, 3)), np.zeros(1), np.ones(1), np.ones(1)).tolist()
    [[[-0.3, -0.4], [1.3, -0.4], [1.3, 0.4], [-0.3, 0.4]]]
    """
    ok, p, th, ahead = _cars(pose, steer, wheelbase)
    d = diameter[ok, None]
    left = np.stack((-np.sin(th), np.cos(th)), axis=-1)
    back = p - OVERHANG * d * ahead
    front = p + (wheelbase[ok, None] + OVERHANG * d) * ahead
    side = 0.5 * BODY_WIDTH * d * left
    return np.stack((back - side, front - side, front + side, back + side), axis=1)


def _cars(
    pose: np.ndarray, steer: np.ndarray, wheelbase: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The drawn cars' rows, rear axles (m, 2), headings (m,) and unit headings."""
    ok = np.isfinite(steer) & np.isfinite(pose).all(axis=1) & np.isfinite(wheelbase)
    th = pose[ok, 2]
    return ok, pose[ok, :2], th, np.stack((np.cos(th), np.sin(th)), axis=-1)
