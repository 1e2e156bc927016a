"""What the CBF filter keeps between steps and what its parts pass to each other.

:class:`CBFState` holds the filter's parameters, the vehicles' limits, the neighbour
index and, for ``barrier: braking`` under sensing, the estimate of the others' poses;
:func:`auto_range` and :func:`braking_range` bound the distance beyond which no
condition of the velocity or the braking barrier can bind; :class:`Brakings` is every
vehicle's braking, which the braking barrier's rows
(:mod:`~sandbox.behaviour.safety.braking`), its check
(:mod:`~sandbox.behaviour.safety.braking_check`) and its runs
(:mod:`~sandbox.behaviour.safety.running`) read. The filter itself is
:mod:`sandbox.behaviour.safety.cbf`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.estimation import BroadcastEstimate
from sandbox.geometry.neighbours import neighbour_search
from sandbox.model.barriers import ESTIMATE_GAIN, sensing_margin

if TYPE_CHECKING:
    from sandbox.plugins.contexts import FilterContext

#: The speed bound used where a vehicle has no ``v1_max`` [m/s] (the loop's bound of a
#: diverged run).
UNLIMITED_SPEED = 1e3


def per_vehicle(value: float | np.ndarray, n: int) -> np.ndarray:
    """A scalar or per-vehicle value as an array of shape (n,) (a read-only view)."""
    return np.broadcast_to(np.asarray(value, dtype=float), (n,))


def auto_range(
    v1_max: np.ndarray,
    v2_max: np.ndarray,
    diameter: np.ndarray,
    gamma: float,
    margin: float,
    look_ahead: float,
) -> float:
    """Distance [m] beyond which no barrier condition can bind.

    Look-ahead points move at most ``s = sqrt(v1_max^2 + (l v2_max)^2)``, so a gap
    closes at most at ``2 s``; the pair's condition ``2 r r' >= -gamma (r^2 - D^2)``
    holds at any velocity for ``r >= 2 s / gamma + sqrt((2 s / gamma)^2 + D^2)``, and
    each half then holds at the velocities of the last period. Plus ``l`` (the
    conditions toward failed vehicles use their centres). Unlimited speeds give
    ``inf``.

    >>> round(auto_range(np.array([2.0]), np.array([4.0]), np.array([0.5]),
    ...                  2.0, 0.05, 0.1), 3)
    4.313
    """
    lateral = np.where(np.isfinite(v2_max), look_ahead * v2_max, v1_max)
    s = float(np.max(np.hypot(v1_max, lateral)))
    if not np.isfinite(s):
        return np.inf
    big_d = float(np.max(diameter)) + 2.0 * look_ahead + margin
    q = 2.0 * s / gamma
    return q + float(np.sqrt(q * q + big_d * big_d)) + look_ahead


class CBFState:
    """What the filter keeps between steps: parameters, limits, the neighbour index."""

    def __init__(self, ctx: FilterContext) -> None:
        p = ctx.params
        n = len(ctx.pos)
        self.gamma = float(p["gamma"])
        self.margin = float(p["margin"])
        self.look = float(p["look_ahead"])
        self.speed_only = p["projection"] == "speed"
        self.broadcast = p["neighbour_velocity"] == "broadcast"
        self.reverse = bool(p["reverse"])
        self.max_rows = int(p["max_constraints"])
        # at most a right angle (1.5708 is pi / 2 as written)
        self.pass_right = min(float(p.get("pass_right") or 0.0), np.pi / 2)
        self.priority = p.get("priority") or "none"  # the rule's ordering (priority.py)
        v1_max = per_vehicle(ctx.v1_max, n)
        v2_max = per_vehicle(ctx.v2_max, n)
        self.v1_max = np.where(np.isfinite(v1_max), v1_max, UNLIMITED_SPEED)
        # The look-ahead point's sideways speed l v2 (v1_max where v2 is unlimited).
        self.lateral = np.where(np.isfinite(v2_max), self.look * v2_max, self.v1_max)
        self.accel = per_vehicle(ctx.accel_max, n).copy()
        self.braking = p.get("barrier", "velocity") == "braking"
        #: The margin for what the vehicles sense of each other [m] (braking only).
        self.sensed = 0.0
        #: The estimate of the others' poses from the broadcast (braking only).
        self.estimate: BroadcastEstimate | None = None
        if self.braking and ctx.sensing is not None:
            gain = p.get("estimate_gain")
            gain = ESTIMATE_GAIN if gain is None else float(gain)
            self.sensed = sensing_margin(
                ctx.sensing.get("position_noise", 0.0),
                ctx.sensing.get("heading_noise", 0.0),
                gain,
                self.look,
                float(np.max(self.v1_max)),
                float(np.min(self.accel)),
                ctx.dt,
            )
            delay = int(round(ctx.sensing.get("delay", 0.0) / ctx.dt))
            self.estimate = BroadcastEstimate(delay, gain, ctx.dt, ctx.substeps)
        radius = p.get("range")
        if radius is None:
            radius = auto_range(
                v1_max, v2_max, ctx.diameter, self.gamma, self.margin, self.look
            )
        if not np.isfinite(radius):
            radius = auto_range(
                self.v1_max, v2_max, ctx.diameter, self.gamma, self.margin, self.look
            )
        if self.braking and p.get("range") is None:
            radius = braking_range(
                self.v1_max,
                self.lateral,
                self.accel,
                ctx.diameter,
                self.margin + self.sensed,
                self.look,
                ctx.dt,
            )
        self.range = float(radius)
        # pairs within each world only, every pair of a small world
        self.neighbours = neighbour_search(ctx.worlds, n // ctx.worlds, self.range)
        #: The C loop's arguments kept between steps (filter_kernel.Arguments).
        self.c_args = None


def braking_range(
    v1_max: np.ndarray,
    lateral: np.ndarray,
    accel: np.ndarray,
    diameter: np.ndarray,
    margin: float,
    look_ahead: float,
    dt: float,
) -> float:
    """Distance [m] beyond which no braking-barrier condition can bind.

    A braking from ``v1_max`` runs at most ``S = v1_max (v1_max / a + dt) / 2 +
    v1_max dt`` (the first period at the command's speed), a vehicle that does not
    brake at most ``s (v1_max / a_min + 2 dt)`` meanwhile (``s = sqrt(v1_max^2 +
    lateral^2)``, the look-ahead points' top speed), so ``H >= r - D - 2 X`` at a
    distance ``r`` of the points, ``X`` the larger travel. A condition binds only if
    a command within the bounds loses more than ``rho H`` against the braking
    command: ``|g . dz| <= G = (2 dt + v1_max / a_min) 2 a dt + dt (1 + S / l) 2
    lateral``, ``rho >= a_min / (a_min + a_max)``. Beyond ``D + l + 2 X + G /
    rho`` none does.

    >>> round(braking_range(np.array([2.0]), np.array([0.4]), np.array([5.0]),
    ...                     np.array([0.5]), 0.05, 0.1, 0.01), 3)
    2.732
    """
    v = float(np.max(v1_max))
    q = float(np.max(lateral))
    s = float(np.max(np.hypot(v1_max, lateral)))
    a_min, a_max = float(np.min(accel)), float(np.max(accel))
    if not (np.isfinite(s) and np.isfinite(a_max) and a_min > 0):
        return np.inf
    stop = v / a_min + dt  # [s] the braking's duration, the first period included
    travel = max(0.5 * v * stop + v * dt, s * (stop + dt))
    reach = (stop + dt) * 2.0 * a_max * dt
    reach += dt * (1.0 + (0.5 * v * stop + v * dt) / look_ahead) * 2.0 * q
    big_d = float(np.max(diameter)) + 2.0 * look_ahead + margin
    return big_d + look_ahead + 2.0 * travel + reach * (a_min + a_max) / a_min


@dataclass
class Brakings:
    """Every vehicle's braking from this state on, period by period.

    The drive reaches a command one substep into the period (``lag = 1 /
    substeps`` of it at the last command), so a period at the speeds ``s_(m-1)``
    then ``s_m`` runs ``dt u_m``, ``u_m = (1 - lag) s_m + lag s_(m-1)`` (``s_(-1) =
    v1^``); its first period also runs ``lag dt l v2^`` sideways and turns the
    heading by ``lag dt v2^``, along which the rest runs (``heading``).

    Attributes
    ----------
    first : ndarray, shape (n,) [m/s]
        The braking command's speed, ``v1^`` moved ``max_accel dt`` toward 0.
    speeds : ndarray, shape (n, S) [m/s]
        ``s_m`` of the periods (0 once stopped); ``S - 1`` periods in all, at least
        one at rest.
    travel : ndarray, shape (n, S) [m]
        Distance run by the start of each period.
    slope : ndarray, shape (n, S) [s]
        ``d travel / d v1`` of the first period's speed.
    heading, side : ndarray, shape (n, 2)
        The heading ``e`` now and ``e^perp``.
    path, path_side : ndarray, shape (n, 2)
        The heading of the braking after the first period, and its ``e^perp``.
    moves : ndarray, shape (n,) int
        The periods in which the braking moves.
    lag : float [1]
    """

    first: np.ndarray
    speeds: np.ndarray
    travel: np.ndarray
    slope: np.ndarray
    heading: np.ndarray
    side: np.ndarray
    path: np.ndarray
    path_side: np.ndarray
    moves: np.ndarray
    lag: float
