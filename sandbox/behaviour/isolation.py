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

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour import residual_kernel
from sandbox.behaviour.residual_state import RECENT_SPEED_WINDOW
from sandbox.behaviour.tracks import stop_fits

if TYPE_CHECKING:
    from sandbox.behaviour.residual_state import DetectorState
    from sandbox.plugins.contexts import DetectorContext

#: Speed below which a vehicle counts as at rest, at least, for isolation [m/s].
STILL_SPEED = 0.1
#: How long after a contact a stop counts as a crash [s].
CRASH_CONTACT_WINDOW = 1.0
#: Standard errors of the fitted speed below which a vehicle is at rest [1].
STILL_Z = 4.0
#: Standard errors of the fitted turn rate beyond which a vehicle at rest turns [1].
TURN_Z = 4.0
#: How much better, in the noise's variances, a crash must fit a track than a
#: braked stop [1] (a track at rest fits both within a few; a wreck's by tens).
IMPACT_MARGIN = 10.0


@dataclass(frozen=True)
class Motion:
    """A vehicle's motion observed lately: a line fitted to its recent track.

    Attributes
    ----------
    speed, speed_se : float [m/s]
        The speed of the straight line fitted to the positions, and the standard
        error of each of its two components.
    rate, rate_se : float [rad/s]
        The turn rate of the line fitted to the (unwrapped) headings, and its
        standard error.
    """

    speed: float
    speed_se: float
    rate: float
    rate_se: float

    def halted(self, commanded: float) -> bool:
        """At rest against its commands, which ask for ``commanded`` [m/s].

        The speed within :data:`STILL_Z` standard errors of 0 (or below
        :data:`STILL_SPEED`), and the commanded speed beyond it by as much: a
        vehicle that its controller slows is not a stopped one.
        """
        still = max(STILL_SPEED, STILL_Z * self.speed_se)
        return self.speed < still and commanded - self.speed > still

    @property
    def turning(self) -> bool:
        """Turning: the turn rate beyond :data:`TURN_Z` standard errors of 0."""
        return abs(self.rate) > TURN_Z * self.rate_se


def recent_motion(
    st: DetectorState, i: int, sigma_p: float, sigma_h: float
) -> Motion | None:
    """Vehicle ``i``'s :class:`Motion` over the last :data:`RECENT_SPEED_WINDOW` s.

    Straight lines fitted by least squares to its fresh broadcast positions and
    headings, with the noise ``sigma_p`` [m] per coordinate and ``sigma_h`` [rad];
    None with fewer than 5 of them.
    """
    history = st.history
    if history is None or not len(history):
        return None
    t, pose = history.track(i, history.newest - RECENT_SPEED_WINDOW - 1e-9)
    if len(t) < 5:
        return None
    t = t - t.mean()
    spread = float(np.sqrt(t @ t))
    values = pose - pose.mean(axis=0)
    values[:, 2] = np.unwrap(pose[:, 2])
    values[:, 2] -= values[:, 2].mean()
    slope = (t @ values) / (spread * spread)
    return Motion(
        speed=float(np.hypot(slope[0], slope[1])),
        speed_se=sigma_p / spread,
        rate=float(slope[2]),
        rate_se=sigma_h / spread,
    )


def stopped_by_impact(st: DetectorState, i: int, brake: float, sigma: float) -> bool:
    """Whether vehicle ``i``'s observed track fits a crash better than a stop.

    Better by :data:`IMPACT_MARGIN` times the noise's variance ``sigma^2`` [m^2]
    (``sigma`` [m] per coordinate): on a track at rest the more supple crash model
    fits the noise a little better. Without a finite braking limit the two move
    alike: no.
    """
    if not np.isfinite(brake) or st.history is None:
        return False
    t, pose = st.history.track(i)
    if len(t) < 10:
        return False
    xy = pose[:, :2]
    chord = xy[-5:].mean(axis=0) - xy[:5].mean(axis=0)
    norm = float(np.hypot(chord[0], chord[1]))
    if norm < 1e-9:
        return False
    crash, stop = stop_fits(t, (xy - xy[0]) @ (chord / norm), brake)
    return crash + IMPACT_MARGIN * sigma * sigma < stop


def rest_kind(st: DetectorState, i: int, t: float, brake: float, sigma: float) -> str:
    """``stop`` or ``crash`` of vehicle ``i`` at rest, read when it came to rest.

    A crash when it was in contact within the last :data:`CRASH_CONTACT_WINDOW` s,
    or when its track fits a crash better than a braked stop
    (:func:`stopped_by_impact`); read at the first reading that finds it at rest
    (its last second of track then holds how it stopped) and kept while it stays
    at rest (``st.rest``), so that neither a later contact nor a second at rest
    that fits both changes it.
    """
    kind = st.rest[i]
    if not kind:
        crash = t - st.last_contact[i] <= CRASH_CONTACT_WINDOW
        crash = crash or stopped_by_impact(st, i, brake, sigma)
        kind = st.rest[i] = "crash" if crash else "stop"
    return kind


def noise(ctx: DetectorContext) -> tuple[float, float]:
    """The position [m] and heading [rad] noise of one observation, floored."""
    p = ctx.params
    return (
        math.hypot(ctx.position_noise, p["noise_floor"]),
        math.hypot(ctx.heading_noise, p["heading_floor"]),
    )


def isolate(st: DetectorState, i: int, t: float, ctx: DetectorContext) -> str:
    """The kind of the alarm of vehicle ``i`` from its accumulated residuals."""
    # Which component dominates: summed magnitudes (a spinning vehicle's heading
    # residual changes sign as its controller turns against it); the sign of the
    # along-track sum says deficit or excess.
    za, zc, zh = st.acc_abs[i]
    duration = max(st.acc_t[i], ctx.dt)
    windows = max(1.0, st.acc_t[i] / max(ctx.params["window"], ctx.dt))
    brakes = ctx.motor_accel if ctx.brake_accel is None else ctx.brake_accel
    sigma_p, sigma_h = noise(ctx)
    # At rest against its commands: the speed observed lately (a line fitted to
    # the last RECENT_SPEED_WINDOW s of broadcast positions) within STILL_Z standard
    # errors of 0, and the model's, the commanded one, beyond; turning: the turn
    # rate fitted to the headings beyond TURN_Z. A vehicle that keeps a part of its
    # speed moves: it is not a stop.
    motion = recent_motion(st, i, sigma_p, sigma_h)
    if motion is None:  # too few observations: the sums since g left 0
        still = st.acc_obs[i] < max(STILL_SPEED * duration, 0.5 * st.acc_pred[i])
        # The observed heading turns beyond 4 standard deviations of the sum of the
        # windows' noisy heading differences, after the first window once there
        # are more (the first one holds the turn made before the fault).
        sh = np.sqrt(2.0 * ctx.heading_noise**2 + ctx.params["heading_floor"] ** 2)
        late = int(st.acc_n[i]) - 1
        rot = st.acc_rot[i] - st.acc_rot0[i] if late > 0 else st.acc_rot[i]
        turned = abs(rot) > 4.0 * sh * np.sqrt(max(late, 1))
    else:
        still = motion.halted(float(np.hypot(*st.vel[i])))
        turned = motion.turning
    if still and turned:
        return "spin"
    if still and st.acc[i, 0] < 0 and (za >= zc or zh >= zc):
        # At rest without turning: the commanded turn did not happen either.
        return rest_kind(st, i, t, float(brakes[i]), sigma_p)
    st.rest[i] = ""
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
    for i in alarms:  # a new detection: how it came to rest is read anew
        st.rest[i] = ""
        st.kinds[i] = isolate(st, i, ctx.t, ctx)
