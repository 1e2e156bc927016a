"""The observed tracks of the vehicles, and what the detectors fit to them.

:class:`TrackHistory` keeps the last observations of every vehicle (the broadcast
poses a detector reads, with which of them were fresh) in ring arrays, one row per
control period: a vehicle's track is read by slicing, not by walking a list of
periods.

:func:`stop_fits` compares two models of a track along its direction of travel, each
fitted over a grid of speeds ``v`` (:data:`SPEEDS` of them) and onsets ``tau`` (the
sample times), with a free offset:

- a *crash* moves at ``v`` until ``tau`` and is at rest after it;
- a braked *stop* moves at ``v`` until ``tau`` and then brakes at ``brake`` to rest
  (reached at ``tau + v / brake``, after ``v^2 / (2 brake)``).

The least sum of squared residuals of each model is the minimum over the grid's
``SPEEDS x m`` rows (``m`` samples), each row's sum taken as numpy takes it: the
residuals ``r = s - model`` of the row's ``m`` samples, less their mean, squared and
summed along the row. Evaluating every row builds arrays of ``SPEEDS x m x m``
elements (0.6 million for a second of samples at 100 Hz), about 9 ms a fit.

The same minimum is found from a few rows. Each row's sum of squares has a closed
form in sums over the samples (``sum s^2``, ``sum s M``, ``sum M^2``, ``sum M`` for the
model ``M``), which prefix sums of ``t^q`` and ``s t^q`` give for all rows at once
(:func:`crash_estimates`, :func:`stop_estimates`). The closed form rounds otherwise
than the row's own sum, but both are within a bound of the exact value: a sum of
``m`` terms rounds by at most about ``m`` units in the last place of the sum of their
magnitudes, and every term here is at most ``W = sum s^2 + m M_max^2`` (``M_max`` the
largest value the model can take). :data:`MARGIN` ``W`` is 10^5 times that bound.
A row whose estimate exceeds the least estimate by more than both rows' margins
cannot hold the minimum, and only the others are evaluated, as numpy evaluates them
in the whole grid (a row's elements are the same elementwise operations, and its sum
the same reduction of a contiguous row): the fit returns the very numbers of the
whole grid, in about 0.5 ms. Where the estimates cannot be trusted (a non-finite
sample, times not in order, a braking limit that is not a positive number) or leave
too many rows, the whole grid is evaluated, a block of rows at a time.

Where the compiled path ``fits`` is on (:mod:`sandbox.accel`; ``_fits.c``), the whole
fit is one C call (about 0.05 ms): the grid of speeds, both models' estimates, the
candidate rows and each candidate's sum of squares, within rtol 1e-9 of
:func:`fits_numpy`, the reference (``tests/test_compiled_paths.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox import accel
from sandbox.model.kernels import c_float64

#: The speeds of the grid, from 0 to 1.5 times the fastest speed observed [1].
SPEEDS = 61
#: A row's estimate is trusted within MARGIN times its bound W [1] (see the module).
MARGIN = 1e-8
#: Above this share of the grid's rows left to evaluate, the whole grid is [1].
MOST_ROWS = 0.25
#: Rows of the grid evaluated at once [1] (the arrays of a block stay small).
BLOCK_ROWS = 2048


class TrackHistory:
    """The last ``length`` observations of ``n`` vehicles, in ring arrays.

    Each :meth:`append` stores one control period: its time, every vehicle's
    observed value (a position ``(2,)``, a heading ``()``) and whether it was fresh
    (a new broadcast, not a held copy).

    >>> h = TrackHistory(3, 2, (2,))
    >>> for k in range(4):
    ...     h.append(0.1 * k, np.full((2, 2), float(k)), np.array([True, k % 2 == 0]))
    >>> t, xy = h.track(1)
    >>> t.tolist(), xy[:, 0].tolist()
    ([0.2], [2.0])
    """

    def __init__(self, length: int, n: int, shape: tuple[int, ...] = ()) -> None:
        self.length = int(length)
        self.times = np.zeros(self.length)
        self.values = np.zeros((self.length, n, *shape))
        self.fresh = np.zeros((self.length, n), dtype=bool)
        self.count = 0  # periods stored, at most length
        self._next = 0  # the slot of the next period
        self._orders: dict[tuple[int, int], np.ndarray] = {}  # _order's, kept

    def __len__(self) -> int:
        return self.count

    def append(self, t: float, values: np.ndarray, fresh: np.ndarray) -> None:
        """Store one period's observations (copied), dropping the oldest when full."""
        k = self.advance(t)
        self.values[k] = values
        self.fresh[k] = fresh

    def advance(self, t: float) -> int:
        """Start storing one period at ``t``, dropping the oldest when full.

        Returns the slot whose ``values[slot]`` and ``fresh[slot]`` the caller fills
        (:meth:`append` does).
        """
        k = self._next
        self.times[k] = t
        self._next = (k + 1) % self.length
        self.count = min(self.count + 1, self.length)
        return k

    @property
    def newest(self) -> float:
        """The time of the last period stored [s]."""
        return float(self.times[(self._next - 1) % self.length])

    def _order(self) -> np.ndarray:
        """The slots of the stored periods, oldest first (kept: not to be written)."""
        start = (self._next - self.count) % self.length
        order = self._orders.get((start, self.count))
        if order is None:
            order = (start + np.arange(self.count)) % self.length
            self._orders[start, self.count] = order
        return order

    def track(self, i: int, since: float = -np.inf) -> tuple[np.ndarray, np.ndarray]:
        """Vehicle ``i``'s fresh observations at or after ``since``, oldest first.

        Returns
        -------
        t : ndarray (r,) [s]
        values : ndarray (r, *shape)
        """
        order = self._order()
        t = self.times[order]
        rows = order[self.fresh[order, i] & (t >= since)]
        return self.times[rows], self.values[rows, i]


def stop_fits(t: np.ndarray, s: np.ndarray, brake: float) -> tuple[float, float]:
    """How well a crash and a braked stop explain a track (least squares).

    Parameters
    ----------
    t : ndarray (m,) [s]
        Times of the observed positions, increasing.
    s : ndarray (m,) [m]
        The positions along the direction of travel.
    brake : float [m/s^2]
        The drive's braking limit (finite, above 0; for others the numpy form
        evaluates the whole grid and the compiled form's numbers are its own).

    Returns
    -------
    crash, stop : float [m^2]
        The least sum of squared residuals of the two models over the grid of
        speeds and onsets (see the module docstring).

    >>> t = np.arange(0.0, 1.0, 0.01)
    >>> crash, stop = stop_fits(t, np.minimum(t, 0.5), 5.0)
    >>> bool(crash < stop)
    True
    """
    c = accel.module("fits")
    if c is not None:  # the whole fit in one C call
        return c.fits(
            c_float64(t), c_float64(s), float(brake), SPEEDS, MOST_ROWS, MARGIN
        )
    return fits_numpy(*_numpy_grid(t, s), brake)


def _numpy_grid(t: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, ...]:
    """The times from the first [s], the positions [m] and the grid's speeds [m/s]."""
    t = np.asarray(t, dtype=float) - t[0]
    s = np.asarray(s, dtype=float)
    lag = min(10, len(t) - 1)
    speed = np.abs(s[lag:] - s[:-lag]) / np.maximum(t[lag:] - t[:-lag], 1e-9)
    v = np.linspace(0.0, 1.5 * float(speed.max()), SPEEDS)
    return t, s, v


def fits_numpy(
    t: np.ndarray, s: np.ndarray, v: np.ndarray, brake: float
) -> tuple[float, float]:
    """:func:`stop_fits` after its grid of speeds ``v``, by numpy (the reference).

    ``t`` (m,) from 0 [s], ``s`` (m,) [m].
    """
    trusted = (
        bool(np.all(np.isfinite(t)) and np.all(np.isfinite(s)))
        and bool(np.all(np.diff(t) >= 0.0))
        and float(brake) > 0.0
    )
    out = []
    for crash in (True, False):
        if trusted:
            estimates = crash_estimates if crash else stop_estimates
            est, margin = estimates(t, s, v, brake)
            rows = candidate_rows(est, margin)
        else:
            rows = None
        if rows is None or len(rows) > MOST_ROWS * v.size * t.size:
            rows = np.arange(v.size * t.size)
        out.append(least_row(t, s, v, brake, crash, rows))
    return out[0], out[1]


def model_rows(
    t: np.ndarray,
    v: np.ndarray,
    tau: np.ndarray,
    brake: float,
    crash: bool,
) -> np.ndarray:
    """The model of each row (speed ``v[k]``, onset ``tau[k]``) at the times ``t``.

    Parameters
    ----------
    t : ndarray (m,) [s]
    v, tau : ndarray (c,) [m/s], [s]
    brake : float [m/s^2]
    crash : bool
        The crash model (at rest after ``tau``), else the braked stop.

    Returns
    -------
    ndarray (c, m) [m]
    """
    v, tau, tt = v[:, None], tau[:, None], t[None, :]
    run = np.minimum(tt, tau)
    if crash:
        return v * run
    braking = np.clip(tt - tau, 0.0, v / brake)
    return v * (run + braking) - 0.5 * brake * braking**2


def row_ssr(s: np.ndarray, model: np.ndarray) -> np.ndarray:
    """Each row's sum of squared residuals with a free offset, shape (c,) [m^2]."""
    r = s - model
    r = r - r.mean(axis=-1, keepdims=True)
    return (r * r).sum(axis=-1)


def least_row(
    t: np.ndarray,
    s: np.ndarray,
    v: np.ndarray,
    brake: float,
    crash: bool,
    rows: np.ndarray,
) -> float:
    """The least sum of squares among the grid's ``rows`` (flat, speed-major)."""
    m = len(t)
    least = np.inf
    for start in range(0, len(rows), BLOCK_ROWS):
        speed, onset = np.divmod(rows[start : start + BLOCK_ROWS], m)
        sums = row_ssr(s, model_rows(t, v[speed], t[onset], brake, crash))
        least = np.minimum(least, sums.min())  # NaN stays, as in np.min
    return float(least)


def candidate_rows(est: np.ndarray, margin: np.ndarray) -> np.ndarray | None:
    """The rows (flat) whose sum of squares may be the least; None if unsure.

    ``est`` (SPEEDS, m): each row's estimate; ``margin`` (SPEEDS, 1): its bound.
    """
    if not (np.all(np.isfinite(est)) and np.all(np.isfinite(margin))):
        return None
    margins = np.broadcast_to(margin, est.shape)
    best = int(np.argmin(est))
    ceiling = est.flat[best] + margins.flat[best]
    return np.flatnonzero(est - margins <= ceiling)


def crash_estimates(
    t: np.ndarray, s: np.ndarray, v: np.ndarray, brake: float
) -> tuple[np.ndarray, np.ndarray]:
    """Every crash row's sum of squares in closed form, and its margin.

    With ``g = min(t, tau)`` the model is ``v g``, and the sum of squares with a free
    offset is ``sum s^2 - 2 v sum s g + v^2 sum g^2 - (sum s - v sum g)^2 / m``.

    Returns
    -------
    est : ndarray (SPEEDS, m) [m^2]
    margin : ndarray (SPEEDS, 1) [m^2]
    """
    m = len(t)
    g = np.minimum(t[None, :], t[:, None])  # row j: onset t_j
    g1, g2, sg = g.sum(axis=1), (g * g).sum(axis=1), g @ s
    s1, s2 = float(s.sum()), float(s @ s)
    vv = v[:, None]
    est = s2 - 2.0 * vv * sg + vv * vv * g2 - (s1 - vv * g1) ** 2 / m
    reach = vv * float(np.max(np.abs(t)))  # the largest |model|
    return est, MARGIN * (s2 + m * reach * reach)


def stop_estimates(
    t: np.ndarray, s: np.ndarray, v: np.ndarray, brake: float
) -> tuple[np.ndarray, np.ndarray]:
    """Every braked-stop row's sum of squares in closed form, and its margin.

    For onset ``tau = t_j`` and braking time ``L = v / brake`` the model is ``v t``
    up to ``tau``, ``v t - brake (t - tau)^2 / 2`` while braking and ``v tau + v L /
    2`` at rest: the three pieces' sums over their samples come from prefix sums of
    ``t^q`` (q <= 4) and ``s t^q`` (q <= 2).

    Returns
    -------
    est : ndarray (SPEEDS, m) [m^2]
    margin : ndarray (SPEEDS, 1) [m^2]
    """
    c = accel.module("fits")
    if c is not None:
        return _stop_estimates_c(c, t, s, v, brake)
    return stop_estimates_numpy(t, s, v, brake)


def _stop_estimates_c(
    c: Any, t: np.ndarray, s: np.ndarray, v: np.ndarray, brake: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`stop_estimates` by one C loop (the same formula; see the module)."""
    m = len(t)
    s1, s2 = float(s.sum()), float(s @ s)
    est = np.empty((len(v), m))
    c.stop_estimates(
        c_float64(t), c_float64(s), c_float64(v), float(brake), s1, s2, est
    )
    vv = v[:, None]
    span = float(np.max(np.abs(t)))
    reach = 2.0 * brake * span * span + vv * (2.0 * span + vv / brake)
    return est, MARGIN * (s2 + m * reach * reach)


def stop_estimates_numpy(
    t: np.ndarray, s: np.ndarray, v: np.ndarray, brake: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`stop_estimates` by numpy (the reference)."""
    m = len(t)
    powers = t[None, :] ** np.arange(5)[:, None]  # (5, m)
    terms = np.concatenate((powers, powers[:3] * s))  # t^q, then s t^q
    prefix = np.concatenate((np.zeros((8, 1)), np.cumsum(terms, axis=1)), axis=1)
    s1, s2 = float(s.sum()), float(s @ s)
    vv = v[:, None]
    tau = t[None, :]
    length = vv / brake  # braking time [s]
    onset = np.arange(1, m + 1)  # samples up to and with the onset
    end = np.maximum(np.searchsorted(t, tau + length, side="left"), onset)
    upto = prefix[:, onset]  # (8, m)
    # the braking samples' sums of t^q and s t^q, each (SPEEDS, m)
    r0, r1, r2, r3, r4, q0, q1, q2 = (prefix[q][end] - upto[q] for q in range(8))
    # braking: a t^2 + b t + c; at rest: v tau + v L / 2
    a = -0.5 * brake
    b = vv + brake * tau
    c = -0.5 * brake * tau * tau
    rest = vv * tau + 0.5 * vv * length
    left = m - end
    sum_m = vv * upto[1] + (a * r2 + b * r1 + c * r0) + rest * left
    sum_mm = (
        vv * vv * upto[2]
        + (a * a * r4 + 2.0 * a * b * r3 + (b * b + 2.0 * a * c) * r2)
        + (2.0 * b * c * r1 + c * c * r0)
        + rest * rest * left
    )
    sum_sm = vv * upto[6] + (a * q2 + b * q1 + c * q0) + rest * (s1 - prefix[5][end])
    est = s2 - 2.0 * sum_sm + sum_mm - (s1 - sum_m) ** 2 / m
    span = float(np.max(np.abs(t)))
    reach = 2.0 * brake * span * span + vv * (2.0 * span + length)
    return est, MARGIN * (s2 + m * reach * reach)
