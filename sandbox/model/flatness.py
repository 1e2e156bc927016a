"""Flatness-based controller with a second-order state extension, eqs. (4)-(6).

Pure functions over arrays of vehicles (shape ``(n, ...)``). The extension states
``chi = (chi1, chi2)`` [m/s] are the "ideal velocity vector" of the report; they live in
the fleet state and are advanced by the simulation loop with :func:`advance_extension`.

Symbols (report -> code): ``x1, x2`` -> ``pos[:, 0], pos[:, 1]``; ``x3`` -> ``theta``;
``x_ref, x_ref', x_ref''`` -> ``p_ref, v_ref, a_ref``; ``k1..k4, kp`` -> :class:`Gains`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from sandbox.model.dynamics import CLIP, wrap_angle

#: Below this speed ``|chi|`` [m/s] the ideal velocity has vanished: the vehicle is at
#: rest, where the direction of chi (the desired heading ``arctan2(chi1, chi2)`` of eq.
#: (5)) is undefined. The vehicle then holds its heading (``v2 = 0``) and moves only
#: along it (``v1`` the component of chi along the heading, of either sign), as the
#: rotated offsets hold the last tangent of eq. (15) when the reference stops
#: (:data:`sandbox.model.laws.REST_SPEED`). Turning towards chi there would make a
#: turn rate of ``kp`` times an angle of noise: a vehicle parked at its point spun at
#: 5-7 rad/s, and a leader spinning at the end of its path swung a rotating formation
#: round it at 14-20 m/s. 1 mm/s: the speed below which eq. (5) set ``v1 = 0`` before;
#: 1 cm/s held vehicles that a filter or their neighbours had slowed, and changed how
#: the report's traffic scenes resolve (`traffic/intersection_four` no longer settled).
CHI_REST = 0.001

#: A vehicle may travel backward only where its target rests (``|x_ref'| <
#: CHI_REST``) within this distance [m] of it (:func:`travel_direction`): about three
#: times the overshoot past a point it stops at from the report's top speed (3.7 cm per
#: m/s for the report's gains). Farther, as when a safety filter or another vehicle
#: holds it metres from its slot, eq. (5) drives forward as in the report: a vehicle
#: that backed away there from a vehicle it faced in a door never passed it.
PARK_RADIUS = 0.25

#: The direction of travel along the heading (:func:`travel_direction`): not yet
#: travelled, forward (eq. (5)), backward (eq. (5) for ``-chi``).
TRAVEL_NONE, TRAVEL_FORWARD, TRAVEL_BACKWARD = 0, 1, -1


@dataclass(frozen=True)
class Gains:
    """Controller gains (scalars, or arrays of shape ``(n,)`` for per-vehicle gains).

    Defaults are the report's values for every simulation: ``k1 = k3 = -100`` [1/s^2],
    ``k2 = k4 = -20`` [1/s], ``kp = 2`` [1/s]. The error dynamics are then
    ``s^2 + 20 s + 100``: a double pole at -10 rad/s.
    """

    k1: float | np.ndarray = -100.0
    k2: float | np.ndarray = -20.0
    k3: float | np.ndarray = -100.0
    k4: float | np.ndarray = -20.0
    kp: float | np.ndarray = 2.0

    @cached_property
    def paired(self) -> tuple[float | np.ndarray, float | np.ndarray]:
        """``(k1, k3)`` and ``(k2, k4)`` as the factors of eq. (6)'s two columns.

        A scalar where the two gains are one scalar (the same products as a pair of
        equal columns), else an array broadcasting over ``(n, 2)``.
        """
        return _pair(self.k1, self.k3), _pair(self.k2, self.k4)


def _pair(a: float | np.ndarray, b: float | np.ndarray) -> float | np.ndarray:
    if np.ndim(a) == 0 and np.ndim(b) == 0 and float(a) == float(b):
        return float(a)
    return np.stack(np.broadcast_arrays(a, b), axis=-1)


def extension_rate(
    pos: np.ndarray,
    chi: np.ndarray,
    p_ref: np.ndarray,
    v_ref: np.ndarray,
    a_ref: np.ndarray,
    gains: Gains,
) -> np.ndarray:
    """Time derivative of the extension states, eq. (6) (eq. (4) when the ref is 0).

    Parameters
    ----------
    pos : ndarray, shape (n, 2) [m]
        Positions ``(x1, x2)``.
    chi : ndarray, shape (n, 2) [m/s]
        Extension states.
    p_ref, v_ref, a_ref : ndarray, shape (n, 2) [m], [m/s], [m/s^2]
        Reference position and its first and second derivatives (true or estimated).
    gains : Gains

    Returns
    -------
    chi_dot : ndarray, shape (n, 2) [m/s^2]
    """
    k_pos, k_vel = gains.paired
    return k_pos * (pos - p_ref) + k_vel * (chi - v_ref) + a_ref  # eq. (6)


def flat_inputs(
    theta: np.ndarray,
    chi: np.ndarray,
    chi_dot: np.ndarray,
    kp: float | np.ndarray,
    aim: np.ndarray | None = None,
    travel: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Control inputs ``(v1, v2)`` from the extension states, eq. (5).

    ``v1 = |chi|``; ``v2`` is the turn rate of chi (flatness feedforward, eq. (3))
    minus ``kp`` times the heading error ``x3 - angle(chi)``, wrapped to ``[-pi,
    pi)``. A vehicle travelling backward (``travel`` :data:`TRAVEL_BACKWARD`, see
    :func:`travel_direction`) drives eq. (5) for ``-chi``: ``v1 = -|chi|`` and the
    heading error measured to the angle of ``-chi`` (the turn rate of chi is that of
    ``-chi``). Where ``|chi| < CHI_REST`` the ideal velocity has vanished and its
    angle is undefined: the vehicle holds its heading (``v2 = 0``) and moves only
    along it, ``v1`` the component of chi along the heading. No NaN is ever produced
    for finite inputs.

    Parameters
    ----------
    theta : ndarray, shape (n,) [rad]
    chi, chi_dot : ndarray, shape (n, 2) [m/s], [m/s^2]
    kp : float or ndarray, shape (n,) [1/s]
    aim : ndarray, shape (n,) [rad], optional
        Where not NaN, the heading the turn-rate anti-windup held chi back from
        (:func:`limit_turn`): the heading error is measured to it instead, at rest
        included.
    travel : ndarray, shape (n,), int8, optional
        The direction of travel (:func:`travel_direction`); default forward.

    Returns
    -------
    v1 : ndarray, shape (n,) [m/s]
    v2 : ndarray, shape (n,) [rad/s]
    """
    c1, c2 = chi[..., 0], chi[..., 1]
    norm2 = c1 * c1 + c2 * c2
    v1 = np.sqrt(norm2)  # eq. (5)
    moving = norm2 >= CHI_REST * CHI_REST
    every = np.count_nonzero(moving) == moving.size  # where(moving, x, y) is x
    safe = np.maximum(norm2, CHI_REST * CHI_REST)
    feedforward = (-c2 * chi_dot[..., 0] + c1 * chi_dot[..., 1]) / safe  # eq. (5)
    # "arctan2(chi1, chi2)" in the report is the angle of the vector (chi1, chi2).
    angle = np.arctan2(c2, c1)
    if travel is not None and np.count_nonzero(travel == TRAVEL_BACKWARD):
        backward = travel == TRAVEL_BACKWARD  # eq. (5) for -chi
        v1 = np.where(backward, -v1, v1)
        angle = np.where(backward, angle + np.pi, angle)
    v2 = feedforward - kp * wrap_angle(theta - angle)  # eq. (5)
    if not every:  # at rest: the heading held, the motion along it
        v1 = np.where(moving, v1, c1 * np.cos(theta) + c2 * np.sin(theta))
        v2 = np.where(moving, v2, 0.0)
    if aim is not None:
        turning = ~np.isnan(aim)
        if np.count_nonzero(turning):  # chi held back by the turn limit: turn to aim
            toward = -kp * wrap_angle(theta - np.where(turning, aim, 0.0))
            if not every:
                feedforward = np.where(moving, feedforward, 0.0)
            v2 = np.where(turning, feedforward + toward, v2)
    return v1, v2


def parking(pos: np.ndarray, aim: np.ndarray, v_ref: np.ndarray) -> np.ndarray:
    """The rows that park, shape (n,) bool.

    A row parks where its target rests (``|x_ref'| < CHI_REST``) within
    :data:`PARK_RADIUS` of the vehicle: there :func:`travel_direction` may choose to
    travel backward. ``aim`` is the target with a NaN coordinate replaced by the
    position's.
    """
    away = aim - pos
    near = away[:, 0] ** 2 + away[:, 1] ** 2 < PARK_RADIUS * PARK_RADIUS
    rest = v_ref[:, 0] ** 2 + v_ref[:, 1] ** 2 < CHI_REST * CHI_REST
    return near & rest


def travel_direction(
    chi: np.ndarray,
    chi_next: np.ndarray,
    theta: np.ndarray,
    travel: np.ndarray,
    parks: np.ndarray | None = None,
) -> np.ndarray:
    """The direction of travel along the heading for the next period.

    Eq. (5) drives forward (``v1 = |chi| >= 0``): a vehicle whose chi points behind
    it turns round first. That is right when it sets off, but not when the ideal
    velocity vanishes at the point it parks at: at the end of a reference that stops,
    or at a stabilization point, the vehicle overshoots by a few centimetres (for the
    report's gains, 3.7 % of the speed it had, in metres per m/s) and chi comes back
    pointing behind it. Turning round for that made the vehicle spin and orbit its
    point. So where the vehicle parks (``parks``, :func:`parking`: its target rests
    within :data:`PARK_RADIUS`), the direction of travel is chosen again whenever chi
    comes back from having vanished (it was at rest, ``|chi| < CHI_REST``, or it
    reversed within one period, ``chi . chi_next < 0``): the vehicle keeps its
    heading line and travels forward or backward, whichever is along chi (it turns by
    less than a quarter turn). Everywhere else, and for a vehicle that has not
    travelled yet, the direction is forward, as in the report; a vehicle travelling
    backward goes forward again once chi points ahead of it or it no longer parks.

    Parameters
    ----------
    chi, chi_next : ndarray, shape (n, 2) [m/s]
        The extension states now and asked for the next period (before the
        turn-rate limit, :func:`limit_turn`).
    theta : ndarray, shape (n,) [rad]
    travel : ndarray, shape (n,), int8
        The direction now: :data:`TRAVEL_NONE` (not travelled yet),
        :data:`TRAVEL_FORWARD` or :data:`TRAVEL_BACKWARD`.
    parks : ndarray, shape (n,), bool, optional
        The rows that park (:func:`parking`); None: every row.

    Returns
    -------
    travel_next : ndarray, shape (n,), int8
        Unchanged where ``chi_next`` is at rest.

    >>> east = np.array([0.0])
    >>> travel_direction(np.array([[0.05, 0.0]]), np.array([[-0.02, 0.0]]), east,
    ...                  np.array([TRAVEL_FORWARD], dtype=np.int8)).tolist()
    [-1]
    >>> travel_direction(np.array([[0.0, 0.0]]), np.array([[-0.02, 0.0]]), east,
    ...                  np.array([TRAVEL_NONE], dtype=np.int8)).tolist()
    [1]
    """
    n1, n2 = chi_next[..., 0], chi_next[..., 1]
    moves = n1 * n1 + n2 * n2 >= CHI_REST * CHI_REST
    if not np.count_nonzero(moves):
        return travel
    c1, c2 = chi[..., 0], chi[..., 1]
    vanished = (c1 * c1 + c2 * c2 < CHI_REST * CHI_REST) | (c1 * n1 + c2 * n2 < 0.0)
    ahead = n1 * np.cos(theta) + n2 * np.sin(theta)
    line = np.where(ahead < 0.0, TRAVEL_BACKWARD, TRAVEL_FORWARD)
    chosen = np.where(travel == TRAVEL_NONE, TRAVEL_FORWARD, line)
    out = np.where(vanished, chosen, travel)
    out = np.where((out == TRAVEL_BACKWARD) & (ahead > 0.0), TRAVEL_FORWARD, out)
    if parks is not None:
        out = np.where(parks, out, TRAVEL_FORWARD)
    out = np.where(out == TRAVEL_NONE, TRAVEL_FORWARD, out)
    return np.where(moves, out, travel).astype(np.int8)


def advance_extension(
    chi: np.ndarray,
    chi_dot: np.ndarray,
    dt: float,
    v1_max: np.ndarray,
    accel_max: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate the extension states one control period, with saturation.

    Explicit Euler ``chi + dt * chi_dot``, then the limits act on chi itself (state
    clamping, the anti-windup of this product): the change of chi is at most
    ``accel_max * dt`` in norm and ``|chi| <= v1_max``. Because ``|v1| <= |chi|``, the
    commanded speed then never exceeds its limits and chi never winds up beyond what
    the vehicle is asked to do. The turn-rate limit of the anti-windup is
    :func:`limit_turn`, applied after.

    Parameters
    ----------
    chi, chi_dot : ndarray, shape (n, 2)
    dt : float [s]
    v1_max, accel_max : ndarray, shape (n,) [m/s], [m/s^2]
        ``inf`` where unlimited.

    Returns
    -------
    chi_next : ndarray, shape (n, 2) [m/s]
    chi_dot_applied : ndarray, shape (n, 2) [m/s^2]
        ``(chi_next - chi) / dt``: the rate actually applied (use it for eq. (5)).
    """
    step = chi_dot * dt
    # A vector within its bound is scaled by 1.0, which leaves it as it is: the
    # scaling is made only where some vector exceeds its bound.
    step_norm = np.hypot(step[..., 0], step[..., 1])
    limit = accel_max * dt
    if np.count_nonzero(step_norm > limit):
        scale = np.where(step_norm > limit, limit / np.maximum(step_norm, 1e-300), 1.0)
        step = step * scale[..., None]
    nxt = chi + step
    norm = np.hypot(nxt[..., 0], nxt[..., 1])
    if np.count_nonzero(norm > v1_max):
        scale = np.where(norm > v1_max, v1_max / np.maximum(norm, 1e-300), 1.0)
        nxt = nxt * scale[..., None]
    return nxt, (nxt - chi) / dt


def limit_turn(
    chi: np.ndarray,
    theta: np.ndarray,
    limit: np.ndarray | float,
    travel: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Turn-rate anti-windup: keep chi where the vehicle can drive in one period.

    A unicycle heading ``theta`` can move, by the next period, only along directions
    within ``limit = v2_max * dt`` of its direction of travel (its heading, or the
    opposite where it travels backward, :func:`travel_direction`). A chi outside that
    cone is replaced by its projection on the nearer edge of the cone (its component
    along that direction, or zero when it points away): chi then stays what the
    vehicle can do, as with the speed and acceleration clamps, instead of rotating
    faster than the vehicle can turn while the heading falls behind for ever. The
    heading the controller asked for is returned as ``aim``: the heading loop of eq.
    (5) turns the vehicle towards it (see :func:`flat_inputs`), at rest included, so
    a vehicle facing away from its target turns (at up to ``v2_max``) before it
    drives. A chi at rest (``|chi| < CHI_REST``) is not limited.

    Parameters
    ----------
    chi : ndarray, shape (n, 2) [m/s]
        The extension states after the speed and acceleration clamps.
    theta : ndarray, shape (n,) [rad]
    limit : float or ndarray, shape (n,) [rad]
    travel : ndarray, shape (n,), int8, optional
        The direction of travel; default forward.

    Returns
    -------
    chi : ndarray, shape (n, 2) [m/s]
    aim : ndarray, shape (n,) [rad]
        The heading along the requested chi (its angle, or the opposite one where
        the vehicle travels backward) where it was outside the cone, NaN elsewhere.

    >>> chi, aim = limit_turn(np.array([[0.0, 1.0]]), np.array([0.0]), 0.1)
    >>> chi.round(3).tolist(), aim.round(4).tolist()
    ([[0.0, 0.0]], [1.5708])
    """
    c1, c2 = chi[..., 0], chi[..., 1]
    norm = np.hypot(c1, c2)
    angle = np.arctan2(c2, c1)
    if travel is not None and np.count_nonzero(travel == TRAVEL_BACKWARD):
        angle = np.where(travel == TRAVEL_BACKWARD, angle + np.pi, angle)
        sign = np.where(travel == TRAVEL_BACKWARD, -1.0, 1.0)
    else:
        sign = 1.0
    off = wrap_angle(angle - theta)
    outside = (np.abs(off) > limit) & (norm >= CHI_REST)
    if not np.count_nonzero(outside):
        nowhere = np.empty(norm.shape)
        nowhere.fill(np.nan)
        return chi, nowhere
    edge = CLIP(off, -limit, limit)
    along = sign * np.maximum(norm * np.cos(off - edge), 0.0)
    direction = theta + edge
    turned = np.empty(chi.shape)
    turned[..., 0] = along * np.cos(direction)
    turned[..., 1] = along * np.sin(direction)
    out = np.where(outside[..., None], turned, chi)
    return out, np.where(outside, angle, np.nan)


def discrete_spectral_radius(k_pos: float, k_vel: float, dt: float) -> float:
    """Spectral radius of the discrete error dynamics of eq. (6) with period ``dt``.

    With a vehicle that follows chi exactly, the tracking error ``e = x - x_ref`` and
    ``c = chi - x_ref'`` evolve under the report's forward-Euler update as
    ``e+ = e + dt c``, ``c+ = c + dt (k_pos e + k_vel c)``. The loop is stable only if
    the spectral radius of that matrix is below 1; for the report's gains
    (-100, -20) this requires ``dt < 0.2`` s.

    >>> round(discrete_spectral_radius(-100.0, -20.0, 0.01), 3)
    0.9
    >>> discrete_spectral_radius(-100.0, -20.0, 0.25) > 1.0
    True
    """
    m = np.array([[1.0, dt], [dt * k_pos, 1.0 + dt * k_vel]])
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def error_poles(k_pos: float, k_vel: float) -> np.ndarray:
    """Continuous-time poles of the tracking error of eq. (6), shape (2,) [1/s].

    With the vehicle following chi, ``e'' = k_pos e + k_vel e'``: the poles are the
    roots of ``s^2 - k_vel s - k_pos``. Both lie in the left half plane iff
    ``k_pos < 0`` and ``k_vel < 0`` (the report's sign convention).

    >>> error_poles(-100.0, -20.0).real.tolist()
    [-10.0, -10.0]
    """
    disc = np.sqrt(complex(k_vel * k_vel + 4.0 * k_pos))
    return np.array([(k_vel + disc) / 2.0, (k_vel - disc) / 2.0])


def max_stable_period(k_pos: float, k_vel: float) -> float:
    """Longest control period [s] for which eq. (6) under forward Euler is stable.

    The discrete error poles are ``z = 1 + dt s`` for the continuous poles ``s`` of
    :func:`error_poles`; ``|1 + dt s| < 1`` iff ``dt < -2 Re(s) / |s|^2``. The bound
    is the smallest over both poles: ``0.2`` s for the report's gains (``s = -10``
    double), ``0`` when the gains are not stable in continuous time (no period helps).
    :func:`discrete_spectral_radius` is below 1 exactly for ``0 < dt <`` this bound.

    >>> max_stable_period(-100.0, -20.0)
    0.2
    >>> max_stable_period(100.0, -20.0)
    0.0
    """
    if not (k_pos < 0 and k_vel < 0):
        return 0.0
    s = error_poles(k_pos, k_vel)
    return float(np.min(-2.0 * s.real / (s.real**2 + s.imag**2)))


def max_control_period(k_pos: float, k_vel: float) -> float:
    """Longest control period [s] the closed loop of eqs. (5)-(6) tolerates.

    Two conditions on the discrete error poles ``z = 1 + dt s``: ``|z| < 1`` (the linear
    bound of :func:`max_stable_period`), and ``Re z > 0`` for every pole, i.e.
    ``dt < 1 / max|Re s|``: with ``Re z < 0`` the error, hence chi, reverses direction
    from one period to the next, and a unicycle cannot follow (``v1 = |chi| >= 0``: it
    has to turn around instead of backing up). For the report's gains (``s = -10``
    double) the second condition is the binding one: ``0.1`` s, not the linear ``0.2``
    s. Measured on the full simulation (point stabilization from 0.2 m and 5 m): the
    report's gains converge at ``dt = 0.097`` s and diverge at ``0.103`` s; with poles
    ``-7.5 +- 6.6j`` the bound is ``0.133`` s (diverges from about ``0.137`` s); with
    poles ``-1 +- 1.7j`` it is the linear ``0.5`` s (diverges just above). For widely
    separated real poles it is conservative (poles ``-2, -8``: bound ``0.125`` s, the
    loop still converges at ``0.2`` s).

    >>> max_control_period(-100.0, -20.0)
    0.1
    >>> max_control_period(100.0, -20.0)
    0.0
    """
    linear = max_stable_period(k_pos, k_vel)
    if linear == 0.0:
        return 0.0
    s = error_poles(k_pos, k_vel)
    return float(min(linear, 1.0 / np.max(-s.real)))
