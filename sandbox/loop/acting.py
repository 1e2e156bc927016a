"""The act stage of K worlds: the commands of a period, from the plan to the drives.

:meth:`Acting.commands` advances the flatness controller (eqs. (5)-(6)) of every
vehicle towards its planned target (or the caller's override), filters the commands
for safety (:mod:`sandbox.loop.safety`), then applies the open-loop schedules
(:mod:`sandbox.loop.schedules`), the caller's command overrides (within the vehicle's
limits) and the failures (:class:`~sandbox.model.failures.Failures`), in that order,
and returns what the period applies (:class:`Acted`). Where the fleet has cars
(:mod:`sandbox.loop.steering`) their rows take the car's controller and every
command they execute is steered within their limits; the unicycles' rows are as
they are without.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from sandbox.loop.detecting import Detecting
from sandbox.loop.layout import Layout
from sandbox.loop.liveness import Failed
from sandbox.loop.plan import Plan
from sandbox.loop.safety import Safety
from sandbox.loop.schedules import CommandSchedules
from sandbox.loop.state import Fleet, limits, uniform
from sandbox.loop.steering import CarDrive
from sandbox.model.dynamics import CLIP
from sandbox.model.failures import Failures
from sandbox.model.flatness import (
    CHI_REST,
    TRAVEL_BACKWARD,
    TRAVEL_FORWARD,
    Gains,
)
from sandbox.model.kernels import Controller
from sandbox.run.record import MODE_EXTERNAL, MODE_FAILED

#: An override of one kind: the (N, 2) rows and the (N,) mask of the overridden.
Override = tuple[np.ndarray, np.ndarray] | None


class Acted(NamedTuple):
    """What a period applies: the commands, the failed rows, modes and ``chi``.

    Attributes
    ----------
    v1, v2 : ndarray, shape (N,) [m/s], [rad/s]
        The commands applied over the period.
    failed : ndarray, shape (N,), bool
        The vehicles with an active failure.
    mode : ndarray, shape (N,), int8
        ``run.MODE_*`` codes of the period.
    chi : ndarray, shape (N, 2) [m/s]
        The controllers' extension states for ``t_k+1``.
    travel : ndarray, shape (N,), int8
        Their directions of travel for ``t_k+1``
        (:func:`~sandbox.model.flatness.travel_direction`).
    target : ndarray, shape (N, 2) [m], or None
        The targets tracked where the caller overrode them (None: the plan's).
    steer : ndarray, shape (N,) [rad]
        The cars' steering angles over the period (the fleet's own ``steer``, as
        it was, where the loop has no car).
    """

    v1: np.ndarray
    v2: np.ndarray
    failed: np.ndarray
    mode: np.ndarray
    chi: np.ndarray
    travel: np.ndarray
    target: np.ndarray | None
    steer: np.ndarray


class Acting:
    """The controller, the limits and the schedules of a loop's K worlds.

    Parameters
    ----------
    layout : Layout
    fleet : Fleet
        The fleet (its gains and limits, its cars).
    safety : Safety
    detecting : Detecting
    failures : Failures
    """

    def __init__(
        self,
        layout: Layout,
        fleet: Fleet,
        safety: Safety,
        detecting: Detecting,
        failures: Failures,
    ) -> None:
        self._layout = layout
        self._safety, self._detecting, self._failures = safety, detecting, failures
        # Gains and limits: scalars when equal over every row, else row arrays.
        keys = ("k1", "k2", "k3", "k4", "kp")
        gains = Gains(**{k: uniform(getattr(fleet.gains, k)) for k in keys})
        self.v1_max, self.v2_max, self.accel_max = limits(fleet)
        # The turn-rate limit of the anti-windup: None when no vehicle has one.
        turn_max = None if np.all(np.isinf(fleet.v2_max)) else self.v2_max
        self.controller = Controller(
            gains, layout.h, self.v1_max, self.accel_max, self.v2_max, turn_max
        )
        self.schedules = CommandSchedules(layout.scenarios, layout.n)
        self._scheduled = len(self.schedules) > 0
        self._fails = len(failures) > 0  # else no vehicle ever fails
        self._commanded_rows = np.flatnonzero(fleet.commanded)
        #: The car rows' controller and steering (None: every row is a unicycle).
        self.cars = CarDrive.build(fleet, layout.h)
        # The commands sent last period, and the rows whose drive did otherwise
        # (a failure that lasts), None when no row did (see _believed_last).
        self._sent: tuple[np.ndarray, np.ndarray] | None = None
        self._hidden: np.ndarray | None = None

    def commands(
        self,
        t: float,
        fleet: Fleet,
        plan: Plan,
        known: np.ndarray,
        seen: np.ndarray | None,
        live: np.ndarray,
        commands: Override,
        targets: Override,
        shifts: Override,
        failed: Failed,
        worlds: Any,
    ) -> Acted:
        """The commands for the period from ``t`` [s]: controller, overrides, failures.

        Parameters
        ----------
        t : float [s]
        fleet : Fleet
            The state at ``t`` and the last period's commands.
        plan : Plan
            The period's plan.
        known : ndarray, shape (N,), bool
            The vehicles believed failed.
        seen : ndarray, shape (N, 3), or None
            The broadcast copies (None: the truth).
        live : ndarray, shape (K,), bool
            The live worlds (a view: a world that ends here is left out after).
        commands, targets, shifts : tuple or None
            The caller's overrides (rows and mask), None for none.
        failed : callable
            ``failed(w, exc)`` ends world ``w`` (its plug-in failed).
        worlds : callable
            ``worlds()``: the live worlds' indices now.
        """
        h = self._layout.h
        target, v_ref, a_ref = plan.target, plan.v_ref, plan.a_ref
        external = None
        if shifts is not None:
            # Moves the planned target; the law's feed-forward motion is kept.
            rows, external = shifts
            target = np.where(external[:, None], target + rows, target)
        if targets is not None:
            # A set-point: the given point, with no feed-forward motion.
            rows, mask = targets
            external = mask if external is None else external | mask
            target = np.where(mask[:, None], rows, target)
            v_ref = np.where(mask[:, None], 0.0, v_ref)
            a_ref = np.where(mask[:, None], 0.0, a_ref)
        chi_next, v1, v2, travel = self.controller.step(
            fleet.pos, fleet.chi, fleet.theta, target, v_ref, a_ref, fleet.travel
        )
        cars = self.cars
        if cars is not None:  # the cars' rows by their own anti-windup (steering.py)
            cars.control(fleet, target, v_ref, a_ref, chi_next, v1, v2)
        safety = self._safety
        if safety.filter is not None:  # after the controller, before the failures
            v1, v2 = safety.commands(
                t, v1, v2, fleet, plan.slot, known, seen, worlds(), failed,
                self._believed_last(fleet, known),
            )  # fmt: skip
        # Vehicles not driven by the controller this period.
        passive = fleet.commanded
        schedules = self.schedules
        if self._scheduled:
            if external is not None:  # an override of the target drives the vehicle
                v1c, v2c = v1.copy(), v2.copy()
                schedules.apply(t, v1, v2)
                v1[external], v2[external] = v1c[external], v2c[external]
                passive = passive & ~external
            else:
                schedules.apply(t, v1, v2)
        if commands is not None:
            rows, mask = commands
            v1 = np.where(mask, self._command_limits(rows[:, 0], fleet.v1), v1)
            v2 = np.where(mask, CLIP(rows[:, 1], -self.v2_max, self.v2_max), v2)
            passive = passive | mask
            external = mask if external is None else external | mask
        steer = fleet.steer
        if cars is not None:  # what a car executes: its steering's turn rate
            v2, steer = cars.steer(v1, v2, fleet.steer)
        detecting = self._detecting
        sent = v1, v2  # what each vehicle sends to its drive (and broadcasts)
        if detecting.on:
            detecting.intend(v1, v2)
        # The drive executes a failure within its acceleration limit (a crash aside).
        fs = self._failures
        if self._fails:
            v1, v2, failing, frozen, errors = fs.apply(
                t, live, v1, v2, fleet.v1, self.accel_max * h
            )
            for w, exc in errors:  # a failure plug-in failed: its world ends now
                failed(w, exc)
        else:  # no vehicle ever fails: the shared read-only flags
            failing = frozen = fs.none
        if cars is not None and self._fails:  # a failure's commands steered too
            v2, steer = cars.steer(v1, v2, fleet.steer, steer, failing)
        if detecting.on:
            # A failed controller does not know: it keeps its own state until the
            # failure ends (then it resumes from the applied velocity).
            lasting = fs.active_vehicles(t + h, live)
            frozen = frozen & ~lasting
            self._note_sent(sent, failing & lasting)
        # chi follows the applied velocity of passive vehicles, so that the law resumes
        # without a jump when the failure or the override ends.
        if self._fails:  # else no vehicle is frozen
            passive = frozen | passive
        if (passive is not fleet.commanded or len(self._commanded_rows)) and (
            np.count_nonzero(passive)
        ):
            rows = passive.nonzero()[0]
            theta, speed = fleet.theta[rows], v1[rows]
            chi_next[rows, 0] = speed * np.cos(theta)
            chi_next[rows, 1] = speed * np.sin(theta)
            # ... and so does the direction of travel (where it moves).
            travel[rows] = np.where(
                np.abs(speed) < CHI_REST,
                travel[rows],
                np.where(speed < 0.0, TRAVEL_BACKWARD, TRAVEL_FORWARD),
            )
        mode = plan.active.astype(np.int8)  # MODE_FORMATION 0, MODE_AVOID 1
        if external is not None:
            mode[external] = MODE_EXTERNAL
        if self._fails:  # else no vehicle has failed
            mode[failing] = MODE_FAILED
        overridden = target if external is not None else None
        return Acted(v1, v2, failing, mode, chi_next, travel, overridden, steer)

    def _believed_last(
        self, fleet: Fleet, known: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The last period's commands as the platoon knows them (None: the fleet's).

        A drive that failed without its vehicle being believed failed is believed to
        have executed what its vehicle sent: the safety filter's rate bound, braking
        command and estimate then start from the sent commands, not from what the
        failed drive did (which would carry the failure into the sent commands and
        hide it from the detector). A vehicle believed failed is seen as its drive
        moves; a healthy drive applies what it was sent, so the two agree.
        """
        if self._hidden is None:
            return None
        hide = self._hidden & ~known
        if not hide.any():
            return None
        v1_sent, v2_sent = self._sent
        return np.where(hide, v1_sent, fleet.v1), np.where(hide, v2_sent, fleet.v2)

    def _note_sent(
        self, sent: tuple[np.ndarray, np.ndarray], hidden: np.ndarray
    ) -> None:
        """Keep the commands sent where a failure that lasts differs from them."""
        if hidden.any():
            self._sent = (sent[0].copy(), sent[1].copy())
            self._hidden = hidden
        else:
            self._hidden = None

    def _command_limits(self, v1: np.ndarray, last: np.ndarray) -> np.ndarray:
        """User speeds within ``v1_max`` and, from the last speed, ``max_accel``."""
        v1 = np.clip(v1, -self.v1_max, self.v1_max)
        step = self.accel_max * self._layout.h
        return np.clip(v1, last - step, last + step)
