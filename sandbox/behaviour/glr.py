"""A windowed generalised likelihood-ratio detector: ``detection: {method: glr}``.

The ``residual`` detector (:mod:`sandbox.behaviour.detection`) sums one CUSUM step
per window of residuals tuned to one fault size, with the noise the scenario
declares. Each of its windows starts from a new observation, so every window carries
the noise of two poses and a small fault of ``delta`` standard deviations a window
needs about ``2 lambda / delta^2`` windows. ``glr`` instead tests for a fault of
unknown size, with the noise estimated from the run:

The innovation
    The motor model of ``residual``
    (:func:`sandbox.behaviour.residual_state.advance_model`) predicts each vehicle's
    pose from its broadcast commands over one control period, restarted from every
    observation received (a lost packet stretches the step to the next one). The
    innovation ``d_k`` is the observed pose minus the predicted one (world ``x, y`` [m]
    and heading [rad]); its running sum ``C_k = sum_j d_j`` telescopes, ``C_k = e_k -
    e_0 + f_k``: the pose noise ``e_k`` of one observation (white, ``sigma`` per
    coordinate), a constant, and what the commands do not explain, ``f_k``. A fault that
    moves the vehicle at a rate ``mu`` off its commands from ``tau`` on (a speed or a
    turn-rate error: a mean shift ``mu h`` of the innovation) makes ``f`` a ramp, ``f(t)
    = mu (t - tau)^+``.

The statistic
    Over the last ``window`` seconds (``m`` observations at times ``t_j``), for each
    candidate change time ``tau`` (an observation time) the regressor
    ``r_j = (t_j - tau)^+`` is centred, ``r~_j = r_j - mean(r)`` (the constant is
    unknown), and the log-likelihood ratio of the ramp against no ramp, maximised
    over ``mu`` in R^3, is::

        L(tau) = 1/2 sum_c (sum_j r~_j C_jc)^2 / (sigma_c^2 sum_j r~_j^2)

    with ``mu_c = sum_j r~_j C_jc / sum_j r~_j^2`` [unit/s] (standard error
    ``sigma_c / sqrt(sum_j r~_j^2)``). The statistic is ``G = max_tau L(tau)``; the
    detector alarms at ``G >= lambda``. Without a fault ``2 L(tau)`` is chi-square
    with 3 degrees of freedom for every ``tau``, so the chance that ``G`` exceeds
    ``lambda`` at one observation is at most ``M P(chi2_3 > 2 lambda)`` (the union
    over the ``M = window / dt`` change times), and the false alarms per vehicle-hour
    at most::

        N = 3600 / dt * M * P(chi2_3 > 2 lambda),
        P(chi2_3 > x) = erfc(sqrt(x / 2)) + sqrt(2 x / pi) exp(-x / 2)

    (a bound: exceedances at consecutive observations are one alarm, and the
    ``tau`` are strongly correlated). ``lambda`` left out is the root of
    ``N = false_alarms`` (:func:`threshold`): 23.7 for 0.01 per hour at
    ``dt = 0.01 s`` and a 1 s window.

The noise
    ``sigma`` is estimated per vehicle from its own innovations, which are
    ``e_k - e_{k-1}`` when nothing is wrong: ``sigma = 1.4826 MAD(d) / sqrt(2)``
    over the last ``noise_window`` seconds of observations taken while the vehicle
    is neither detected, nor suspected (``G < lambda / 2``) nor near a contact, the
    positions' two axes pooled; it is floored by ``sqrt(s^2 + floor^2)`` with ``s``
    the declared ``sensing`` noise and ``floor`` = ``noise_floor`` or
    ``heading_floor`` (what the model misses), so a noise larger than declared is
    followed and a smaller one never lowers the threshold.

Contacts, isolation, clearing
    A contact (and ``CONTACT_GATE`` s after it) empties the vehicle's window: the
    world moved it against its commands. At an alarm the kind is read from the fit
    at the maximising ``tau`` and the observed track, again at every observation for
    ``isolation`` seconds (and until a failed drive could have braked to rest from
    the commanded speed, plus 0.1 s), with the rules of ``residual``'s
    :func:`~sandbox.behaviour.isolation.isolate` for a slow vehicle (spin, stop or
    crash, the crash-or-stop fit of the track) and, for a moving one, the fit: an
    along-track rate beyond ``SPEED_Z`` standard errors is ``uncontrolled``, else a
    turn-rate beyond ``SPEED_Z`` and the cross-track one a ``stuck_steering``, else
    ``uncontrolled``. Then the window restarts; the detection is withdrawn when a
    whole window passes with ``G < lambda`` (the vehicle moved as commanded).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sandbox.behaviour.detection import RESIDUAL_PARAMS
from sandbox.behaviour.isolation import recent_motion, rest_kind
from sandbox.behaviour.residual_state import (
    RECENT_SPEED_WINDOW,
    DetectorState,
    advance_model,
    shape_history,
    start_state,
    wrap_difference,
)
from sandbox.plugins.registration import DetectorContext, Param, register_detector

#: How long after a contact the window stays empty [s].
CONTACT_GATE = 0.1
#: Standard errors beyond which a rate of the fit counts, for isolation.
SPEED_Z = 3.0
#: How long the kind is read after a braked vehicle's track shows it at rest [s].
ISOLATION_MARGIN = 0.1
#: MAD to standard deviation of a normal distribution.
MAD_SCALE = 1.4826
#: Fewest innovations before the noise estimate replaces the declared noise.
MIN_NOISE_SAMPLES = 50
#: Observations between two updates of the noise estimate.
NOISE_EVERY = 10

GLR_PARAMS = {
    "lambda": Param(
        "number",
        None,
        doc="GLR threshold [nats]; default: the root of the false-alarm bound at "
        "false_alarms",
        minimum=0.0,
        exclusive=True,
    ),
    "false_alarms": Param(
        "number",
        0.01,
        "1/h",
        "Target false alarms per vehicle-hour, through the bound "
        "3600/dt M P(chi2_3 > 2 lambda) (when lambda is left out)",
        minimum=0.0,
        exclusive=True,
    ),
    "window": Param(
        "number",
        1.0,
        "s",
        "The sliding window of the test: the change times searched (a whole number "
        "of control periods)",
        minimum=0.0,
        exclusive=True,
    ),
    "noise_window": Param(
        "number",
        5.0,
        "s",
        "How much of a vehicle's fault-free innovations the noise estimate (a "
        "median absolute deviation) reads; 0: the declared noise only",
        minimum=0.0,
    ),
    "isolation": Param(
        "number",
        0.3,
        "s",
        "How long after an alarm the kind is still read (and at least until a "
        "failed drive could have braked to rest, plus 0.1 s)",
        minimum=0.0,
    ),
    # the floors of the residual detector, declared once
    "noise_floor": RESIDUAL_PARAMS["noise_floor"],
    "heading_floor": RESIDUAL_PARAMS["heading_floor"],
}


def chi2_3_tail(x: float) -> float:
    """``P(chi2_3 > x)``, the tail of a chi-square with 3 degrees of freedom.

    >>> round(chi2_3_tail(7.814728), 4)
    0.05
    """
    if x <= 0.0:
        return 1.0
    return math.erfc(math.sqrt(x / 2.0)) + math.sqrt(2.0 * x / math.pi) * math.exp(
        -x / 2.0
    )


def false_alarm_bound(lam: float, window: float, dt: float) -> float:
    """The bound on false alarms per vehicle-hour of threshold ``lam`` [1/h].

    ``3600 / dt * M * P(chi2_3 > 2 lam)`` for ``M = window / dt`` change times: the
    union bound over the change times of the chance that one observation's
    statistic exceeds ``lam``, times the observations of an hour.
    """
    m = max(1.0, round(window / dt))
    return 3600.0 / dt * m * chi2_3_tail(2.0 * lam)


def threshold(rate: float, window: float, dt: float) -> float:
    """The ``lambda`` [nats] whose :func:`false_alarm_bound` is ``rate`` [1/h].

    >>> round(threshold(0.01, 1.0, 0.01), 1)
    23.7
    """
    lo, hi = 0.0, 200.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if false_alarm_bound(mid, window, dt) > rate:
            lo = mid
        else:
            hi = mid
    return hi


def glr_statistic(
    t: np.ndarray, c: np.ndarray, valid: np.ndarray, sigma: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The GLR of a ramp of unknown slope and start in each row's window.

    Parameters
    ----------
    t : ndarray (n, M) [s]
        Observation times, increasing along a row where ``valid``.
    c : ndarray (n, M, k)
        The summed innovations ``C`` at those times.
    valid : ndarray (n, M) bool
        Which entries hold an observation.
    sigma : ndarray (n, k)
        The noise standard deviation of each channel.

    Returns
    -------
    g : ndarray (n,)
        ``max_tau L(tau)`` [nats] (0 with fewer than 3 observations).
    tau : ndarray (n,) int
        The index of the maximising change time (-1 if none).
    mu : ndarray (n, k) [unit/s]
        The fitted slope at that ``tau``.
    se : ndarray (n, k) [unit/s]
        Its standard error.

    >>> t = np.arange(10.0)[None, :]
    >>> c = np.maximum(t - 4.0, 0.0)[:, :, None] * 3.0
    >>> g, tau, mu, se = glr_statistic(t, c, np.ones((1, 10), bool), np.ones((1, 1)))
    >>> int(tau[0]), round(float(mu[0, 0]), 6)
    (4, 3.0)
    """
    w = valid.astype(float)
    n, m = w.shape
    last = np.where(valid, t, -np.inf).max(axis=1, keepdims=True)
    last = np.where(np.isfinite(last), last, 0.0)
    tt = np.where(valid, t - last, 0.0)
    first = np.argmax(valid, axis=1)
    c0 = c[np.arange(n), first][:, None, :]
    cc = np.where(valid[:, :, None], c - c0, 0.0)

    def suffix(a: np.ndarray) -> np.ndarray:
        return np.flip(np.cumsum(np.flip(a, axis=1), axis=1), axis=1)

    cnt = suffix(w)
    s1 = suffix(w * tt)
    s2 = suffix(w * tt * tt)
    sc = suffix(cc)
    stc = suffix(tt[:, :, None] * cc)
    total = cnt[:, :1]
    sum_c = sc[:, :1, :]
    r1 = s1 - tt * cnt  # sum of r over the window (r = 0 before tau)
    r2 = s2 - 2.0 * tt * s1 + tt * tt * cnt
    rc = stc - tt[:, :, None] * sc
    safe_total = np.maximum(total, 1.0)
    rr = r2 - r1 * r1 / safe_total  # sum of centred r^2
    rcc = rc - r1[:, :, None] * sum_c / safe_total[:, :, None]
    ok = valid & (cnt >= 2.0) & (total >= 3.0) & (rr > 1e-12)
    safe_rr = np.where(ok, rr, 1.0)
    z = rcc / (sigma[:, None, :] * np.sqrt(safe_rr)[:, :, None])
    llr = np.where(ok, 0.5 * (z * z).sum(axis=2), -np.inf)
    tau = np.argmax(llr, axis=1)
    rows = np.arange(n)
    g = llr[rows, tau]
    found = np.isfinite(g)
    g = np.where(found, g, 0.0)
    best_rr = safe_rr[rows, tau]
    mu = rcc[rows, tau] / best_rr[:, None]
    se = sigma / np.sqrt(best_rr)[:, None]
    return g, np.where(found, tau, -1), mu, se


def mad_sigma(d: np.ndarray) -> float:
    """The noise of one pose coordinate from innovations ``d = e_k - e_{k-1}``.

    ``1.4826 median(|d - median(d)|) / sqrt(2)``: robust to a few faulty samples.
    """
    d = np.asarray(d, dtype=float).ravel()
    med = np.median(d)
    return float(MAD_SCALE * np.median(np.abs(d - med)) / math.sqrt(2.0))


@dataclass
class GlrState:
    """What the GLR detector keeps between control periods, per vehicle."""

    model: DetectorState  # the motor model and the observed history of ``residual``
    csum: np.ndarray  # summed innovations C (n, 3) [m, m, rad]
    times: np.ndarray  # the window's observation times (n, M) [s]
    values: np.ndarray  # the window's C (n, M, 3)
    valid: np.ndarray  # (n, M) bool
    started: np.ndarray  # time of the window's first observation (n,) [s]
    gate: np.ndarray  # until when the window stays empty (n,) [s]
    innov: np.ndarray  # fault-free innovations, a ring (n, K, 3)
    innov_n: np.ndarray  # how many are stored (n,)
    innov_at: np.ndarray  # the ring's next slot (n,)
    sigma: np.ndarray  # the noise in use (n, 3)
    floor: np.ndarray  # its floor (3,)
    lam: float  # the threshold [nats]
    detected: np.ndarray  # (n,) bool
    isolating: np.ndarray  # until when the kind is read (n,) [s]
    clearing: np.ndarray  # the window restarted after isolation (n,) bool
    kinds: list  # (n,)
    count: np.ndarray  # observations received (n,)


def _init(ctx: DetectorContext) -> GlrState:
    p = ctx.params
    n = len(ctx.pos)
    m = max(3, int(round(p["window"] / ctx.dt)) + 1)
    k = max(1, int(round(p["noise_window"] / ctx.dt)))
    lam = p.get("lambda")
    if lam is None:
        lam = threshold(float(p["false_alarms"]), float(p["window"]), ctx.dt)
    floor = np.array(
        [
            math.hypot(ctx.position_noise, p["noise_floor"]),
            math.hypot(ctx.position_noise, p["noise_floor"]),
            math.hypot(ctx.heading_noise, p["heading_floor"]),
        ]
    )
    model = start_state(ctx)
    model.history = shape_history(ctx)
    return GlrState(
        model=model,
        csum=np.zeros((n, 3)),
        times=np.zeros((n, m)),
        values=np.zeros((n, m, 3)),
        valid=np.zeros((n, m), dtype=bool),
        started=np.full(n, np.inf),
        gate=np.full(n, -np.inf),
        innov=np.zeros((n, k, 3)),
        innov_n=np.zeros(n, dtype=int),
        innov_at=np.zeros(n, dtype=int),
        sigma=np.tile(floor, (n, 1)),
        floor=floor,
        lam=float(lam),
        detected=np.zeros(n, dtype=bool),
        isolating=np.full(n, -np.inf),
        clearing=np.zeros(n, dtype=bool),
        kinds=[""] * n,
        count=np.zeros(n, dtype=int),
    )


def _empty(st: GlrState, rows: np.ndarray) -> None:
    st.valid[rows] = False
    st.started[rows] = np.inf


def mad_sigmas(d: np.ndarray) -> np.ndarray:
    """:func:`mad_sigma` of each row of ``d`` (r, m): the same numbers, at once."""
    med = np.median(d, axis=1)
    return MAD_SCALE * np.median(np.abs(d - med[:, None]), axis=1) / math.sqrt(2.0)


def _update_noise(st: GlrState, ctx: DetectorContext, due: np.ndarray) -> None:
    """Re-estimate the noise of the vehicles ``due`` with enough fault-free innovations.

    The vehicles with the same number of stored innovations are estimated together
    (each row's medians as :func:`mad_sigma` takes them one vehicle at a time).
    """
    if ctx.params["noise_window"] <= 0.0 or not due.size:
        return
    due = due[st.innov_n[due] >= MIN_NOISE_SAMPLES]
    for count in np.unique(st.innov_n[due]):
        rows = due[st.innov_n[due] == count]
        d = st.innov[rows, :count]
        sp = mad_sigmas(d[:, :, :2].reshape(len(rows), -1))
        sh = mad_sigmas(d[:, :, 2])
        st.sigma[rows] = np.maximum(np.stack((sp, sp, sh), -1), st.floor)


def _kind(st: GlrState, i: int, t: float, ctx: DetectorContext, fit: tuple) -> str:
    """The kind of vehicle ``i``'s alarm from the fit and the observed track."""
    mu, se = fit
    model = st.model
    heading = float(model.pose[i, 2])
    c, s = math.cos(heading), math.sin(heading)
    z_a = (c * mu[0] + s * mu[1]) / se[0]
    z_c = (-s * mu[0] + c * mu[1]) / se[1]
    z_h = mu[2] / se[2]
    brakes = ctx.motor_accel if ctx.brake_accel is None else ctx.brake_accel
    # At rest against its commands (the speed fitted to the last
    # RECENT_SPEED_WINDOW s of positions within STILL_Z standard errors of 0, the
    # commanded one beyond), turning or not (the turn rate fitted to the headings
    # beyond TURN_Z), with the noise as estimated.
    motion = recent_motion(model, i, float(st.sigma[i, 0]), float(st.sigma[i, 2]))
    commanded = float(np.hypot(*model.vel[i]))
    if motion is not None and motion.halted(commanded):
        if motion.turning:
            return "spin"
        return rest_kind(model, i, t, float(brakes[i]), float(st.sigma[i, 0]))
    model.rest[i] = ""
    if abs(z_a) > SPEED_Z:
        return "uncontrolled"
    if abs(z_h) > SPEED_Z and abs(z_h) >= abs(z_c):
        return "stuck_steering"
    return "uncontrolled"


@register_detector("glr", params=GLR_PARAMS, batched=True)
def glr(ctx: DetectorContext) -> tuple[np.ndarray, list[str]]:
    """A windowed GLR on the summed innovations, with the noise estimated."""
    st: GlrState | None = ctx.memory.get("glr")
    if st is None or ctx.commands is None:
        st = ctx.memory["glr"] = _init(ctx)
        return st.detected.copy(), list(st.kinds)
    p = ctx.params
    model = st.model
    model.history.append(ctx.t, ctx.seen, ctx.fresh)
    advance_model(model, ctx)
    contact = ctx.in_contact
    model.last_contact = np.where(contact, ctx.t, model.last_contact)
    st.gate = np.where(contact, ctx.t + CONTACT_GATE, st.gate)
    rows = np.flatnonzero(ctx.fresh)
    if rows.size == 0:
        return st.detected.copy(), list(st.kinds)
    # Each vehicle's noise is estimated anew every NOISE_EVERY of its observations.
    st.count[rows] += 1
    due = rows[st.count[rows] % NOISE_EVERY == 0]
    seen = ctx.seen[rows]
    pred = model.pose[rows]
    turned = wrap_difference(seen[:, 2] - pred[:, 2])
    d = np.column_stack((seen[:, :2] - pred[:, :2], turned))
    # Restart the prediction from the observation: consecutive innovations share it,
    # so their sum telescopes.
    model.pose[rows] = seen
    model.travel[rows] = 0.0
    st.csum[rows] += d
    gated = st.gate[rows] >= ctx.t - 1e-9
    _empty(st, rows[gated])
    keep = rows[~gated]
    # Shift the window of the rows observed and append.
    st.times[keep, :-1] = st.times[keep, 1:]
    st.values[keep, :-1] = st.values[keep, 1:]
    st.valid[keep, :-1] = st.valid[keep, 1:]
    st.times[keep, -1] = ctx.t
    st.values[keep, -1] = st.csum[keep]
    st.valid[keep, -1] = True
    st.started[keep] = np.where(np.isfinite(st.started[keep]), st.started[keep], ctx.t)
    if st.valid[keep, 0].any():  # the oldest observation left: the window slides
        first = st.times[keep][:, 0]
        st.started[keep] = np.where(st.valid[keep, 0], first, st.started[keep])
    if keep.size == 0:
        _update_noise(st, ctx, due)
        return st.detected.copy(), list(st.kinds)
    g, tau, mu, se = glr_statistic(
        st.times[keep], st.values[keep], st.valid[keep], st.sigma[keep]
    )
    trace = ctx.memory.get("trace")
    if trace is not None:  # (t, vehicle, G) of every observation, for studies
        trace.extend((ctx.t, int(i), float(x)) for i, x in zip(keep, g, strict=True))
    # Fault-free innovations for the noise estimate.
    quiet = keep[(~st.detected[keep]) & (g < 0.5 * st.lam)]
    if quiet.size and st.innov.shape[1]:
        k = st.innov.shape[1]
        slot = st.innov_at[quiet]
        st.innov[quiet, slot] = d[np.searchsorted(rows, quiet)]
        st.innov_at[quiet] = (slot + 1) % k
        st.innov_n[quiet] = np.minimum(st.innov_n[quiet] + 1, k)
    _update_noise(st, ctx, due)
    window = float(p["window"])
    # Only a vehicle with an alarm, or raising one, has anything to do.
    for k in np.flatnonzero(st.detected[keep] | (g >= st.lam)):
        i = int(keep[k])
        if not st.detected[i]:
            if g[k] >= st.lam:
                st.detected[i] = True
                model.rest[i] = ""  # how it came to rest is read anew
                st.kinds[i] = _kind(st, i, ctx.t, ctx, (mu[k], se[k]))
                brakes = ctx.motor_accel if ctx.brake_accel is None else ctx.brake_accel
                braking = float(np.hypot(*model.vel[i])) / float(brakes[i])
                after = braking + ISOLATION_MARGIN + RECENT_SPEED_WINDOW
                st.isolating[i] = ctx.t + max(float(p["isolation"]), after)
                st.clearing[i] = False
            continue
        if ctx.t <= st.isolating[i] + 1e-9:
            st.kinds[i] = _kind(st, i, ctx.t, ctx, (mu[k], se[k]))
            continue
        if not st.clearing[i] or g[k] >= st.lam:
            # After isolation, and whenever the motion is still off the commands:
            # a new window, which must pass whole below lambda to clear.
            st.clearing[i] = True
            _empty(st, np.array([i]))
            continue
        if ctx.t - st.started[i] >= window - 1e-9:
            st.detected[i] = False
            st.kinds[i] = ""
            st.clearing[i] = False
    return st.detected.copy(), list(st.kinds)
