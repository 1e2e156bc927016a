"""The car's reachable set in the CBF filter's quadratic program (``model: bicycle``).

The filter of :mod:`sandbox.behaviour.safety.cbf` solves for ``z = (v1, l v2)``, the
look-ahead point's velocity in the vehicle's frame, within a box of input bounds. A car
(:mod:`sandbox.model.bicycle`) executes only the turn rate ``v2 = v1 tan(delta) / L``
of a steering angle ``delta`` it can reach this period, ``delta_lo <= delta <=
delta_hi`` (its last angle moved by at most ``max_steer_rate h``, within
``max_steer``: :meth:`~sandbox.model.bicycle.CarSteering.reach`). In ``z`` that is
``z2 = k z1`` with ``k`` between ``k_lo = l tan(delta_lo) / L`` and ``k_hi = l
tan(delta_hi) / L``: two cones through the origin, one driving forward (``z1 >= 0``),
the two half-planes::

    z2 - k_hi z1 <= 0,      k_lo z1 - z2 <= 0,

and its mirror image reversing (``z1 <= 0``). Their union is not convex; each is.
:class:`CarCone` solves a car's problem twice, its box and barrier rows with either
cone's two rows as hard rows (like the box), and keeps the better solution (the
least slack, then the nearer to the nominal; forward on a tie): the exact optimum
over the union. Both contain ``z = 0``; neither turns at rest. A car's nominal ``z``
is first made the command the steering stage would execute of it
(:func:`~sandbox.model.bicycle.steer_commands`), so a filter that changes nothing
for a car reports nothing; the cars are solved in groups of their own, so a
unicycle's problem, and its numbers, are those it has without cars.

A car takes no right-hand rule (:mod:`~sandbox.behaviour.safety.right_hand`): the
rule turns a stalled vehicle's nominal velocity to its right, which a car, unable to
turn where it stands, can follow only by driving forward at full lock; in the exact
ring of ``scenarios/safety/circle_swap_20.yaml`` that walked every car into its
neighbours.

A command in either cone is executed as it is (up to rounding): the steering stage
after the filter finds the angle it asks for within the car's reach. Where the box
and a cone have no common point (the box keeps the car's speed on the other side of
zero, or a steering-rate limit holds the wheels turned at a speed the box keeps too
high for the turn-rate bound), that cone is not used; where neither meets the box the
car has no cone rows that period, and the steering stage changes what the filter
chose.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.safety.accounting import FilterStep
from sandbox.behaviour.safety.qp import TOLERANCE, solve
from sandbox.model.bicycle import CarLimits, CarSteering, steer_commands

if TYPE_CHECKING:
    from sandbox.plugins.contexts import FilterContext

#: A group's problems: the half-planes ``mat z <= off``, (k, c, 2) and (k, c), and
#: which may be relaxed, (k, c).
Problems = tuple[np.ndarray, np.ndarray, np.ndarray]


class CarCone:
    """The cars of one step of the filter and their cones (see the module docstring).

    Parameters
    ----------
    steering : CarSteering
        The cars among the filter's rows.
    look : float [m]
        The look-ahead distance ``l``.
    dt : float [s]
        The control period.
    box : tuple of ndarray, each shape (n,)
        ``lo1, hi1, lo2, hi2``: the bounds of ``z`` [m/s] (of the filtered rows).
    who : ndarray, shape (w,) int
        The filtered rows.
    v2_max : float or ndarray, shape (n,) [rad/s]
        The vehicles' turn-rate limits.
    """

    def __init__(
        self,
        steering: CarSteering,
        look: float,
        dt: float,
        box: tuple[np.ndarray, ...],
        who: np.ndarray,
        v2_max: float | np.ndarray,
    ) -> None:
        self.steering, self.look, self.dt = steering, look, dt
        n = len(steering.wheelbase)
        self._v2_max = np.broadcast_to(np.asarray(v2_max, dtype=float), (n,))
        #: The filtered cars, (n,) bool.
        self.car = np.zeros(n, dtype=bool)
        self.car[who] = np.isfinite(steering.wheelbase[who])
        rows = self.car.nonzero()[0]
        lo1, hi1, lo2, hi2 = (b[rows] for b in box)
        wheelbase = steering.wheelbase[rows]
        least, most = steering.reach(dt)
        k_lo = look * np.tan(least[rows]) / wheelbase
        k_hi = look * np.tan(most[rows]) / wheelbase
        forward = np.zeros((len(rows), 2, 2))
        forward[:, 0, 0], forward[:, 0, 1] = -k_hi, 1.0  # z2 - k_hi z1 <= 0
        forward[:, 1, 0], forward[:, 1, 1] = k_lo, -1.0  # k_lo z1 - z2 <= 0
        forward /= np.hypot(forward[..., 0], forward[..., 1])[..., None]
        self._rows = np.full(n, -1, dtype=np.intp)
        self._rows[rows] = np.arange(len(rows))
        #: Each car's forward and reverse cone rows, (cars, 2, 2) each; zero (the
        #: QP's padding) where the cone has no common point with the box.
        self._cones = []
        # Each cone's z1 nearest 0 within the box, where its z2 are nearest 0.
        ahead, behind = np.maximum(lo1, 0.0), np.minimum(hi1, 0.0)
        for sign, z1, inside in (
            (1.0, ahead, ahead <= hi1),
            (-1.0, behind, behind >= lo1),
        ):
            z2 = np.stack((k_lo * z1, k_hi * z1))
            meets = inside & (z2.min(axis=0) <= hi2) & (z2.max(axis=0) >= lo2)
            cone = sign * forward
            cone[~meets] = 0.0
            self._cones.append((cone, meets))

    @classmethod
    def of(
        cls,
        ctx: FilterContext,
        look: float,
        speed_only: bool,
        box: tuple[np.ndarray, ...],
        who: np.ndarray,
    ) -> CarCone | None:
        """The cones of the step, or None: no car among the rows, or ``speed_only``.

        ``projection: speed`` keeps the controller's turn rate, which a car cannot
        keep at another speed: it has no cone.
        """
        steering = ctx.steering
        if steering is None or speed_only:
            return None
        if not np.isfinite(steering.wheelbase[who]).any():
            return None
        return cls(steering, look, ctx.dt, box, who, ctx.v2_max)

    def nominal(self, v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
        """``v2`` [rad/s] with each car's the turn rate its steering would execute.

        The filter's nominal command of a car is what the steering stage makes of
        the controller's (:func:`~sandbox.model.bicycle.steer_commands`), which lies
        in one of the car's cones.
        """
        rows = self.car.nonzero()[0]
        s = self.steering
        limits = CarLimits.of(
            wheelbase=s.wheelbase[rows],
            max_steer=s.max_steer[rows],
            max_steer_rate=s.max_steer_rate[rows],
            v2_max=self._v2_max[rows],
        )
        out = v2.copy()
        turn, _ = steer_commands(v1[rows], v2[rows], s.held[rows], limits, self.dt)
        out[rows] = turn
        return out

    def add(self, group: np.ndarray, problems: Problems, half: int) -> Problems:
        """A group of cars' problems with the cone ``half`` (0 forward, 1 reverse).

        Its two rows appended to each problem, hard; ``problems`` as
        :func:`~sandbox.behaviour.safety.qp.bounded_problems` makes them.
        """
        mat, off, soft = problems
        k = len(group)
        cone = self._cones[half][0][self._rows[group]]
        return (
            np.concatenate((mat, cone), axis=1),
            np.concatenate((off, np.zeros((k, 2))), axis=1),
            np.concatenate((soft, np.zeros((k, 2), dtype=bool)), axis=1),
        )

    def solve(
        self, group: np.ndarray, z0: np.ndarray, problems: Problems
    ) -> tuple[np.ndarray, np.ndarray, Problems]:
        """The nearest point to ``z0`` over either cone of each car of ``group``.

        :func:`~sandbox.behaviour.safety.qp.solve` with the forward cone and with
        the reverse cone; each car keeps the solution of least slack, then the
        nearer to ``z0`` (the forward one on a tie), and its problem with that cone
        (for the right-hand rule's second solve). A group of unicycles is solved as
        it is.

        Returns
        -------
        z : ndarray, shape (k, 2) [m/s]
        slack : ndarray, shape (k,) [m/s]
        problems : tuple
            Each vehicle's problem as solved.
        """
        if not self.car[group[0]]:
            return (*solve(z0, *problems), problems)
        fwd, rev = self.add(group, problems, 0), self.add(group, problems, 1)
        zf, sf = solve(z0, *fwd)
        zr, sr = solve(z0, *rev)
        cars = self._rows[group]
        ok_f, ok_r = self._cones[0][1][cars], self._cones[1][1][cars]
        sf_of = np.where(ok_f | ~ok_r, sf, np.inf)
        sr_of = np.where(ok_r, sr, np.inf)
        df = np.sum((zf - z0) ** 2, axis=1)
        dr = np.sum((zr - z0) ** 2, axis=1)
        tie = np.abs(sr_of - sf_of) <= TOLERANCE
        back = (sr_of < sf_of - TOLERANCE) | (tie & (dr < df))
        kept = (
            np.where(back[:, None, None], rev[0], fwd[0]),
            np.where(back[:, None], rev[1], fwd[1]),
            fwd[2],  # the same in both
        )
        return np.where(back[:, None], zr, zf), np.where(back, sr, sf), kept


def solved_groups(
    who: np.ndarray, counts: np.ndarray, cone: CarCone | None, clipped: bool = True
) -> list[tuple[int, np.ndarray]]:
    """The filter's problems by size: ``(m, group)``, ``m`` barrier rows each.

    The vehicles ``who`` with ``counts[who] == m`` are solved together, ``m``
    ascending; with cars (``cone``), a group's unicycles apart from its cars.

    Parameters
    ----------
    who : ndarray, shape (w,) int
        The vehicles solved.
    counts : ndarray, shape (n,) int
        Each vehicle's barrier rows.
    cone : CarCone or None
    clipped : bool
        Whether a vehicle without a barrier row is clipped to its box apart (then
        only the cars among them are given: their cone is not a clip).

    >>> solved_groups(np.arange(4), np.array([1, 0, 1, 2]), None)
    [(1, array([0, 2])), (2, array([3]))]
    """
    out = []
    for m in np.unique(counts[who]).tolist():
        group = who[counts[who] == m]
        if cone is None:
            if m or not clipped:
                out.append((m, group))
            continue
        car = cone.car[group]
        parts = [group[car]] if m == 0 and clipped else [group[~car], group[car]]
        out.extend((m, part) for part in parts if len(part))
    return out


def with_cars(
    car: np.ndarray,
    fast: tuple[np.ndarray, np.ndarray, FilterStep],
    cars: tuple[np.ndarray, np.ndarray, FilterStep],
) -> tuple[np.ndarray, np.ndarray, FilterStep]:
    """The compiled step's commands and counters with the cars' rows of ``cars``.

    The compiled velocity step knows no cone: a step with cars is also made by
    numpy for the cars' rows, whose commands, ``active`` and ``slack`` replace the
    compiled step's there (each vehicle solves alone, so the unicycles' rows are
    those they have without cars). Its ``rows``, least barrier and each vehicle's
    are the compiled step's.

    Parameters
    ----------
    car : ndarray, shape (n,), bool
        The cars' rows.
    fast, cars : tuple
        ``(v1, v2, step)`` of the compiled step and of numpy's.
    """
    v1, v2, step = fast
    v1c, v2c, stepc = cars
    v1[car], v2[car] = v1c[car], v2c[car]
    step.active[car], step.slack[car] = stepc.active[car], stepc.slack[car]
    return v1, v2, step
