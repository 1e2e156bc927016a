"""Failure detection without an oracle: the ``residual`` detector (``detection:``).

With ``detection: {method: oracle}`` (the default) the platoon knows every failure at
once, as in v0.1. With ``method: residual`` it has to find them: each vehicle's
observed motion (its broadcast poses, :attr:`Simulation.seen`, or the truth without
sensing) is compared with what the commands its controller broadcasts predict, and a
one-sided CUSUM per vehicle decides when the difference is too large to be noise.

The prediction
    Every control period each vehicle broadcasts the commands ``(v1, v2)`` its
    controller asks for (a failed vehicle's controller does not know it has failed:
    it goes on asking for what its law wants). The detector integrates the unicycle
    of eq. (1) with these commands through the motor model of the physics: in each
    of the ``substeps`` substeps of a period the position and heading advance with the
    body's current velocity, and then the velocity moves toward the command (the
    world-frame vector ``v1 (cos, sin)(x3 + v2 h / 2)`` and the rate ``v2``) by at most
    the motor's acceleration limit (``motor_accel``, and ``4 motor_accel / radius`` for
    the turn rate; a vehicle without ``motor_accel`` reaches its command within one
    substep). The predicted pose starts every ``window`` seconds from the last
    observed pose; the residual of a window is the observed pose at its end minus the
    predicted one, in the frame of the predicted heading: along-track ``r_a``,
    cross-track ``r_c`` [m] and heading ``r_h`` [rad].

Normalisation
    Each end of a window carries the broadcast noise, so ``r_a`` and ``r_c`` have a
    standard deviation ``sqrt(2 sigma_p^2 + floor_p^2)`` (``r_c`` also
    ``L sigma_h`` for a travel ``L`` over the window, the start heading's error) and
    ``r_h`` ``sqrt(2 sigma_h^2 + floor_h^2)``, with ``sigma_p, sigma_h`` the
    ``sensing`` noise and ``floor_p = 1 mm``, ``floor_h = 1 mrad`` by default
    (``noise_floor``, ``heading_floor``): what the prediction misses without any noise
    (the residual of a healthy platoon seen through the truth stays below a tenth of
    that). ``z`` is the residual divided by these.

The CUSUM
    Under no fault ``z`` is close to a standard normal vector in 3-D. The alternative
    is a mean shift of ``shift`` standard deviations in an unknown direction; the
    log-likelihood ratio of one window, averaged over the directions, is
    ``l(z) = log(sinh(mu |z|) / (mu |z|)) - mu^2 / 2`` with ``mu = shift``, and the
    detector runs ``g = max(0, g + l)`` per vehicle, alarming at ``g >= lambda``.
    For independent windows Lorden's bound gives a mean time between false alarms of
    at least ``e^lambda`` windows; consecutive windows share an end point, and the
    README reports the rate measured on fault-free runs. A window during which the
    vehicle was in a contact episode (or one window after it) is skipped: contacts
    move vehicles against their commands and are known to the world.

Isolation
    At an alarm the residuals accumulated since ``g`` last left 0 name the kind, and
    they are read again with every window for ``isolation`` seconds more (default 0.3
    s), and at least until a failed drive could have braked to rest from the commanded
    speed at its limit (the least of its declared ``max_accel`` and ``motor_accel``)
    plus a window; the detection time stays the alarm's. A failed drive reaches its
    faulty command within its limits, so a braking stop or spin, or a runaway whose
    speed is near the commanded one, is plain only after a few windows. A vehicle is
    *slow* when its speed observed lately (a line fitted to its last
    :data:`RECENT_SPEED_WINDOW` s of broadcast positions) is below half the model's, the
    commanded speed (or below ``STILL_SPEED``). Slow and turning (the observed heading
    change after the first window, beyond 4 standard deviations) is a ``spin``; slow,
    not turning and short of its predicted travel is a ``stop``, or a ``crash`` when the
    vehicle was in contact within the last second or its last
    :data:`~sandbox.behaviour.residual_state.SHAPE_HISTORY` seconds of observed track
    fit a crash better than a braked stop (:func:`~sandbox.behaviour.tracks.stop_fits`:
    a wreck stops within a substep, a deceleration no drive makes; see
    :mod:`sandbox.model.failures`). Without a declared limit the two move alike and a
    crash in free space reads as a stop. A moving vehicle whose heading residual
    dominates (by summed magnitudes) is a ``stuck_steering``, or ``uncontrolled`` when
    the along-track sum is beyond 2 standard deviations too. Any other motion against
    the commands (too fast, sideways) is ``uncontrolled``.

Studies
    With ``memory["trace"]`` set to a list (``Simulation.detection.memory``), every
    window's ``(t, vehicle, l)`` is appended to it: the CUSUM of any other ``lambda``
    can be recomputed from one run (a run is the same for every ``lambda`` up to its
    first alarm). ``benchmarks/detection_lambda.py`` does so.

Latching
    A detection stays until the same statistic run the other way,
    ``c = max(0, c - l)``, reaches ``lambda``: the vehicle has moved as commanded long
    enough (a cleared failure); the detection is then reported cleared.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox.behaviour import residual_kernel
from sandbox.behaviour.isolation import read_kinds
from sandbox.behaviour.residual_state import (
    RECENT_SPEED_WINDOW,
    DetectorState,
    advance_model,
    shape_history,
    start_state,
    wrap_difference,
)
from sandbox.behaviour.tracks import stop_fits as stop_fits  # its documented path
from sandbox.errors import PluginRunError
from sandbox.plugins.registration import (
    DetectorContext,
    Param,
    get,
    register_detector,
    register_metrics,
    runnable,
)

if TYPE_CHECKING:
    from sandbox.scenario import Scenario

#: The kinds a detection names (failure kinds of :mod:`sandbox.model.failures`).
KINDS = ("stop", "spin", "stuck_steering", "uncontrolled", "crash")
#: Angular motor limit as a multiple of ``motor_accel / radius`` (as the physics).
ANGULAR_MOTOR_FACTOR = 4.0

RESIDUAL_PARAMS = {
    "lambda": Param(
        "number",
        12.0,
        doc="CUSUM threshold [nats]: a false alarm about every e^lambda windows in "
        "theory (independent windows)",
        minimum=0.0,
        exclusive=True,
    ),
    "window": Param(
        "number",
        0.1,
        "s",
        "Length of one residual: the prediction restarts from the observed pose "
        "every window (a whole number of control periods)",
        minimum=0.0,
        exclusive=True,
    ),
    "shift": Param(
        "number",
        4.0,
        doc="The fault the CUSUM is tuned to: a residual of this many noise standard "
        "deviations",
        minimum=0.0,
        exclusive=True,
    ),
    "isolation": Param(
        "number",
        0.3,
        "s",
        "How long after an alarm the residuals still go into the kind, at least "
        "(and at least until a failed drive could have braked to rest from the "
        "commanded speed, plus a window); the detection itself is at the alarm",
        minimum=0.0,
    ),
    "noise_floor": Param(
        "number",
        0.001,
        "m",
        "Least position noise assumed (what the prediction misses without noise)",
        minimum=0.0,
        exclusive=True,
    ),
    "heading_floor": Param(
        "number",
        0.001,
        "rad",
        "Least heading noise assumed",
        minimum=0.0,
        exclusive=True,
    ),
}


def llr(z_norm: np.ndarray, mu: float) -> np.ndarray:
    """Log-likelihood ratio of a mean shift ``mu`` in an unknown 3-D direction.

    ``log E_u[exp(mu u.z - mu^2/2)]`` over unit vectors ``u``, uniform on the
    sphere: ``log(sinh(mu r) / (mu r)) - mu^2 / 2`` for ``r = |z|``.

    >>> round(float(llr(np.array([0.0]), 2.0)[0]), 6)
    -2.0
    """
    x = mu * np.asarray(z_norm, dtype=float)
    # log(sinh(x)/x), stable for small and large x.
    small = x < 1e-4
    safe = np.where(small, 1.0, x)
    big = safe + np.log1p(-np.exp(-2.0 * safe)) - np.log(2.0 * safe)
    return np.where(small, x * x / 6.0, big) - 0.5 * mu * mu


def _accumulate(st: DetectorState, i: np.ndarray, k: np.ndarray, sums: tuple) -> None:
    """Add windows ``k`` (of the due rows) to vehicles ``i``'s sums for isolation.

    ``i`` and ``k`` are arrays of the same length (``i`` without repeats).
    """
    z, raw, observed, travel, seconds, rotation = sums
    st.acc[i] += z[k]
    st.acc_abs[i] += np.abs(z[k])
    st.acc_raw[i] += raw[k]
    st.acc_obs[i] += observed[k]
    st.acc_pred[i] += travel[k]
    st.acc_t[i] += seconds[k]
    first = st.acc_n[i] == 0
    st.acc_rot0[i[first]] = rotation[k[first]]
    st.acc_rot[i] += rotation[k]
    st.acc_n[i] += 1


def _floored(x: np.ndarray) -> np.ndarray:
    """``max(0.0, x)`` of each element as Python takes it (0.0 unless ``x > 0``)."""
    return np.where(x > 0.0, x, 0.0)


@register_detector("oracle")
def oracle(ctx: DetectorContext) -> np.ndarray:
    """The truth, known at once (v0.1's behaviour)."""
    return ctx.failing.copy()


@register_detector("residual", params=RESIDUAL_PARAMS, batched=True)
def residual(ctx: DetectorContext) -> tuple[np.ndarray, list[str]]:
    """Residuals of the observed motion against the commands, and a CUSUM."""
    st: DetectorState | None = ctx.memory.get("state")
    if st is None or ctx.commands is None:
        # The first poses (or, with a delay, the first copies held): start from them.
        st = ctx.memory["state"] = start_state(ctx)
        return st.detected.copy(), list(st.kinds)
    if st.history is None:
        st.history = shape_history(ctx)
    if residual_kernel.usable():  # the compiled path: the pass in one C call
        events = residual_kernel.ResidualPass.of(ctx).run(
            st, ctx.t, ctx.seen, ctx.fresh, ctx.in_contact, ctx.commands,
            ctx.memory.get("trace"),
        )  # fmt: skip
    else:
        st.history.append(ctx.t, ctx.seen, ctx.fresh)
        events = residual_pass(st, ctx)
    read_kinds(st, ctx, events)
    return st.detected.copy(), list(st.kinds)


def residual_pass(st: DetectorState, ctx: DetectorContext) -> tuple:
    """:func:`residual`'s period after the history's append, up to reading kinds.

    The motor model, the windows, the contact gate, the due windows' residuals and
    CUSUMs, the sums for isolation, the latch of an alarm and a clearing: the
    definition of :meth:`~sandbox.behaviour.residual_kernel.ResidualPass.run`, which
    returns the same. Each row's kind is read after (:func:`_read_kinds`), from its
    own row alone.

    Returns
    -------
    tuple
        :data:`~sandbox.behaviour.residual_kernel.QUIET`, or the rows read on while
        isolating, cleared and alarming (ndarray of intp, increasing).
    """
    p = ctx.params
    mu, lam = float(p["shift"]), float(p["lambda"])
    window = max(1, int(round(p["window"] / ctx.dt)))
    sp = np.sqrt(2.0 * ctx.position_noise**2 + p["noise_floor"] ** 2)
    sh = np.sqrt(2.0 * ctx.heading_noise**2 + p["heading_floor"] ** 2)
    advance_model(st, ctx)
    st.age += 1
    # Windows start from a new observation (never the last one's end), so that no two
    # windows share a pose's noise: independent windows.
    restart = st.pending & ctx.fresh
    if np.any(restart):
        st.pose[restart] = ctx.seen[restart]
        st.start[restart] = ctx.seen[restart]
        st.age[restart] = 0
        st.travel[restart] = 0.0
        st.pending &= ~restart
    contact = ctx.in_contact
    st.last_contact = np.where(contact, ctx.t, st.last_contact)
    # A window touching a contact, or the window after it, is skipped.
    st.gate = np.where(contact, 2 * window, np.maximum(st.gate - 1, 0))
    due = (st.age >= window) & ctx.fresh & ~st.pending
    if not np.any(due):
        return residual_kernel.QUIET
    rows = np.flatnonzero(due)
    seen = ctx.seen[rows]
    pred = st.pose[rows]
    d = seen[:, :2] - pred[:, :2]
    c, s = np.cos(pred[:, 2]), np.sin(pred[:, 2])
    raw = np.column_stack(
        (
            c * d[:, 0] + s * d[:, 1],
            -s * d[:, 0] + c * d[:, 1],
            wrap_difference(seen[:, 2] - pred[:, 2]),
        )
    )
    travel = st.travel[rows]
    sc = np.sqrt(sp * sp + (travel * ctx.heading_noise) ** 2)
    z = raw / np.column_stack((np.full(len(rows), sp), sc, np.full(len(rows), sh)))
    gated = st.gate[rows] > 0
    inc = np.where(gated, 0.0, llr(np.hypot.reduce(z, axis=1), mu))
    trace = ctx.memory.get("trace")
    if trace is not None:  # (t, vehicle, l) of every window used, for studies
        used = ~gated
        trace.extend(
            (ctx.t, int(i), float(x))
            for i, x in zip(rows[used], inc[used], strict=True)
        )
    observed = np.hypot(*(seen[:, :2] - st.start[rows, :2]).T)
    rotation = wrap_difference(seen[:, 2] - st.start[rows, 2])
    seconds = st.age[rows] * ctx.dt
    window_sums = (z, raw, observed, travel, seconds, rotation)
    # Each vehicle's CUSUM alone, all vehicles at once: the rows never mix. Vehicles
    # already detected read their kind on while isolating, and clear.
    used = np.flatnonzero(~gated)
    held = st.detected[rows[used]]
    k_det, k_new = used[held], used[~held]
    k_read = k_det[ctx.t <= st.isolating[rows[k_det]] + 1e-9]
    # The kind from more residuals: a vehicle still braking (a stop or a spin) or a
    # runaway whose speed is near the commanded one is plain only once its drive has
    # reached its faulty command.
    _accumulate(st, rows[k_read], k_read, window_sums)
    i_det = rows[k_det]
    st.clear[i_det] = _floored(st.clear[i_det] - inc[k_det])
    cleared = i_det[st.clear[i_det] >= lam]
    st.detected[cleared] = False
    st.clear[cleared] = 0.0
    i_new = rows[k_new]
    restart = i_new[st.g[i_new] <= 0.0]  # g left 0: new sums
    st.acc[restart] = 0.0
    st.acc_abs[restart] = 0.0
    st.acc_raw[restart] = 0.0
    st.acc_obs[restart] = st.acc_pred[restart] = 0.0
    st.acc_t[restart] = st.acc_rot[restart] = 0.0
    st.acc_n[restart] = 0
    st.g[i_new] = _floored(st.g[i_new] + inc[k_new])
    rising = st.g[i_new] > 0.0
    _accumulate(st, i_new[rising], k_new[rising], window_sums)
    alarms = i_new[st.g[i_new] >= lam]
    st.detected[alarms] = True
    # Read on at least until a failed drive could have braked to rest from the
    # commanded speed and its track has shown it at rest, and one window more.
    brakes = ctx.motor_accel if ctx.brake_accel is None else ctx.brake_accel
    for i in alarms:
        braking = float(np.hypot(*st.vel[i])) / float(brakes[i])
        after = braking + window * ctx.dt + RECENT_SPEED_WINDOW
        st.isolating[i] = ctx.t + max(float(p["isolation"]), after)
    st.g[alarms] = 0.0
    st.clear[alarms] = 0.0
    st.pending[rows] = True  # the next window starts at the next observation
    if not (len(k_read) or len(cleared) or len(alarms)):
        return residual_kernel.QUIET
    return rows[k_read], cleared, alarms


class BatchDetection:
    """The detector of a loop's K worlds: its context each period, and the events.

    Made by :meth:`make` from the worlds' scenarios (None for the oracle, which the
    loop applies itself, so that the default is today's behaviour to the bit); the
    rows are the K worlds' ``n`` vehicles, world after world, for any K (a single
    run is K = 1). :meth:`update` is called at every ``t_k`` and returns what each
    world's platoon believes has failed: one call of a detector registered with
    ``batched=True`` on every row (its decisions row by row), any other world by
    world on the world's rows, with the world's own ``memory``. Every world's
    detections are its own (:meth:`summary`), so that each is byte for byte its run
    alone.

    Parameters
    ----------
    scenarios : sequence of Scenario
        The K worlds' scenarios, of one structure (the method, its values and the
        declared noise are the first's; the drives' limits each world's own).
    names : sequence of sequence of str
        Each world's vehicle names.
    """

    def __init__(
        self, scenarios: Sequence[Scenario], names: Sequence[Sequence[str]]
    ) -> None:
        first = scenarios[0]
        spec = first.detection
        registered = get("detector", spec.method)
        self.method = spec.method
        self.func = runnable(registered)
        self.params = dict(spec.params)
        #: Whether the detector is called once on the rows of every world.
        self.batched = bool(registered.options.get("batched"))
        self.K, self.n = len(scenarios), len(names[0])
        self.names = [list(world) for world in names]
        #: What the detector keeps between periods: one dict for the rows of every
        #: world (``batched``), else each world's (``memory`` is the first's).
        self.memories: list[dict] = (
            [{}] if self.batched else [{} for _ in range(self.K)]
        )
        self.memory = self.memories[0]
        sensing = first.sensing
        self.position_noise = float(sensing.position_noise)
        self.heading_noise = float(sensing.heading_noise)
        self.substeps = int(first.substeps)
        vehicles = [v for sc in scenarios for v in sc.vehicles]
        accel = np.array(
            [np.inf if v.motor_accel is None else v.motor_accel for v in vehicles]
        )
        radius = np.array([v.diameter / 2.0 for v in vehicles])
        self.motor_accel = accel
        # The hardest the drive brakes: its declared acceleration limit, within the
        # motor's (a failure's speed moves by at most max_accel h per period).
        declared = np.array(
            [np.inf if v.max_accel is None else v.max_accel for v in vehicles]
        )
        self.brake_accel = np.minimum(accel, declared)
        self.turn_accel = ANGULAR_MOTOR_FACTOR * accel / radius
        #: The commands every vehicle sent in the last period (K n, 2).
        self.intended: np.ndarray | None = None
        delay = int(round(first.sensing.delay / first.dt))
        self._sent: deque[np.ndarray] = deque(maxlen=delay + 1)
        self._known = np.zeros(self.K * self.n, dtype=bool)
        self._open: dict[int, dict] = {}
        #: Each world's detections, ``{"vehicle", "t", "kind", "cleared"}``.
        self.events: list[list[dict]] = [[] for _ in range(self.K)]
        # The built-in residual, whose periods may take its pass in C.
        self._builtin = self.func is residual
        self._kernel: residual_kernel.ResidualPass | None = None

    @classmethod
    def make(
        cls, scenarios: Sequence[Scenario], names: Sequence[Sequence[str]]
    ) -> BatchDetection | None:
        """The detection of K worlds, or None for ``method: oracle``."""
        if scenarios[0].detection.method == "oracle":
            return None
        return cls(scenarios, names)

    def update(
        self,
        t: float,
        dt: float,
        fleet: Any,
        seen: np.ndarray,
        fresh: np.ndarray | None,
        contact: np.ndarray | None,
        failing: np.ndarray,
        live: Sequence[int],
        failed: Callable[[int, PluginRunError], None],
    ) -> np.ndarray:
        """What each world's platoon believes has failed at ``t`` [s], (K n,) bool.

        Parameters
        ----------
        t, dt : float [s]
        fleet : Fleet
            The rows' true states (``pos``, ``theta``, ``vel``).
        seen : ndarray, shape (K n, 3) [m, m, rad]
            The broadcast copies (or the true poses without sensing).
        fresh, contact : ndarray, shape (K n,), bool, or None
            The copies that arrived (None: all) and the rows in contact (None:
            none).
        failing : ndarray, shape (K n,), bool
            The rows with an active failure (the truth, for the oracle).
        live : sequence of int
            The live worlds (a detector called world by world skips the others).
        failed : callable
            ``failed(w, exc)`` ends world ``w`` whose detector raised (world by
            world; a batched detector's error ends every world, in the loop).
        """
        if self.intended is not None:
            self._sent.append(self.intended)
            self.intended = None
        commands = self._sent[0] if len(self._sent) == self._sent.maxlen else None
        if self.batched:
            st = self.memory.get("state") if self._builtin else None
            if (
                st is not None
                and commands is not None
                and st.history is not None
                and residual_kernel.usable()
            ):
                return self._residual_pass(
                    st, t, dt, fleet, seen, fresh, contact, failing, commands
                )
            rows = slice(None)
            ctx = self._context(
                t, dt, fleet, seen, fresh, contact, failing, commands, rows, 0
            )
            known, kinds = self._answer(self.func(ctx), len(seen))
            return self._note(t, known, kinds)
        n = self.n
        known = np.zeros(self.K * n, dtype=bool)
        kinds: list = [None] * (self.K * n)
        for w in live:
            rows = slice(w * n, (w + 1) * n)
            ctx = self._context(
                t, dt, fleet, seen, fresh, contact, failing, commands, rows, w
            )
            try:
                out = self.func(ctx)
            except PluginRunError as exc:
                failed(w, exc)
                continue
            known[rows], kinds[rows] = self._answer(out, n)
        return self._note(t, known, kinds)

    @staticmethod
    def _answer(out: Any, n: int) -> tuple[np.ndarray, list]:
        """A detector's answer as ``(known, kinds)``: (n,) bool, n kinds or None."""
        kinds = None
        if isinstance(out, tuple):
            out, kinds = out
        known = np.asarray(out, dtype=bool).copy()
        return known, [None] * n if kinds is None else list(kinds)

    def _context(
        self, t, dt, fleet, seen, fresh, contact, failing, commands, rows, w
    ) -> DetectorContext:
        """What the detector sees at ``t`` on ``rows`` (all, or world ``w``'s)."""
        seen = seen[rows]
        n = len(seen)
        return DetectorContext(
            t=t,
            dt=dt,
            pos=fleet.pos[rows],
            theta=fleet.theta[rows],
            vel=fleet.vel[rows],
            seen=seen,
            fresh=np.ones(n, dtype=bool) if fresh is None else fresh[rows],
            commands=None if commands is None else commands[rows],
            in_contact=np.zeros(n, dtype=bool) if contact is None else contact[rows],
            failing=failing[rows],
            position_noise=self.position_noise,
            heading_noise=self.heading_noise,
            substeps=self.substeps,
            motor_accel=self.motor_accel[rows],
            turn_accel=self.turn_accel[rows],
            params=self.params,
            memory=self.memories[w],
            brake_accel=self.brake_accel[rows],
        )

    def _residual_pass(
        self, st, t, dt, fleet, seen, fresh, contact, failing, commands
    ) -> np.ndarray:
        """The built-in ``residual`` of a period by its pass in C, without a context.

        The same state, kinds and events as :func:`residual` called through
        :meth:`_context`: the context is built only when a kind is to be read.
        """
        kernel = self._kernel
        if kernel is None or kernel.dt != dt:
            kernel = self._kernel = residual_kernel.ResidualPass(
                len(seen), dt, self.substeps, self.params,
                self.position_noise, self.heading_noise, self.motor_accel,
                self.turn_accel, self.brake_accel,
            )  # fmt: skip
        events = kernel.run(
            st, t, seen, fresh, contact, commands, self.memory.get("trace")
        )
        if events is residual_kernel.QUIET:  # no kind read: nothing detected or not
            self._known = known = self._known.copy()
            return known
        ctx = self._context(
            t, dt, fleet, seen, fresh, contact, failing, commands, slice(None), 0
        )
        read_kinds(st, ctx, events)
        return self._note(t, st.detected.copy(), st.kinds)

    def _note(self, t: float, known: np.ndarray, kinds: list) -> np.ndarray:
        """Record the detections made, re-read and withdrawn at ``t``; ``known``."""
        for i in np.flatnonzero(known & ~self._known):
            kind = kinds[i] or "unknown"
            w, j = divmod(int(i), self.n)
            event = {"vehicle": self.names[w][j], "t": round(t, 9), "kind": kind}
            event["cleared"] = None
            self.events[w].append(event)
            self._open[int(i)] = event
        for i, event in self._open.items():  # a kind still read is updated
            if known[i] and kinds[i]:
                event["kind"] = kinds[i]
        for i in np.flatnonzero(~known & self._known):
            event = self._open.pop(int(i), None)
            if event is not None:
                event["cleared"] = round(t, 9)
        self._known = known
        return known

    def summary(self, w: int) -> dict:
        """World ``w``'s ``Run.info["detection"]``: method, values and events."""
        return {
            "method": self.method,
            "params": dict(self.params),
            "events": [dict(e) for e in self.events[w]],
        }


def detection_metrics(info: dict, failures: list[dict]) -> dict | None:
    """The ``detection`` block of ``metrics.json``, or None under the oracle.

    Parameters
    ----------
    info : dict
        ``Run.info`` (its ``detection`` entry holds the method and the events).
    failures : list of dict
        ``Run.info["failures"]``: ``{vehicle, kind, at, until}`` of each failure.

    Returns
    -------
    dict
        ``method``; ``detections``: ``{vehicle, t, kind, cleared, false_alarm}`` in
        the order they happened, ``false_alarm`` when the vehicle had no active
        failure at ``t``; ``failures``: per failure ``{vehicle, kind, at, detected_at,
        delay, detected_kind, kind_right}`` (the first detection on the vehicle
        during the failure; null fields when it was never detected);
        ``false_alarms``: how many detections were false alarms.
    """
    block = info.get("detection")
    if not block:
        return None
    events = block.get("events", [])

    def failing(vehicle: str, t: float) -> bool:
        return any(
            f["vehicle"] == vehicle
            and f["at"] <= t + 1e-9
            and (f["until"] is None or t + 1e-9 < f["until"])
            for f in failures
        )

    detections = [
        {**e, "false_alarm": not failing(e["vehicle"], e["t"])} for e in events
    ]
    per_failure = []
    for f in failures:
        end = np.inf if f["until"] is None else f["until"]
        hit = next(
            (
                e
                for e in events
                if e["vehicle"] == f["vehicle"] and f["at"] - 1e-9 <= e["t"] < end
            ),
            None,
        )
        per_failure.append(
            {
                "vehicle": f["vehicle"],
                "kind": f["kind"],
                "at": f["at"],
                "detected_at": None if hit is None else hit["t"],
                "delay": None if hit is None else round(hit["t"] - f["at"], 9),
                "detected_kind": None if hit is None else hit["kind"],
                "kind_right": None if hit is None else hit["kind"] == f["kind"],
            }
        )
    return {
        "method": block.get("method"),
        "detections": detections,
        "failures": per_failure,
        "false_alarms": sum(d["false_alarm"] for d in detections),
    }


@register_metrics("detection")
def detection_blocks(run: Any) -> dict[str, Any]:
    """``detections`` and ``detection`` of ``metrics.json`` (none under the oracle)."""
    detection = detection_metrics(run.info, run.info.get("failures", []))
    if detection is None:
        return {}
    return {"detections": detection.pop("detections"), "detection": detection}
