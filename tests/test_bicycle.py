"""The kinematic bicycle's equations, hand-computed (sandbox/model/bicycle.py).

The anchor for the flat car is python-control's ``examples/kincar-flatsys.py``: its
forward map (``vehicle_flat_forward``) is written out below and the steering angle
recovered by :func:`flat_steer` from the flat output's derivatives.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sandbox.model.bicycle import (
    CarLimits,
    bicycle_rates,
    car_controller_step,
    car_turn_limit,
    flat_steer,
    limit_steer,
    limit_steer_angle,
    min_turning_radius,
    steer_angle,
    steer_commands,
    turn_rate,
)
from sandbox.model.flatness import Gains


def flat_forward(x: np.ndarray, u: np.ndarray, wheelbase: float) -> tuple:
    """python-control's ``vehicle_flat_forward``: the flat output's derivatives."""
    v, delta = u
    thdot = v / wheelbase * math.tan(delta)
    first = np.array([v * math.cos(x[2]), v * math.sin(x[2])])
    second = np.array([-v * thdot * math.sin(x[2]), v * thdot * math.cos(x[2])])
    return first, second


def test_rates_of_a_car_at_45_degrees_of_steering() -> None:
    # theta = 0, v = 1 m/s, delta = pi/4, L = 1 m: x1' = 1, x2' = 0, x3' = tan(pi/4) = 1
    rates = bicycle_rates(np.zeros(1), np.ones(1), np.full(1, math.pi / 4), np.ones(1))
    np.testing.assert_allclose(rates, [[1.0, 0.0, 1.0]], atol=1e-15)
    # heading pi/2: the motion is along x2
    rates = bicycle_rates(np.full(1, math.pi / 2), np.full(1, 2.0), np.zeros(1), 1.0)
    np.testing.assert_allclose(rates, [[0.0, 2.0, 0.0]], atol=1e-15)


def test_a_car_does_not_turn_in_place() -> None:
    # v2 = v1 tan(delta) / L: zero at v1 = 0 whatever the steering angle
    assert turn_rate(np.zeros(3), np.array([-0.5, 0.0, 0.5]), 1.0).tolist() == [
        0.0,
        0.0,
        0.0,
    ]
    assert car_turn_limit(np.zeros(1), np.ones(1), np.full(1, 0.5))[0] == 0.0


def test_least_turning_radius() -> None:
    # L = 1 m, max_steer = 0.5 rad: R = 1 / tan(0.5) = 1 / 0.546302 = 1.830487 m
    assert min_turning_radius(1.0, 0.5) == pytest.approx(1.830487, abs=1e-6)
    # the turn limit at 2 m/s is the speed over that radius: 2 / 1.830487 = 1.092605
    limit = car_turn_limit(np.full(1, 2.0), np.ones(1), np.full(1, 0.5))
    assert limit[0] == pytest.approx(2.0 / 1.830487, rel=1e-6)


@pytest.mark.parametrize(
    ("theta", "v", "delta"),
    [(0.0, 10.0, 0.1), (1.0, 10.0, -0.05), (-2.5, 3.0, 0.4), (0.3, 0.5, 0.0)],
)
def test_flat_steer_inverts_the_flat_forward_map(theta, v, delta) -> None:
    # python-control's example: wheelbase 3 m, 10 m/s.
    first, second = flat_forward(np.array([0.0, 0.0, theta]), (v, delta), 3.0)
    got = flat_steer(first[None], second[None], np.full(1, 3.0))
    assert got[0] == pytest.approx(delta, abs=1e-12)


def test_flat_steer_by_hand() -> None:
    # chi = (1, 0), chi' = (0, 1), L = 1: cross = 1 * 1 - 0 * 0 = 1, |chi|^3 = 1,
    # delta = atan2(1, 1) = pi/4
    got = flat_steer(np.array([[1.0, 0.0]]), np.array([[0.0, 1.0]]), np.ones(1))
    assert got[0] == pytest.approx(math.pi / 4, abs=1e-15)
    # at rest: 0, never NaN
    assert flat_steer(np.zeros((1, 2)), np.ones((1, 2)), np.ones(1))[0] == 0.0


def test_steer_angle_from_the_curvature() -> None:
    # v1 = 2 m/s, v2 = 1 rad/s, L = 1 m: delta = atan(1 * 1 / 2) = 0.463648 rad
    got = steer_angle(
        np.array([2.0, -2.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0, 0.0]), 1.0
    )
    np.testing.assert_allclose(got, [0.463648, -0.463648, math.pi / 2, 0.0], atol=1e-6)
    # the turn rate of that angle is the asked one, reversing included
    v1 = np.array([2.0, -2.0])
    back = turn_rate(v1, got[:2], 1.0)
    np.testing.assert_allclose(back, [1.0, 1.0], rtol=1e-12)


def test_steering_saturates_then_is_rate_limited() -> None:
    # request 1.0 rad against 0.5 rad: 0.5; with 1 rad/s over 0.1 s from 0: 0.1
    got = limit_steer_angle(
        np.array([1.0, 1.0, -0.2, 0.3]),
        np.array([0.0, 0.0, 0.0, 0.35]),
        np.full(4, 0.5),
        np.array([np.inf, 1.0, 1.0, 1.0]),
        0.1,
    )
    np.testing.assert_allclose(got, [0.5, 0.1, -0.1, 0.3], atol=1e-15)


def test_limit_steer_keeps_the_speed_and_turns_to_the_cone() -> None:
    # chi = (0, 2) [m/s] at heading 0 with a cone of 0.1 rad: turned to 0.1 rad,
    # |chi| = 2 kept: (2 cos 0.1, 2 sin 0.1) = (1.990008, 0.199667)
    chi, aim = limit_steer(
        np.array([[0.0, 2.0], [1.0, 0.05]]), np.zeros(2), np.full(2, 0.1)
    )
    np.testing.assert_allclose(chi[0], [1.990008, 0.199667], atol=1e-6)
    assert np.hypot(*chi[0]) == pytest.approx(2.0, abs=1e-15)
    assert aim[0] == pytest.approx(math.pi / 2)
    # within the cone (0.05 rad off): untouched, no aim
    assert chi[1].tolist() == [1.0, 0.05] and np.isnan(aim[1])


def test_steer_commands_hold_the_wheels_at_rest_and_keep_v2_max() -> None:
    limits = CarLimits.of(wheelbase=[1.0] * 4, max_steer=[0.5] * 4, v2_max=[0.2] * 4)
    v1 = np.array([0.0, 0.0, 1.0, 10.0])
    v2 = np.array([0.0, 1.0, 0.1, 1.0])
    held = np.array([0.3, 0.0, 0.0, 0.0])
    u2, steer = steer_commands(v1, v2, held, limits, 0.01)
    # nothing asked at rest: the wheels stay at 0.3; a turn asked at rest: full lock,
    # no turn
    assert steer[0] == 0.3 and u2[0] == 0.0
    assert steer[1] == 0.5 and u2[1] == 0.0
    # 0.1 rad/s at 1 m/s: delta = atan(0.1) = 0.099669, executed exactly
    assert steer[2] == pytest.approx(math.atan(0.1)) and u2[2] == pytest.approx(0.1)
    # 1 rad/s at 10 m/s is beyond v2_max = 0.2: delta = atan(1 * 0.2 / 10) = 0.019997
    assert steer[3] == pytest.approx(math.atan(0.02)) and u2[3] == pytest.approx(0.2)


def test_the_car_controller_holds_a_circle_at_its_curvature() -> None:
    # A car on a circle of radius 5 m at 1 m/s, on its slot, heading along the
    # tangent, chi the reference velocity: eq. (6) asks for the reference's own
    # acceleration, the turn rate is 1 / 5 rad/s and the steering angle
    # atan(L / R) = atan(1 / 5) = 0.197396 rad.
    pos = np.array([[5.0, 0.0]])
    chi = np.array([[0.0, 1.0]])
    theta = np.array([math.pi / 2])
    a_ref = np.array([[-0.2, 0.0]])
    limits = CarLimits.of(wheelbase=[1.0], max_steer=[0.5])
    nxt, v1, v2 = car_controller_step(
        pos, chi, theta, pos.copy(), chi.copy(), a_ref, Gains(), 0.01, limits
    )
    assert v1[0] == pytest.approx(1.0)
    assert v2[0] == pytest.approx(0.2, rel=1e-3)
    _, steer = steer_commands(v1, v2, np.zeros(1), limits, 0.01)
    assert steer[0] == pytest.approx(math.atan(0.2), rel=1e-3)


def test_the_car_controller_does_not_shrink_chi_when_it_must_turn() -> None:
    # Target straight to the left of a car heading +x1 at 1 m/s: a unicycle's
    # anti-windup would shorten chi towards 0 (it turns at rest); the car keeps its
    # speed and turns at full lock towards the target.
    limits = CarLimits.of(wheelbase=[1.0], max_steer=[0.5], v1_max=[1.0])
    nxt, v1, v2 = car_controller_step(
        np.zeros((1, 2)),
        np.array([[1.0, 0.0]]),
        np.zeros(1),
        np.array([[0.0, 3.0]]),
        np.zeros((1, 2)),
        np.zeros((1, 2)),
        Gains(),
        0.01,
        limits,
    )
    assert np.hypot(*nxt[0]) == pytest.approx(1.0)  # clamped at v1_max, not shrunk
    assert v1[0] == pytest.approx(1.0) and v2[0] > 0.0
    _, steer = steer_commands(v1, v2, np.zeros(1), limits, 0.01)
    assert steer[0] == 0.5
