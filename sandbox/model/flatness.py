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

# : Below this speed ``|chi|`` [m/s] the direction of chi is undefined (a vehicle at
# rest):
#: the vehicle holds its heading (v2 = 0) instead of dividing by zero in eq. (5), and
#: stands still (v1 = 0): driving at ``|chi|`` along a heading unrelated to chi pushes
#: a parked vehicle off its point (eq. (4) then ends in a millimetre orbit spinning at
#: about 5 rad/s, or a 0.5 m orbit when ``v2_max`` is 3 rad/s).
CHI_HOLD = 1e-3
#: The feedforward of eq. (5) divides by ``max(|chi|^2, CHI_REG^2)`` [m/s]: exact above
#: this speed, bounded near rest (where numerical noise in chi would otherwise be turned
#: into turn rates of thousands of rad/s).
CHI_REG = 0.01


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
) -> tuple[np.ndarray, np.ndarray]:
    """Control inputs ``(v1, v2)`` from the extension states, eq. (5).

    ``v1 = |chi|``; ``v2`` is the turn rate of chi (flatness feedforward, eq. (3)) minus
    ``kp`` times the heading error ``x3 - angle(chi)``, wrapped to ``[-pi, pi)``. Where
    ``|chi| < CHI_HOLD`` the angle of chi is undefined and the vehicle holds its heading
    and stands still (``v1 = v2 = 0``); below ``CHI_REG`` the feedforward's divisor is
    floored at ``CHI_REG^2``. No NaN is ever produced for finite inputs.

    Parameters
    ----------
    theta : ndarray, shape (n,) [rad]
    chi, chi_dot : ndarray, shape (n, 2) [m/s], [m/s^2]
    kp : float or ndarray, shape (n,) [1/s]
    aim : ndarray, shape (n,) [rad], optional
        Where not NaN, the direction the turn-rate anti-windup held chi back from
        (:func:`limit_turn`): the heading error is measured to it instead of to chi.

    Returns
    -------
    v1 : ndarray, shape (n,) [m/s]
    v2 : ndarray, shape (n,) [rad/s]
    """
    c1, c2 = chi[..., 0], chi[..., 1]
    norm2 = c1 * c1 + c2 * c2
    v1 = np.sqrt(norm2)  # eq. (5)
    defined = norm2 >= CHI_HOLD * CHI_HOLD
    every = np.count_nonzero(defined) == defined.size  # where(defined, x, 0) is x
    safe = np.maximum(norm2, CHI_REG * CHI_REG)
    feedforward = (-c2 * chi_dot[..., 0] + c1 * chi_dot[..., 1]) / safe  # eq. (5)
    # "arctan2(chi1, chi2)" in the report is the angle of the vector (chi1, chi2).
    heading_error = wrap_angle(theta - np.arctan2(c2, c1))
    v2 = feedforward - kp * heading_error  # eq. (5)
    if not every:
        v2 = np.where(defined, v2, 0.0)
    if aim is not None:
        turning = ~np.isnan(aim)
        if np.count_nonzero(turning):  # chi held back by the turn limit: turn to aim
            toward = -kp * wrap_angle(theta - np.where(turning, aim, 0.0))
            if not every:
                feedforward = np.where(defined, feedforward, 0.0)
            v2 = np.where(turning, feedforward + toward, v2)
    return (v1 if every else np.where(defined, v1, 0.0)), v2


def advance_extension(
    chi: np.ndarray,
    chi_dot: np.ndarray,
    dt: float,
    v1_max: np.ndarray,
    accel_max: np.ndarray,
    theta: np.ndarray | None = None,
    turn_max: np.ndarray | float | None = None,
) -> tuple[np.ndarray, ...]:
    """Integrate the extension states one control period, with saturation.

    Explicit Euler ``chi + dt * chi_dot``, then the limits act on chi itself (state
    clamping, the anti-windup of this product): the change of chi is at most
    ``accel_max * dt`` in norm and ``|chi| <= v1_max``. Because ``v1 = |chi|``, the
    commanded speed then never exceeds its limits and chi never winds up beyond what the
    vehicle is asked to do. With a turn-rate limit (``theta`` and ``turn_max`` given),
    chi is also kept within the directions the vehicle can drive along by the next
    period (:func:`limit_turn`).

    Parameters
    ----------
    chi, chi_dot : ndarray, shape (n, 2)
    dt : float [s]
    v1_max, accel_max : ndarray, shape (n,) [m/s], [m/s^2]
        ``inf`` where unlimited.
    theta : ndarray, shape (n,) [rad], optional
        Headings, for the turn-rate limit.
    turn_max : float or ndarray, shape (n,) [rad/s], optional
        ``v2_max`` (``inf`` where unlimited); None: no turn-rate limit.

    Returns
    -------
    chi_next : ndarray, shape (n, 2) [m/s]
    chi_dot_applied : ndarray, shape (n, 2) [m/s^2]
        ``(chi_next - chi) / dt``: the rate actually applied (use it for eq. (5)).
    aim : ndarray, shape (n,) [rad]
        Only with ``turn_max``: see :func:`limit_turn` (pass it to
        :func:`flat_inputs`).
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
        norm = None  # changed: limit_turn measures it again
    if turn_max is None:
        return nxt, (nxt - chi) / dt
    nxt, aim = limit_turn(nxt, theta, turn_max * dt, norm)
    return nxt, (nxt - chi) / dt, aim


def limit_turn(
    chi: np.ndarray,
    theta: np.ndarray,
    limit: np.ndarray | float,
    norm: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Turn-rate anti-windup: keep chi where the vehicle can drive in one period.

    A unicycle heading ``theta`` can move, by the next period, only along directions
    within ``limit = v2_max * dt`` of its heading. A chi outside that cone is replaced
    by its projection on the nearer edge of the cone (its component along that
    direction, or zero when it points away): chi then stays what the vehicle can do,
    as with the speed and acceleration clamps, instead of rotating faster than the
    vehicle can turn while the heading falls behind for ever. The direction the
    controller asked for is returned as ``aim``: the heading loop of eq. (5) turns
    the vehicle towards it (see :func:`flat_inputs`), at rest included, so a vehicle
    facing away from its target turns (at up to ``v2_max``) before it drives.

    Parameters
    ----------
    chi : ndarray, shape (n, 2) [m/s]
        The extension states after the speed and acceleration clamps.
    theta : ndarray, shape (n,) [rad]
    limit : float or ndarray, shape (n,) [rad]
    norm : ndarray, shape (n,) [m/s], optional
        ``|chi|`` if known (the same numbers as measuring it here).

    Returns
    -------
    chi : ndarray, shape (n, 2) [m/s]
    aim : ndarray, shape (n,) [rad]
        Angle of the requested chi where it was outside the cone, NaN elsewhere.

    >>> chi, aim = limit_turn(np.array([[0.0, 1.0]]), np.array([0.0]), 0.1)
    >>> chi.round(3).tolist(), aim.round(4).tolist()
    ([[0.0, 0.0]], [1.5708])
    """
    c1, c2 = chi[..., 0], chi[..., 1]
    if norm is None:
        norm = np.hypot(c1, c2)
    angle = np.arctan2(c2, c1)
    off = wrap_angle(angle - theta)
    outside = (np.abs(off) > limit) & (norm >= CHI_HOLD)
    if not np.count_nonzero(outside):
        nowhere = np.empty(norm.shape)
        nowhere.fill(np.nan)
        return chi, nowhere
    edge = CLIP(off, -limit, limit)
    along = np.maximum(norm * np.cos(off - edge), 0.0)
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
