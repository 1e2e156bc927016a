"""The crash-or-stop fit from a few rows gives the whole grid's numbers.

``grid_fits`` is the fit as it was first written (every row of the grid of speeds
and onsets evaluated at once): the reference that the numpy form of
:func:`sandbox.behaviour.tracks.stop_fits` must equal exactly (the same numpy
operations on the rows it keeps), and its compiled form (the path ``fits``) within
rtol 1e-9, on the tracks the detector reads (crashes, braked stops, steady driving,
noise) and on hostile ones.
"""

from __future__ import annotations

import numpy as np
import pytest

from sandbox import accel
from sandbox.behaviour import tracks
from sandbox.behaviour.tracks import stop_fits


def grid_fits(t, s, brake):
    """The least squares of both models over every row of the grid at once."""
    t = np.asarray(t, dtype=float) - t[0]
    s = np.asarray(s, dtype=float)
    lag = min(10, len(t) - 1)
    speed = np.abs(s[lag:] - s[:-lag]) / np.maximum(t[lag:] - t[:-lag], 1e-9)
    v = np.linspace(0.0, 1.5 * float(speed.max()), 61)[:, None, None]
    tau = t[None, :, None]
    tt = t[None, None, :]
    run = np.minimum(tt, tau)
    crash = v * run
    braking = np.clip(tt - tau, 0.0, v / brake)
    stop = v * (run + braking) - 0.5 * brake * braking**2

    def ssr(model):
        r = s - model
        r = r - r.mean(axis=-1, keepdims=True)
        return float((r * r).sum(axis=-1).min())

    return ssr(crash), ssr(stop)


def track(rng, kind: int, m: int):
    """A track of ``m`` samples at 100 Hz: crash, stop, steady, a random walk."""
    t = 3.0 + np.arange(m) * 0.01
    if kind == 4:  # jittered sample times (lost and late packets)
        t = np.sort(t + rng.uniform(0.0, 0.004, m))
    v0, brake = rng.uniform(0.0, 2.5), float(rng.choice([0.5, 2.0, 5.0, 50.0]))
    tt, onset = t - t[0], rng.uniform(0.0, t[-1] - t[0])
    if kind == 0:
        s = v0 * np.minimum(tt, onset)
    elif kind == 1:
        b = np.clip(tt - onset, 0.0, v0 / brake)
        s = v0 * (np.minimum(tt, onset) + b) - 0.5 * brake * b * b
    elif kind == 2:
        s = v0 * tt
    else:
        s = np.cumsum(rng.normal(0.0, 0.02, m))
    noise = float(rng.choice([0.0, 0.001, 0.01, 0.03]))
    return t, s + rng.normal(0.0, noise, m) + rng.uniform(-3.0, 3.0), brake


@pytest.fixture(params=[True, False], ids=["c", "numpy"])
def kernel(request):
    """The fits in C (where the path is on) and by numpy."""
    if request.param:
        if accel.module("fits") is None:
            pytest.skip("the compiled path fits is off")
        yield True
        return
    with accel.switched_off("fits"):
        yield False


def assert_fits(got, want, kernel: bool) -> None:
    """numpy's fit: the grid's numbers; the compiled fit: within rtol 1e-9."""
    if kernel:
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=0.0, equal_nan=True)
    else:
        np.testing.assert_array_equal(got, want)  # NaN where the grid has NaN


@pytest.mark.parametrize("seed", range(6))
def test_fit_equals_the_whole_grid(seed, kernel):
    rng = np.random.default_rng(seed)
    for k in range(40):
        t, s, brake = track(rng, k % 5, int(rng.integers(10, 102)))
        assert_fits(stop_fits(t, s, brake), grid_fits(t, s, brake), kernel)


def test_crash_and_stop_told_apart():
    # A wreck at rest from 0.5 s (a crash); a stop braking at 5 m/s^2 from 1 m/s.
    t = np.arange(0.0, 1.0, 0.01)
    crash, stop = stop_fits(t, np.minimum(t, 0.5), 5.0)
    assert crash < stop
    b = np.clip(t - 0.3, 0.0, 0.2)
    crash, stop = stop_fits(t, np.minimum(t, 0.3) + b - 2.5 * b * b, 5.0)
    assert stop < crash


@accel.switched_off("fits")
def test_few_rows_are_evaluated(monkeypatch):
    # The closed forms leave a handful of the 61 x 101 rows on a clean track (the
    # numpy fits, whose rows are seen).
    seen = []
    least_row = tracks.least_row

    def counting(t, s, v, brake, crash, rows):
        seen.append(len(rows))
        return least_row(t, s, v, brake, crash, rows)

    monkeypatch.setattr(tracks, "least_row", counting)
    t = np.arange(0.0, 1.01, 0.01)
    rng = np.random.default_rng(3)
    stop_fits(t, np.minimum(t, 0.5) + rng.normal(0.0, 0.01, len(t)), 5.0)
    assert len(seen) == 2 and max(seen) < 50


@pytest.mark.parametrize(
    "case",
    ["nan sample", "unsorted times", "zero brake", "standing still", "few samples"],
)
def test_hostile_tracks_as_the_grid(case, kernel):
    # Where the closed forms cannot be trusted, the whole grid is evaluated.
    t = np.arange(0.0, 0.5, 0.01)
    s = np.minimum(t, 0.2)
    brake = 5.0
    if case == "nan sample":
        s = s.copy()
        s[7] = np.nan
    elif case == "unsorted times":
        t = t[::-1].copy()
    elif case == "zero brake":
        if kernel:  # outside the fit's domain (brake > 0): each form's own arithmetic
            pytest.skip("a braking limit of 0 is outside the compiled fit's domain")
        brake = 0.0
    elif case == "standing still":
        s = np.zeros_like(t)
    elif case == "few samples":
        t, s = t[:10], s[:10]
    with np.errstate(invalid="ignore", divide="ignore"):
        got, want = stop_fits(t, s, brake), grid_fits(t, s, brake)
    assert_fits(got, want, kernel)
