"""The ``glr`` detector: its statistic, its threshold, its noise estimate, its runs."""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import SCENARIOS, run_scenario
from numpy.lib.stride_tricks import sliding_window_view

from sandbox import Simulation, load_scenario
from sandbox.behaviour.glr import (
    chi2_3_tail,
    false_alarm_bound,
    glr_statistic,
    mad_sigma,
    threshold,
)
from sandbox.errors import ScenarioError

FAILURES = SCENARIOS / "failures"
GLR = ("detection.method=glr", "detection.lambda=null")
NOISE_2CM = ("sensing.position_noise=0.02", "sensing.heading_noise=0.01")


def windows(e: np.ndarray, m: int, dt: float = 0.01) -> tuple:
    """Every window of ``m`` consecutive rows of ``e`` (k, 3), as the detector's."""
    t = np.arange(len(e)) * dt
    times = sliding_window_view(t, m)
    values = sliding_window_view(e, m, axis=0).transpose(0, 2, 1)
    return times, values, np.ones(times.shape, dtype=bool)


def test_the_chi2_tail_and_the_threshold():
    # P(chi2_3 > 7.8147) = 0.05 (the table's 95 % point); 0 and below: 1.
    assert chi2_3_tail(7.814728) == pytest.approx(0.05, abs=1e-6)
    assert chi2_3_tail(0.0) == 1.0
    lam = threshold(0.01, 1.0, 0.01)
    # 3600 / 0.01 * 100 * P(chi2_3 > 2 lam) = 0.01 per hour.
    assert false_alarm_bound(lam, 1.0, 0.01) == pytest.approx(0.01, rel=1e-6)
    assert lam == pytest.approx(23.73, abs=0.01)
    assert threshold(0.01, 2.0, 0.01) > lam  # more change times, a higher threshold


def test_a_known_ramp_is_found_at_its_start():
    # 101 observations 0.01 s apart of unit noise; from t = 0.6 s the sum of the
    # innovations ramps at 30 sigma/s in x and -20 sigma/s in heading: the change
    # time and the slopes are found within their errors.
    rng = np.random.default_rng(3)
    t = np.arange(101) * 0.01
    ramp = np.maximum(t - 0.6, 0.0)[:, None] * np.array([30.0, 0.0, -20.0])
    c = rng.standard_normal((101, 3)) + ramp
    g, tau, mu, se = glr_statistic(
        t[None], c[None], np.ones((1, 101), bool), np.ones((1, 3))
    )
    assert abs(t[tau[0]] - 0.6) <= 0.05
    assert np.all(np.abs(mu[0] - [30.0, 0.0, -20.0]) <= 3.5 * se[0])
    # The energy of the ramp, sum (mu r)^2 / 2 over its 40 samples:
    # (30^2 + 20^2) * 0.01^2 * sum_{j<=40} j^2 / 2 = 0.13 * 22140 / 2 = 1439 nats,
    # less what the centring (the unknown constant) takes.
    assert 700.0 < g[0] < 1439.0 + 30.0
    # The same noise without the ramp stays far below.
    g0, *_ = glr_statistic(
        t[None], (c - ramp)[None], np.ones((1, 101), bool), np.ones((1, 3))
    )
    assert g0[0] < 12.0


def test_a_lost_observation_leaves_a_gap_not_a_change():
    # Invalid entries are skipped: the statistic of a window with holes is that of
    # the observations left.
    rng = np.random.default_rng(4)
    t = np.arange(50) * 0.01
    c = rng.standard_normal((1, 50, 3))
    valid = np.ones((1, 50), bool)
    valid[0, 10:20] = False
    g, *_ = glr_statistic(t[None], c, valid, np.ones((1, 3)))
    keep = valid[0]
    g2, *_ = glr_statistic(
        t[None, keep], c[:, keep], np.ones((1, keep.sum()), bool), np.ones((1, 3))
    )
    assert g[0] == pytest.approx(g2[0])


@pytest.mark.parametrize("lam", [6.0, 8.0])
def test_pure_noise_exceeds_lambda_below_the_bound(lam):
    # 10,000 windows of 101 observations of white noise: the fraction whose statistic
    # reaches lambda is below the union bound M P(chi2_3 > 2 lambda), by the factor
    # measured (12 to 20 for lambda from 5 to 10, docs/concepts/detection.md), within
    # a tolerance: between bound / 40 and bound / 5.
    rng = np.random.default_rng(5)
    times, values, valid = windows(rng.standard_normal((10_100, 3)), 101)
    g, *_ = glr_statistic(
        times[:10_000], values[:10_000], valid[:10_000], np.ones((10_000, 3))
    )
    bound = 101 * chi2_3_tail(2.0 * lam)
    assert bound / 40.0 < np.mean(g >= lam) < bound / 5.0


def test_the_mad_estimate_is_robust():
    # Innovations e_k - e_{k-1} of 2 cm noise, with 3 % of them 20 cm off (a fault):
    # the estimate is within 5 % of 2 cm.
    rng = np.random.default_rng(6)
    e = rng.normal(0.0, 0.02, 2001)
    d = np.diff(e)
    d[rng.random(d.size) < 0.03] += 0.2
    assert mad_sigma(d) == pytest.approx(0.02, rel=0.05)


def test_the_noise_estimate_converges_in_a_run():
    # 8 s of the fault-free platoon declaring 1 cm / 0.005 rad while the broadcast
    # draws 1.5 cm / 0.0075 rad: the estimate follows the real noise (within 10 %),
    # above its floor (the declared noise), and no alarm.
    doc = FAILURES / "detect_fault_free.yaml"
    sim = Simulation(
        load_scenario(doc, overrides=[*GLR, "duration=8", "detection.noise_window=5"])
    )
    sim.broadcast.sigma[:] = [0.015, 0.015, 0.0075]
    sim.run()
    st0 = sim.detection.memory["glr"]
    np.testing.assert_allclose(st0.sigma[:, 0], 0.015, rtol=0.1)
    np.testing.assert_allclose(st0.sigma[:, 2], 0.0075, rtol=0.1)
    assert np.all(st0.sigma >= st0.floor)
    assert sim.detection.events == [[]]  # world 0 of 1: no detection


@pytest.mark.parametrize(
    ("name", "sets", "kind"),
    [
        ("detect_follower_stuck_steering", ("failures[0].v2=-0.2", *NOISE_2CM), None),
        ("detect_follower_stop", (), None),
        ("detect_follower_crash", (), None),
    ],
)
def test_a_bundled_failure_under_glr_is_detected_with_its_kind(name, sets, kind):
    _, m = run_scenario(FAILURES / f"{name}.yaml", *GLR, *sets, duration=4.5)
    (failure,) = m["detection"]["failures"]
    assert failure["delay"] is not None and 0.0 <= failure["delay"] <= 0.5
    assert failure["kind_right"], failure
    assert m["detection"]["false_alarms"] == 0
    assert m["detection"]["method"] == "glr"


@pytest.mark.slow
def test_glr_withdraws_a_cleared_failure():
    # The leader spins from 3 s to 7 s: detected as a spin, withdrawn once it drives
    # as commanded for a whole window again.
    _, m = run_scenario(FAILURES / "detect_leader_spin.yaml", *GLR, duration=10)
    (d,) = m["detections"]
    assert d["kind"] == "spin" and not d["false_alarm"]
    assert 7.0 < d["cleared"] < 9.0


@pytest.mark.parametrize(
    ("sets", "message"),
    [
        (
            ["detection.window=0.015"],
            "detection.window: must be a whole number of control periods",
        ),
        (
            ["detection.false_alarms=0"],
            "detection.false_alarms: must be greater than 0",
        ),
        (["detection.noise_window=-1"], "detection.noise_window: must be at least 0"),
        (["detection.lambda=-2"], "detection.lambda: must be greater than 0"),
        (["detection.isolation=x"], "detection.isolation"),
    ],
)
def test_bad_glr_values_give_one_line_errors(sets, message):
    with pytest.raises(ScenarioError, match=re.escape(message)) as info:
        load_scenario(
            FAILURES / "follower_stop.yaml",
            overrides=["detection.method=glr", *sets],
        )
    assert len(str(info.value).splitlines()) == 1
