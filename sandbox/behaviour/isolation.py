"""Naming the kind of a residual detector's alarm (:mod:`~sandbox.behaviour.detection`).

At an alarm, and with every window read while isolating, the residuals summed since
the CUSUM left 0 and the observed track name the kind (``Isolation`` in
:mod:`sandbox.behaviour.detection`): :func:`isolate`, from one vehicle's row of the
:class:`~sandbox.behaviour.residual_state.DetectorState` and its observed history
alone.
:func:`read_kinds` reads the kinds of the rows a period's pass names. The ``glr``
detector reads the speed and the stop-or-crash fit here too.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour import residual_kernel
from sandbox.behaviour.tracks import stop_fits

if TYPE_CHECKING:
    from sandbox.behaviour.residual_state import DetectorState
    from sandbox.plugins.contexts import DetectorContext

#: Speed below which a vehicle counts as still, for isolation [m/s].
STILL_SPEED = 0.1
#: How long after a contact a stop counts as a crash [s].
CRASH_CONTACT_WINDOW = 1.0
#: Over how long the speed observed lately is fitted, for isolation [s].
RECENT_SPEED_WINDOW = 0.2


def recent_speed(st: DetectorState, i: int) -> float | None:
    """Vehicle ``i``'s speed over the last :data:`RECENT_SPEED_WINDOW` s [m/s].

    The slope of a straight line fitted to its fresh broadcast positions; None with
    fewer than 5 of them.
    """
    history = st.history
    if history is None or not len(history):
        return None
    t, xy = history.track(i, history.newest - RECENT_SPEED_WINDOW - 1e-9)
    if len(t) < 5:
        return None
    # The means as ndarray.mean takes them: the sums divided by the count.
    count = len(t)
    t = t - np.add.reduce(t) / count
    centred = xy - np.add.reduce(xy, axis=0) / count
    slope = np.add.reduce(t[:, None] * centred, axis=0) / np.add.reduce(t * t)
    return float(np.hypot(slope[0], slope[1]))


def stopped_by_impact(st: DetectorState, i: int, brake: float) -> bool:
    """Whether vehicle ``i``'s observed track fits a crash better than a stop.

    Without a finite braking limit the two move alike: no.
    """
    if not np.isfinite(brake) or st.history is None:
        return False
    t, xy = st.history.track(i)
    if len(t) < 10:
        return False
    chord = np.add.reduce(xy[-5:], axis=0) / 5 - np.add.reduce(xy[:5], axis=0) / 5
    norm = float(np.hypot(chord[0], chord[1]))
    if norm < 1e-9:
        return False
    crash, stop = stop_fits(t, (xy - xy[0]) @ (chord / norm), brake)
    return crash < stop


def isolate(st: DetectorState, i: int, t: float, ctx: DetectorContext) -> str:
    """The kind of the alarm of vehicle ``i`` from its accumulated residuals."""
    # Which component dominates: summed magnitudes (a spinning vehicle's heading
    # residual changes sign as its controller turns against it); the sign of the
    # along-track sum says deficit or excess.
    za, zc, zh = st.acc_abs[i]
    duration = max(st.acc_t[i], ctx.dt)
    windows = max(1.0, st.acc_t[i] / max(ctx.params["window"], ctx.dt))
    brakes = ctx.motor_accel if ctx.brake_accel is None else ctx.brake_accel
    brake = float(brakes[i])
    # Slow: the speed observed lately (a line fitted to the last RECENT_SPEED_WINDOW s
    # of broadcast positions) is below half the model's, the commanded one: a
    # stopped or spinning vehicle once its drive has braked (an integral over the
    # sums would count the travel before the onset, and the braking, as moving).
    recent = recent_speed(st, i)
    commanded = float(np.hypot(*st.vel[i]))
    if recent is None:  # too few observations: the sums since g left 0
        slow = st.acc_obs[i] < max(STILL_SPEED * duration, 0.5 * st.acc_pred[i])
    else:
        slow = recent < max(STILL_SPEED, 0.5 * commanded)
    # Whether the observed heading turns, beyond 4 standard deviations of the sum of
    # the windows' noisy heading differences: after the first window once there are
    # more (the first one holds the turn the vehicle made before the fault).
    sh = np.sqrt(2.0 * ctx.heading_noise**2 + ctx.params["heading_floor"] ** 2)
    late = int(st.acc_n[i]) - 1
    rot = st.acc_rot[i] - st.acc_rot0[i] if late > 0 else st.acc_rot[i]
    turned = abs(rot) > 4.0 * sh * np.sqrt(max(late, 1))
    if slow and turned:
        return "spin"
    if slow and st.acc[i, 0] < 0 and (za >= zc or zh >= zc):
        # At rest without turning: the commanded turn did not happen either.
        if t - st.last_contact[i] <= CRASH_CONTACT_WINDOW:
            return "crash"
        # Stopped harder than the drive can brake: an impact.
        return "crash" if stopped_by_impact(st, i, brake) else "stop"
    if zh >= max(za, zc):
        # Moving: the speed is off the commands too (beyond 2 sigma) when uncontrolled.
        speed_off = abs(st.acc[i, 0]) > 2.0 * np.sqrt(windows)
        return "uncontrolled" if speed_off else "stuck_steering"
    return "uncontrolled"


def read_kinds(st: DetectorState, ctx: DetectorContext, events: tuple) -> None:
    """The kinds of the rows a period's pass names, as ``residual`` reads them.

    ``events`` is :data:`~sandbox.behaviour.residual_kernel.QUIET` or the rows read
    on while isolating, cleared and alarming: each reads only its own row's state,
    which the pass left as the numpy path leaves it when it reads the kind.
    """
    if events is residual_kernel.QUIET:
        return
    read, cleared, alarms = events
    for i in read:  # the kind from more residuals, before a clearing
        st.kinds[i] = isolate(st, i, ctx.t, ctx)
    for i in cleared:
        st.kinds[i] = ""
    for i in alarms:
        st.kinds[i] = isolate(st, i, ctx.t, ctx)
