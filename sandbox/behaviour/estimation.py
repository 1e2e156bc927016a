"""The others' poses now, estimated from the broadcast copies and their commands.

The broadcast (:mod:`sandbox.behaviour.sensing`) gives every vehicle a copy of each
other vehicle's pose sent ``D = delay / dt`` periods ago, with white noise of standard
deviation ``sigma_p`` per coordinate (``sigma_theta`` on the heading), the last copy
held when a packet is lost; every receiver gets the same copy. What each vehicle also
knows of the others is the commands ``u = (v1, v2)`` their drives applied, up to the
last period (the filter's ``v1_prev``, ``v2_prev``). From the two,
:class:`BroadcastEstimate` keeps one estimate of every vehicle's pose *now*, the same
for every receiver:

1. **The drive's period** (:func:`drive_period`, exact for a free vehicle): the
   drive's control body moves at ``V_m = v1_m (cos, sin)(x3_m + v2_m dt / 2)`` over
   period ``m`` (:meth:`sandbox.physics.world.World.write_commands`), which the body
   reaches one substep into the period, so::

       x_(m+1) = x_m + dt ((1 - lag) V_m + lag V_(m-1)),
       x3_(m+1) = x3_m + dt ((1 - lag) v2_m + lag v2_(m-1)),   lag = 1 / substeps.

2. **The estimate at the copy's time** ``x~`` (``D`` periods ago) is carried one
   period by the commands of that period, then moved toward a new copy ``y`` by the
   gain ``K_m = max(1 / m, K)`` (``m`` the copies used so far, the first included;
   the heading's difference wrapped)::

       x~ <- x~ + K_m (y - x~),

   a running mean of the copies (each carried to the same time by the commands) for
   the first ``1 / K`` copies, a constant-gain filter after. A copy equal to the last
   one is a lost packet (a copy with noise is never equal to the last; without noise
   it is a vehicle at rest, whose copy adds nothing) and is not used.
3. **The estimate now** ``x^`` is ``x~`` carried through the commands of the last
   ``D`` periods (dead reckoning over the delay).

Its error, where the drive follows its commands (no contact, no saturated motor): no
lag and no bias (the commands carry the mean); per coordinate a standard deviation
of at most ``sigma_p sqrt(K)`` from the ``(1 / K)``-th copy on (the mean of ``m``
copies has variance ``sigma^2 / m <= K sigma^2``, and the recursion ``P' = (1 - K)^2
P + K^2 sigma^2`` keeps ``P <= K sigma^2``, tending to ``K sigma^2 / (2 - K)``), on
the heading ``sigma_theta sqrt(K)``. Where the drive does not follow its commands
(a contact, a shove), the error left decays by ``1 - K`` a copy: a time constant of
``dt / K``. Every row is its own vehicle: the estimate of stacked worlds is each
world's alone.
"""

from __future__ import annotations

import numpy as np

from sandbox.model.barriers import ESTIMATE_GAIN
from sandbox.model.dynamics import wrap_angle


def drive_period(
    pose: np.ndarray,
    last_velocity: np.ndarray,
    last_turn: np.ndarray,
    v1: np.ndarray,
    v2: np.ndarray,
    dt: float,
    lag: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Carry poses one period under the commands ``(v1, v2)``, the drive's way.

    Parameters
    ----------
    pose : ndarray, shape (n, 3) [m, m, rad]
        The poses at the period's start.
    last_velocity : ndarray, shape (n, 2) [m/s]
        The control velocity ``V`` of the period before.
    last_turn : ndarray, shape (n,) [rad/s]
        The turn rate of the period before.
    v1, v2 : ndarray, shape (n,) [m/s], [rad/s]
        The period's commands.
    dt : float [s]
    lag : float [1]
        The share of the period run at the last period's velocity (``1 /
        substeps``).

    Returns
    -------
    pose : ndarray, shape (n, 3)
        The poses at the period's end.
    velocity : ndarray, shape (n, 2) [m/s]
        The period's control velocity ``V``.

    Examples
    --------
    From rest, 1 m/s straight, 4 substeps: the first substep still at rest, so
    ``dt (1 - 1/4) = 0.75`` m in a period of 1 s.

    >>> out, v = drive_period(np.zeros((1, 3)), np.zeros((1, 2)), np.zeros(1),
    ...                       np.ones(1), np.zeros(1), 1.0, 0.25)
    >>> out.tolist(), v.tolist()
    ([[0.75, 0.0, 0.0]], [[1.0, 0.0]])
    """
    mid = pose[:, 2] + 0.5 * v2 * dt
    velocity = v1[:, None] * np.stack((np.cos(mid), np.sin(mid)), -1)
    out = np.empty_like(pose)
    out[:, :2] = pose[:, :2] + dt * ((1.0 - lag) * velocity + lag * last_velocity)
    out[:, 2] = pose[:, 2] + dt * ((1.0 - lag) * v2 + lag * last_turn)
    return out, velocity


class BroadcastEstimate:
    """Every vehicle's pose now, from the broadcast copies and the commands.

    Parameters
    ----------
    delay : int
        ``D``, the broadcast's delay in periods.
    gain : float
        ``K``, the filter's least gain, in (0, 1] (1: each copy alone, carried over
        the delay).
    dt : float [s]
    substeps : int
        The physics' substeps a period (the drive's lag is one of them).

    Examples
    --------
    A vehicle that starts from rest at the origin at 1 m/s along x (4 substeps,
    ``dt = 0.1`` s) is at 0.075, 0.175, 0.275, 0.375 m after 1-4 periods; copies 2
    periods late (the first held until then), exact: the estimate is where it is.

    >>> est = BroadcastEstimate(2, 0.1, 0.1, 4)
    >>> x = est.update(np.zeros((1, 3)), None, None)
    >>> for y in [0.0, 0.0, 0.075, 0.175]:
    ...     x = est.update(np.array([[y, 0.0, 0.0]]), np.ones(1), np.zeros(1))
    >>> np.round(x, 12).tolist()
    [[0.375, 0.0, 0.0]]
    """

    def __init__(self, delay: int, gain: float, dt: float, substeps: int) -> None:
        self.delay = int(delay)
        self.gain = float(gain)
        self.dt = float(dt)
        self.lag = 1.0 / max(int(substeps), 1)
        #: The estimate at the newest copy's time (``D`` periods ago), (n, 3).
        self.past: np.ndarray | None = None

    def _start(self, seen: np.ndarray) -> np.ndarray:
        n = len(seen)
        self.past = np.array(seen, dtype=float)
        self.velocity = np.zeros((n, 2))  # the control velocity before `past`
        self.turn = np.zeros(n)
        #: The commands of the last D + 1 periods, oldest first, (D + 1, n, 2).
        self.commands = np.zeros((self.delay + 1, n, 2))
        self.used = np.ones(n)  # copies used, the first included
        self.last = self.past.copy()
        return self.past.copy()

    def update(
        self,
        seen: np.ndarray,
        v1_prev: np.ndarray | None,
        v2_prev: np.ndarray | None,
    ) -> np.ndarray:
        """Take this period's copies; return the estimate of every pose now.

        Parameters
        ----------
        seen : ndarray, shape (n, 3) [m, m, rad]
            The copies held now.
        v1_prev, v2_prev : ndarray, shape (n,) or None
            The commands applied over the last period (None at the first period:
            the vehicles were at rest before it).

        Returns
        -------
        ndarray, shape (n, 3) [m, m, rad]
        """
        if self.past is None:
            return self._start(seen)
        n = len(seen)
        last = np.zeros((n, 2))
        if v1_prev is not None:
            last = np.stack((v1_prev, v2_prev), -1)
        self.commands = np.concatenate((self.commands[1:], last[None]), axis=0)
        oldest = self.commands[0]
        self.past, self.velocity = drive_period(
            self.past,
            self.velocity,
            self.turn,
            oldest[:, 0],
            oldest[:, 1],
            self.dt,
            self.lag,
        )
        self.turn = oldest[:, 1]
        fresh = np.any(seen != self.last, axis=1)
        self.last = np.array(seen, dtype=float)
        self.used += fresh
        gain = np.where(fresh, np.maximum(1.0 / self.used, self.gain), 0.0)
        innovation = seen - self.past
        innovation[:, 2] = wrap_angle(innovation[:, 2])
        self.past = self.past + gain[:, None] * innovation
        now, velocity, turn = self.past, self.velocity, self.turn
        for u in self.commands[1:]:
            now, velocity = drive_period(
                now, velocity, turn, u[:, 0], u[:, 1], self.dt, self.lag
            )
            turn = u[:, 1]
        return now


def platoon_estimate(scenario, dt: float, substeps: int) -> BroadcastEstimate | None:
    """The estimate the platoon's law and recovery see under the braking barrier.

    With sensing and ``safety: {filter: cbf, barrier: braking}`` the formation law,
    the recovery strategy and the safety filter all see the others through the
    estimate (:class:`BroadcastEstimate`, least gain ``safety.estimate_gain``), not
    the copies as received: a law that differentiates its leader's copies, or a
    strategy steering round a neighbour's, turns 2 cm of white noise into commands
    that swing from one period to the next, and a vehicle in a runaway's way does
    not leave it. The failure detector keeps the copies (its residual is their
    difference from the commands). None otherwise: every other run sees the copies,
    as before.

    Parameters
    ----------
    scenario : Scenario
    dt : float [s]
    substeps : int
    """
    sensing, safety = scenario.sensing, scenario.safety
    if not (
        sensing.position_noise or sensing.heading_noise or sensing.delay or sensing.loss
    ):
        return None
    if safety.filter != "cbf" or safety.params.get("barrier") != "braking":
        return None
    gain = safety.params.get("estimate_gain")
    gain = ESTIMATE_GAIN if gain is None else float(gain)
    return BroadcastEstimate(int(round(sensing.delay / dt)), gain, dt, substeps)
