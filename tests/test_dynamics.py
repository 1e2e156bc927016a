"""Unicycle kinematics, eq. (1), and the angle helper: hand-computed values."""

import math

import numpy as np
import pytest

from sandbox.model.dynamics import unicycle_rates, unicycle_step, wrap_angle


@pytest.mark.parametrize(
    ("angle", "expected"),
    [
        (0.0, 0.0),
        (1.0, 1.0),
        (math.pi, -math.pi),  # the interval is [-pi, pi): +pi maps to -pi
        (-math.pi, -math.pi),
        (3 * math.pi / 2, -math.pi / 2),  # 270 deg = -90 deg
        (-3 * math.pi / 2, math.pi / 2),
        (2 * math.pi + 0.25, 0.25),
        (-7 * math.pi, -math.pi),  # -7 pi = -pi - 3 * 2 pi
        (np.nextafter(-math.pi, -np.inf), -math.pi),  # rounds to the lower end, not +pi
    ],
)
def test_wrap_angle_values(angle: float, expected: float) -> None:
    assert float(wrap_angle(angle)) == pytest.approx(expected, abs=1e-12)


def test_wrap_angle_across_pi_is_the_short_way() -> None:
    # From pi - 0.1 to -pi + 0.1 the short way is +0.2 rad (through pi),
    # not -2 pi + 0.2.
    a, b = math.pi - 0.1, -math.pi + 0.1
    assert float(wrap_angle(b - a)) == pytest.approx(0.2, abs=1e-12)
    assert float(wrap_angle(a - b)) == pytest.approx(-0.2, abs=1e-12)


def test_wrap_angle_is_vectorized() -> None:
    out = wrap_angle(np.array([[0.0, 4.0], [-4.0, 10.0]]))
    assert out.shape == (2, 2)
    # 4 - 2 pi = -2.2832; -4 + 2 pi = 2.2832; 10 - 4 pi = -2.5664
    np.testing.assert_allclose(out, [[0.0, -2.283185307], [2.283185307, -2.566370614]])


def test_unicycle_rates_eq1() -> None:
    # x1' = v1 cos x3 = 2 cos(pi/2) = 0; x2' = 2 sin(pi/2) = 2; x3' = v2 = 0.5
    rates = unicycle_rates(np.array([math.pi / 2]), np.array([2.0]), np.array([0.5]))
    np.testing.assert_allclose(rates, [[0.0, 2.0, 0.5]], atol=1e-15)


def test_unicycle_step_straight() -> None:
    # v = 1 m/s, omega = 0, dt = 1 s from the origin heading 0: one metre along x1.
    pose = unicycle_step(np.zeros((1, 3)), np.ones(1), np.zeros(1), 1.0)
    np.testing.assert_allclose(pose, [[1.0, 0.0, 0.0]], atol=1e-15)


def test_unicycle_step_quarter_circle() -> None:
    # v = 1, omega = pi/2, dt = 1: a quarter turn on a circle of radius v/omega = 2/pi
    # centred at (0, 2/pi); it ends at (2/pi, 2/pi) heading pi/2.
    pose = unicycle_step(np.zeros((1, 3)), np.ones(1), np.array([math.pi / 2]), 1.0)
    r = 2 / math.pi
    np.testing.assert_allclose(pose, [[r, r, math.pi / 2]], atol=1e-12)


def test_unicycle_step_matches_fine_integration() -> None:
    # The closed form equals eq. (1) integrated numerically (midpoint rule, 200k steps).
    x0, y0, th0, v1, v2, dt = 1.0, -2.0, 0.3, 1.5, -0.8, 2.0
    exact = unicycle_step(np.array([[x0, y0, th0]]), np.array([v1]), np.array([v2]), dt)
    steps = 200_000
    th = th0 + v2 * (np.arange(steps) + 0.5) * (dt / steps)
    x = x0 + v1 * np.cos(th).sum() * (dt / steps)
    y = y0 + v1 * np.sin(th).sum() * (dt / steps)
    np.testing.assert_allclose(exact, [[x, y, th0 + v2 * dt]], atol=1e-9)


def test_unicycle_zero_command_stays_put() -> None:
    pose0 = np.array([[3.0, 4.0, -1.0], [0.0, 0.0, 2.0]])
    out = unicycle_step(pose0, np.zeros(2), np.zeros(2), 5.0)
    np.testing.assert_array_equal(out, pose0)
