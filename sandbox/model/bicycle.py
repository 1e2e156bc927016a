"""The kinematic bicycle (a car-like vehicle) and its flatness controller.

The report's vehicle is the unicycle of eq. (1). A car has the same flat output, the
position ``(x1, x2)`` of its rear axle, and a bounded steering angle ``delta`` of its
front wheels, a wheelbase ``L`` [m] ahead::

    x1' = v cos x3,   x2' = v sin x3,   x3' = v tan(delta) / L.

Its motion is therefore a unicycle's with the turn rate ``v2 = v1 tan(delta) / L``: a
car cannot turn in place (``v2 = 0`` at ``v1 = 0``) and its turn rate is bounded by
``|v1| tan(max_steer) / L``, the curvature by ``1 / R_min`` with the least turning
radius ``R_min = L / tan(max_steer)``. The flat map of the report's eq. (3) gives the
steering angle from the flat output's first two derivatives (python-control's
``examples/kincar-flatsys.py``, ``vehicle_flat_reverse``)::

    delta = atan2(L (x1' x2'' - x2' x1''), |x'|^3),

and the controller of eqs. (4)-(6) gives them as the ideal velocity vector ``chi``
and its rate: :func:`flat_steer`. The commands of eq. (5) give the same angle
through the curvature ``v2 / v1``: :func:`steer_angle`. The steering saturation and
rate limit are :func:`limit_steer_angle`; the anti-windup that keeps ``chi`` where a
car can drive by the next period is :func:`limit_steer`; one period of the car's
controller is :func:`car_controller_step` and the steering stage after every other
change of the commands is :func:`steer_commands`.

Symbols (report -> code): ``x3`` -> ``theta``; ``v1, v2`` -> ``v1, v2``; the car's
``delta`` -> ``steer``, ``L`` -> ``wheelbase``, ``delta_max`` -> ``max_steer``.
Pure functions of arrays of shape ``(n,)`` (vehicles); no state, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sandbox.model.dynamics import CLIP, wrap_angle
from sandbox.model.flatness import (
    CHI_REST,
    Gains,
    advance_extension,
    extension_rate,
    flat_inputs,
    limit_turn,
)

#: The vehicle models a scenario may name (``vehicle.model``).
VEHICLE_MODELS = ("unicycle", "bicycle")


def bicycle_rates(
    theta: np.ndarray, v1: np.ndarray, steer: np.ndarray, wheelbase: np.ndarray
) -> np.ndarray:
    """Right-hand side of the kinematic bicycle: ``(x1', x2', x3')``, shape (n, 3).

    Eq. (1) of the report with ``v2 = v1 tan(delta) / L`` (:func:`turn_rate`).

    Parameters
    ----------
    theta : ndarray, shape (n,) [rad]
        Headings x3.
    v1 : ndarray, shape (n,) [m/s]
        Speeds of the rear axle (the flat output).
    steer : ndarray, shape (n,) [rad]
        Steering angles delta of the front wheels.
    wheelbase : ndarray, shape (n,) [m]
        Distances L from the rear to the front axle.

    >>> bicycle_rates(np.zeros(1), np.ones(1), np.full(1, np.pi / 4), np.ones(1))
    array([[1., 0., 1.]])
    """
    v2 = turn_rate(v1, steer, wheelbase)
    return np.stack((v1 * np.cos(theta), v1 * np.sin(theta), v2), axis=-1)  # eq. (1)


def turn_rate(
    v1: np.ndarray, steer: np.ndarray, wheelbase: np.ndarray | float
) -> np.ndarray:
    """The turn rate ``v2 = v1 tan(delta) / L`` [rad/s] of a car.

    Zero at ``v1 = 0``: a car does not turn in place.

    >>> round(float(turn_rate(np.float64(2.0), np.arctan(0.5), 1.0)), 12)
    1.0
    """
    return v1 * np.tan(steer) / wheelbase


def min_turning_radius(
    wheelbase: np.ndarray | float, max_steer: np.ndarray | float
) -> np.ndarray:
    """The least turning radius ``L / tan(max_steer)`` [m] of the rear axle.

    >>> round(float(min_turning_radius(1.0, np.arctan(0.25))), 12)
    4.0
    """
    return np.asarray(wheelbase, dtype=float) / np.tan(max_steer)


def car_turn_limit(
    speed: np.ndarray, wheelbase: np.ndarray, max_steer: np.ndarray
) -> np.ndarray:
    """The largest turn rate ``|v1| tan(max_steer) / L`` [rad/s] at a speed.

    The unicycle's turn-rate limit ``v2_max`` is a constant; a car's grows with its
    speed and is zero at rest.

    >>> car_turn_limit(np.array([0.0, 2.0]), np.ones(2), np.full(2, np.arctan(0.5)))
    array([0., 1.])
    """
    return np.abs(speed) * np.tan(max_steer) / wheelbase


def steer_angle(v1: np.ndarray, v2: np.ndarray, wheelbase: np.ndarray) -> np.ndarray:
    """The steering angle [rad] whose curvature gives ``v2`` at ``v1``.

    ``delta = atan(L v2 / v1)``, written ``atan2(L v2 s, |v1|)`` with ``s`` the sign
    of ``v1`` (1 at rest) so that it is defined everywhere: in ``(-pi/2, pi/2)`` for
    any ``v1 != 0`` (reversing included, where ``v1 tan(delta) / L = v2`` too), and
    ``+-pi/2`` where a turn is asked at rest (the wheels turned fully; the car still
    does not turn until it moves). ``v2 = 0`` gives 0.

    Parameters
    ----------
    v1 : ndarray, shape (n,) [m/s]
    v2 : ndarray, shape (n,) [rad/s]
    wheelbase : ndarray, shape (n,) [m]

    >>> steer_angle(np.array([2.0, -2.0, 0.0]), np.array([1.0, 1.0, 1.0]),
    ...             np.ones(3)).round(4).tolist()
    [0.4636, -0.4636, 1.5708]
    """
    sign = np.where(v1 < 0.0, -1.0, 1.0)
    return np.arctan2(wheelbase * v2 * sign, np.abs(v1))


def flat_steer(
    chi: np.ndarray, chi_dot: np.ndarray, wheelbase: np.ndarray | float
) -> np.ndarray:
    """The steering angle [rad] of the flat output's motion ``(chi, chi')``.

    The car's flat map (eq. (3) of the report for the bicycle; python-control's
    ``vehicle_flat_reverse``): with the rear axle's velocity ``chi`` and acceleration
    ``chi'``, ``v = |chi|`` and ``v x3' = (chi1 chi2' - chi2 chi1') / |chi|``, so
    ``delta = atan2(L (chi1 chi2' - chi2 chi1'), |chi|^3)``. Forward motion; 0 at
    rest.

    Parameters
    ----------
    chi, chi_dot : ndarray, shape (n, 2) [m/s], [m/s^2]
    wheelbase : ndarray, shape (n,) [m]

    >>> float(flat_steer(np.array([[1.0, 0.0]]), np.array([[0.0, 1.0]]), 1.0)[0])
    0.7853981633974483
    """
    c1, c2 = chi[..., 0], chi[..., 1]
    cross = c1 * chi_dot[..., 1] - c2 * chi_dot[..., 0]
    norm = np.hypot(c1, c2)
    return np.arctan2(wheelbase * cross, norm * norm * norm)


def limit_steer_angle(
    request: np.ndarray,
    held: np.ndarray,
    max_steer: np.ndarray,
    max_rate: np.ndarray,
    dt: float,
) -> np.ndarray:
    """The steering angle a car applies [rad]: saturated, then rate-limited.

    ``clip(request, -max_steer, max_steer)``, then moved from the angle ``held`` of
    the last period by at most ``max_rate * dt`` (``inf`` where no rate limit is
    declared).

    Parameters
    ----------
    request, held : ndarray, shape (n,) [rad]
    max_steer : ndarray, shape (n,) [rad]
    max_rate : ndarray, shape (n,) [rad/s]
    dt : float [s]

    >>> limit_steer_angle(np.array([1.0, -0.2]), np.zeros(2), np.full(2, 0.5),
    ...                   np.array([np.inf, 1.0]), 0.1).tolist()
    [0.5, -0.1]
    """
    saturated = CLIP(request, -max_steer, max_steer)
    step = max_rate * dt
    return held + CLIP(saturated - held, -step, step)


def limit_steer(
    chi: np.ndarray, theta: np.ndarray, limit: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The car's anti-windup: turn chi into the directions it can drive by then.

    A car heading ``theta`` at speed ``|chi|`` turns by at most ``limit = |chi|
    tan(max_steer) / L * dt`` in one period. A chi outside that cone is turned onto
    its nearer edge, *keeping its length*: unlike the unicycle's
    :func:`~sandbox.model.flatness.limit_turn`, which shortens chi to its component
    along the edge (a unicycle then turns at rest before it drives), a car must keep
    moving to turn at all, and a shorter chi would shrink its cone until it stops.
    The car then drives its tightest turn towards the requested direction, and chi
    stays what the car can do instead of winding up. The requested direction is
    returned as ``aim`` (for :func:`~sandbox.model.flatness.flat_inputs`).

    Parameters
    ----------
    chi : ndarray, shape (n, 2) [m/s]
    theta : ndarray, shape (n,) [rad]
    limit : ndarray, shape (n,) [rad]

    Returns
    -------
    chi : ndarray, shape (n, 2) [m/s]
    aim : ndarray, shape (n,) [rad]
        Angle of the requested chi where it was outside the cone, NaN elsewhere.

    >>> chi, aim = limit_steer(np.array([[0.0, 2.0]]), np.zeros(1), np.full(1, 0.1))
    >>> chi.round(4).tolist(), aim.round(4).tolist()
    ([[1.99, 0.1997]], [1.5708])
    """
    c1, c2 = chi[..., 0], chi[..., 1]
    norm = np.hypot(c1, c2)
    angle = np.arctan2(c2, c1)
    off = wrap_angle(angle - theta)
    outside = (np.abs(off) > limit) & (norm >= CHI_REST)
    if not np.count_nonzero(outside):  # every chi within its cone: as it is
        nowhere = np.empty(norm.shape)
        nowhere.fill(np.nan)
        return chi, nowhere
    direction = theta + CLIP(off, -limit, limit)
    turned = np.empty(chi.shape)
    turned[..., 0] = norm * np.cos(direction)
    turned[..., 1] = norm * np.sin(direction)
    out = np.where(outside[..., None], turned, chi)
    return out, np.where(outside, angle, np.nan)


def car_controller_step(
    pos: np.ndarray,
    chi: np.ndarray,
    theta: np.ndarray,
    target: np.ndarray,
    v_ref: np.ndarray,
    a_ref: np.ndarray,
    gains: Gains,
    dt: float,
    limits: CarLimits,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One period of the flatness controller for cars, eqs. (5)-(6).

    The unicycle's composition (:class:`~sandbox.model.kernels.Controller`) with the
    car's anti-windup: eq. (6) for the flat output; the chi it asks for turned into
    the car's cone at the speed it asks for (:func:`limit_steer`), so that a car
    asked to go the other way accelerates into its tightest turn instead of braking
    to rest, where it could not turn; chi's speed and acceleration clamps
    (:func:`~sandbox.model.flatness.advance_extension`) towards it; chi turned into
    the cone of its new speed; then eq. (5) and the clip of ``v2`` to ``v2_max``. The
    commands still ask for any turn rate; :func:`steer_commands` makes them a
    steering angle within the car's limits. A car whose target is at rest (``|x_ref'|
    < CHI_REST``) within one least turning radius **parks**: its chi is shortened as
    the unicycle's (:func:`~sandbox.model.flatness.limit_turn`), so it stops where
    the target falls behind it instead of looping around a point it cannot reach
    without reversing.

    Parameters
    ----------
    pos, chi : ndarray, shape (n, 2) [m], [m/s]
    theta : ndarray, shape (n,) [rad]
    target, v_ref, a_ref : ndarray, shape (n, 2) [m], [m/s], [m/s^2]
        The slot to track (a NaN coordinate aims at the position's) and its
        feed-forward velocity and acceleration.
    gains : Gains
        Arrays of shape (n,) or scalars.
    dt : float [s]
    limits : CarLimits

    Returns
    -------
    chi_next : ndarray, shape (n, 2) [m/s]
    v1 : ndarray, shape (n,) [m/s]
    v2 : ndarray, shape (n,) [rad/s]
    """
    aim_at = np.where(np.isnan(target), pos, target)
    chi_dot = extension_rate(pos, chi, aim_at, v_ref, a_ref, gains)  # eq. (6)
    # Where the target rests within one least turning radius, a car parks: chi is
    # shortened as a unicycle's (it stops where the target falls behind) instead of
    # being kept for a loop around a point it would only orbit.
    parks = np.hypot(v_ref[:, 0], v_ref[:, 1]) < CHI_REST
    if np.count_nonzero(parks):
        away = aim_at - pos
        parks &= np.hypot(away[:, 0], away[:, 1]) < limits.radius
    # The chi eq. (6) asks for, turned into the car's cone first: its length is the
    # speed the car is asked to reach, which the clamps below then limit.
    wanted = chi + chi_dot * dt
    reach = np.minimum(np.hypot(wanted[:, 0], wanted[:, 1]), limits.v1_max)
    wanted, aim = _into_cone(wanted, theta, limits.cone(reach, dt), parks)
    nxt, _ = advance_extension(
        chi, (wanted - chi) / dt, dt, limits.v1_max, limits.accel_max
    )
    speed = np.hypot(nxt[:, 0], nxt[:, 1])
    nxt, late = _into_cone(nxt, theta, limits.cone(speed, dt), parks)
    aim = np.where(np.isnan(aim), late, aim)
    v1, v2 = flat_inputs(theta, chi, (nxt - chi) / dt, gains.kp, aim)  # eq. (5)
    return nxt, v1, CLIP(v2, -limits.v2_max, limits.v2_max)


def _into_cone(
    chi: np.ndarray, theta: np.ndarray, limit: np.ndarray, parks: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`limit_steer`, or the unicycle's ``limit_turn`` on the rows that park."""
    kept, aim = limit_steer(chi, theta, limit)
    if not np.count_nonzero(parks):
        return kept, aim
    short, stop = limit_turn(chi, theta, limit)
    return np.where(parks[:, None], short, kept), np.where(parks, stop, aim)


def steer_commands(
    v1: np.ndarray, v2: np.ndarray, held: np.ndarray, limits: CarLimits, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """The commands a car executes: ``(v2, delta)`` for the speeds ``v1``.

    The asked turn rate becomes a steering angle through the curvature
    (:func:`steer_angle`), which is saturated at ``max_steer`` and moved from the
    angle ``held`` at most ``max_steer_rate * dt`` (:func:`limit_steer_angle`),
    and bounded so that the turn rate stays within ``v2_max``; the turn rate
    executed is the car's, ``v1 tan(delta) / L``. Where nothing is asked (``v1 = v2 =
    0``) the wheels are held where they are.

    Parameters
    ----------
    v1, v2 : ndarray, shape (n,) [m/s], [rad/s]
        The commands after the controller, the safety filter, the schedules, the
        overrides and the failures.
    held : ndarray, shape (n,) [rad]
        The steering angles of the last period.
    limits : CarLimits
    dt : float [s]

    Returns
    -------
    v2 : ndarray, shape (n,) [rad/s]
    steer : ndarray, shape (n,) [rad]

    >>> lim = CarLimits.of(wheelbase=[1.0], max_steer=[0.5])
    >>> v2, steer = steer_commands(np.array([1.0]), np.array([2.0]), np.zeros(1),
    ...                            lim, 0.01)
    >>> round(float(steer[0]), 3), round(float(v2[0]), 4)
    (0.5, 0.5463)
    """
    request = steer_angle(v1, v2, limits.wheelbase)
    request = np.where((v1 == 0.0) & (v2 == 0.0), held, request)
    steer = limit_steer_angle(
        request, held, limits.max_steer, limits.max_steer_rate, dt
    )
    # |v1 tan(delta) / L| <= v2_max: |delta| <= atan(L v2_max / |v1|)
    bound = np.arctan2(limits.wheelbase * limits.v2_max, np.abs(v1))
    steer = CLIP(steer, -bound, bound)
    return turn_rate(v1, steer, limits.wheelbase), steer


class CarLimits:
    """The per-row parameters of a set of cars, float64 arrays of shape (n,).

    Parameters
    ----------
    wheelbase : ndarray [m]
    max_steer : ndarray [rad]
        In ``(0, pi/2)``.
    max_steer_rate : ndarray [rad/s]
        ``inf`` where not declared.
    v1_max, accel_max, v2_max : ndarray [m/s], [m/s^2], [rad/s]
        ``inf`` where not declared.

    Attributes
    ----------
    curvature : ndarray [1/m]
        The largest curvature ``tan(max_steer) / L``.
    radius : ndarray [m]
        The least turning radius ``L / tan(max_steer)`` (:func:`min_turning_radius`).
    """

    #: The constructor's arguments, in order.
    FIELDS = (
        "wheelbase",
        "max_steer",
        "max_steer_rate",
        "v1_max",
        "accel_max",
        "v2_max",
    )
    __slots__ = (*FIELDS, "curvature", "radius", "_tan", "_turn_capped")

    def __init__(
        self,
        wheelbase: np.ndarray,
        max_steer: np.ndarray,
        max_steer_rate: np.ndarray,
        v1_max: np.ndarray,
        accel_max: np.ndarray,
        v2_max: np.ndarray,
    ) -> None:
        self.wheelbase = wheelbase
        self.max_steer = max_steer
        self.max_steer_rate = max_steer_rate
        self.v1_max, self.accel_max, self.v2_max = v1_max, accel_max, v2_max
        self._tan = np.tan(max_steer)
        self.curvature = self._tan / wheelbase
        self.radius = min_turning_radius(wheelbase, max_steer)
        self._turn_capped = bool(np.isfinite(v2_max).any())

    def cone(self, speed: np.ndarray, dt: float) -> np.ndarray:
        """The largest turn [rad] in one period at ``speed``, within ``v2_max`` too.

        ``|speed| tan(max_steer) / L dt`` (:func:`car_turn_limit`), at most
        ``v2_max dt``.
        """
        turn = np.abs(speed) * self._tan / self.wheelbase  # car_turn_limit's order
        if self._turn_capped:
            turn = np.minimum(turn, self.v2_max)
        return turn * dt

    @classmethod
    def of(cls, **values: object) -> CarLimits:
        """Limits from lists or arrays; those left out are ``inf`` (unlimited).

        >>> CarLimits.of(wheelbase=[1.0, 2.0], max_steer=[0.5, 0.5]).v1_max.tolist()
        [inf, inf]
        """
        n = len(np.atleast_1d(values["wheelbase"]))
        out = {}
        for name in cls.FIELDS:
            value = values.get(name, np.inf)
            out[name] = np.ascontiguousarray(
                np.broadcast_to(np.asarray(value, dtype=float), (n,))
            )
        return cls(**out)

    def rows(self, index: np.ndarray) -> CarLimits:
        """The limits of the rows ``index`` (copies)."""
        return CarLimits(*(getattr(self, name)[index] for name in self.FIELDS))


@dataclass(frozen=True)
class CarSteering:
    """The cars among a safety filter's rows (``FilterContext.steering``).

    Every array has a row per vehicle of the filter's rows, NaN (``inf`` for the
    rate) on a unicycle's.

    Attributes
    ----------
    wheelbase : ndarray, shape (n,) [m]
        ``L``; NaN marks a unicycle.
    max_steer : ndarray, shape (n,) [rad]
    max_steer_rate : ndarray, shape (n,) [rad/s]
        ``inf`` where not declared.
    held : ndarray, shape (n,) [rad]
        The steering angles of the last period, from which this period's move
        (:func:`limit_steer_angle`).
    """

    wheelbase: np.ndarray
    max_steer: np.ndarray
    max_steer_rate: np.ndarray
    held: np.ndarray

    def reach(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The least and the largest steering angle [rad] of the period, (n,) each.

        ``held`` moved by at most ``max_steer_rate dt``, within ``max_steer``: the
        angles :func:`limit_steer_angle` can give (NaN on a unicycle's row).

        >>> CarSteering(np.ones(1), np.full(1, 0.5), np.full(1, 1.0),
        ...             np.full(1, 0.45)).reach(0.1)
        (array([0.35]), array([0.5]))
        """
        step = self.max_steer_rate * dt
        lo = np.maximum(-self.max_steer, self.held - step)
        hi = np.minimum(self.max_steer, self.held + step)
        return lo, hi
