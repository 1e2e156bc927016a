"""The error a formation law keeps by design: eq. (12)'s steady state of a turn.

A follower of the ``rotating`` law (and of ``virtual`` with ``rotate: true``) is fed
the derivatives of its frame's origin (the leader, or the virtual leader), not those
of its own slot, which turns with the frame. On a reference turning at a steady rate
``w`` it therefore keeps a steady error (eq. (12) of the report). With the
controller's error dynamics ``e'' - k2 e' - k1 e`` (gains of
:class:`~sandbox.model.flatness.Gains`, negative) and the error constant in the
turning frame, its size is

    |Err| = |delta| |w| sqrt(k2^2 + w^2) / sqrt((k1 + w^2)^2 + (k2 w)^2)

for a slot at offset ``delta`` from the origin: eq. (12)'s first-order
``|delta| |w| sqrt(k2^2 + w^2) / |k1|`` divided by 1.0004 for the report's gains at
``w = 0.2`` rad/s (``tests/test_paper_sections_2_3.py`` derives both). On the bundled
``paper/rotating_circle`` (``|delta|`` = 1.414 m, 5 m circle at 1 m/s) it is 5.65 cm,
above the default ``metrics.settle_tol`` of 5 cm: ``converged`` then says no for a
formation that does all its law can. :func:`steady_state` gives each follower's
steady error at the end of a run, so that ``metrics.json`` can also tell convergence
to it (``steady_state``, :func:`~sandbox.run.metrics.compute_metrics`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: The laws whose followers keep eq. (12)'s steady error on a turning reference (the
#: law, and whether it needs ``rotate: true``).
TURNING_LAWS = {"rotating": False, "virtual": True}


def turning_steady_error(delta: float, w: float, k1: float, k2: float) -> float:
    """Steady error [m] of a slot ``delta`` [m] from a frame turning at ``w`` [rad/s].

    Parameters
    ----------
    delta : float [m]
        Distance of the slot from the frame's origin, ``|delta|``.
    w : float [rad/s]
        The frame's turn rate.
    k1 : float [1/s^2]
    k2 : float [1/s]
        The controller's gains of the axis (the report's: -100 and -20).

    Returns
    -------
    float [m]

    Examples
    --------
    The bundled ``paper/rotating_circle``: 1.414 m on a 5 m circle at 1 m/s.

    >>> round(turning_steady_error(math.sqrt(2.0), 0.2, -100.0, -20.0), 5)
    0.05655
    >>> turning_steady_error(1.0, 0.0, -100.0, -20.0)
    0.0
    """
    num = abs(delta) * abs(w) * math.sqrt(k2 * k2 + w * w)
    return num / math.hypot(k1 + w * w, k2 * w)


def turn_rate(t: np.ndarray, path: np.ndarray, window: float) -> float | None:
    """Mean turn rate [rad/s] of a path's heading over its last ``window`` [s].

    Parameters
    ----------
    t : ndarray, shape (T,) [s]
    path : ndarray, shape (T, 2) [m]
        Points of the path at ``t`` (its heading is that of its steps).
    window : float [s]

    Returns
    -------
    float or None
        None where the path does not move over the window.

    >>> t = np.linspace(0.0, 10.0, 1001)
    >>> circle = 5.0 * np.stack((np.cos(0.2 * t), np.sin(0.2 * t)), -1)
    >>> round(turn_rate(t, circle, 1.0), 6)
    0.2
    """
    start = int(np.searchsorted(t, t[-1] - window - 1e-9))
    pts, times = path[start:], t[start:]
    step = np.diff(pts, axis=0)
    moving = np.isfinite(step).all(axis=1) & (np.hypot(step[:, 0], step[:, 1]) > 0)
    if moving.sum() < 2:
        return None
    heading = np.unwrap(np.arctan2(step[moving, 1], step[moving, 0]))
    mid = 0.5 * (times[1:] + times[:-1])[moving]
    if mid[-1] <= mid[0]:
        return None
    return float((heading[-1] - heading[0]) / (mid[-1] - mid[0]))


def steady_state(run: Any, window: float) -> dict[str, Any] | None:
    """Each follower's steady error at the end of ``run`` [m], or None.

    Parameters
    ----------
    run : Run
        A run of one platoon whose law is in :data:`TURNING_LAWS`, without
        reassignments (the offsets are the file's to the end).
    window : float [s]
        The stretch at the end over which the reference's turn rate is measured.

    Returns
    -------
    dict or None
        ``{"law", "turn_rate" [rad/s], "errors": {vehicle: [m]}}`` (the leader and
        vehicles without an offset are left out); None for other runs, and for a
        reference that does not move at the end.
    """
    sc = run.scenario
    if sc is None or sc.formation is None or getattr(sc, "platoons", ()):
        return None
    law = sc.formation.law
    if law not in TURNING_LAWS or (TURNING_LAWS[law] and not sc.formation.rotate):
        return None
    if run.info.get("reassignments") or len(run.t) < 3:
        return None
    reference = np.asarray(run.reference, dtype=float).reshape(len(run.t), -1)
    if reference.shape[1] != 2:
        return None
    w = turn_rate(np.asarray(run.t), reference, window)
    if w is None:
        return None
    errors = {}
    for v in sc.vehicles:
        if v.leader or v.name not in run.names:
            continue
        delta = math.hypot(*v.offset)
        g = v.gains
        axes = ((g.k1, g.k2), (g.k3, g.k4))
        if not all(np.ndim(k) == 0 for pair in axes for k in pair):
            return None  # per-vehicle arrays of gains: not this file's vehicles
        errors[v.name] = max(
            turning_steady_error(delta, w, float(k1), float(k2)) for k1, k2 in axes
        )
    return {"law": law, "turn_rate": w, "errors": errors}
