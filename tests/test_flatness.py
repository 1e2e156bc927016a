"""The flatness controller, eqs. (4)-(6): hand-computed values, limits, guards."""

import math

import numpy as np
import pytest

from sandbox.model.flatness import (
    CHI_REST,
    TRAVEL_BACKWARD,
    TRAVEL_FORWARD,
    TRAVEL_NONE,
    Gains,
    advance_extension,
    discrete_spectral_radius,
    extension_rate,
    flat_inputs,
    parking,
    travel_direction,
)

INF = np.array([np.inf])


def v(*rows: float) -> np.ndarray:
    """A (1, k) array from numbers."""
    return np.array([rows], dtype=float)


def test_gains_default_to_the_reports() -> None:
    g = Gains()
    assert (g.k1, g.k2, g.k3, g.k4, g.kp) == (-100.0, -20.0, -100.0, -20.0, 2.0)


# ---------------------------------------------------------------------------- eq. (6)
def test_eq6_tracking_update() -> None:
    # chi1' = k1 (x1 - x1ref) + k2 (chi1 - x1ref') + x1ref''
    #       = -100 * (1 - 0) - 20 * (0.5 - 1) + 0     = -100 + 10       = -90
    # chi2' = -100 * (2 - 0) - 20 * (-0.5 - 0) + 0.3 = -200 + 10 + 0.3 = -189.7
    out = extension_rate(v(1, 2), v(0.5, -0.5), v(0, 0), v(1, 0), v(0, 0.3), Gains())
    np.testing.assert_allclose(out, [[-90.0, -189.7]])


def test_eq6_uses_k1_k2_on_x1_and_k3_k4_on_x2() -> None:
    g = Gains(k1=-4.0, k2=-3.0, k3=-2.0, k4=-1.0)
    # chi1' = -4 * 1 - 3 * (0.5 - 1) + 0   = -4 + 1.5       = -2.5
    # chi2' = -2 * 2 - 1 * (-0.5 - 0) + 0.3 = -4 + 0.5 + 0.3 = -3.2
    out = extension_rate(v(1, 2), v(0.5, -0.5), v(0, 0), v(1, 0), v(0, 0.3), g)
    np.testing.assert_allclose(out, [[-2.5, -3.2]])


def test_eq4_is_eq6_with_a_zero_reference() -> None:
    # chi' = (k1 x1 + k2 chi1, k3 x2 + k4 chi2) = (-100*2 - 20*0.1, -100*(-1) - 20*0.2)
    #      = (-202, 96)
    zero = v(0, 0)
    out = extension_rate(v(2, -1), v(0.1, 0.2), zero, zero, zero, Gains())
    np.testing.assert_allclose(out, [[-202.0, 96.0]])


def test_eq6_on_the_reference_returns_its_acceleration() -> None:
    # No error in position or velocity: chi' is the feedforward x_ref'' alone.
    p, dp, ddp = v(3, 4), v(-0.8, 0.6), v(-0.12, -0.16)
    np.testing.assert_allclose(extension_rate(p, dp, p, dp, ddp, Gains()), ddp)


def test_eq6_per_vehicle_gains() -> None:
    g = Gains(k1=np.array([-1.0, -2.0]), k3=np.array([-1.0, -2.0]), k2=0.0, k4=0.0)
    pos = np.array([[1.0, 1.0], [1.0, 1.0]])
    zero = np.zeros((2, 2))
    out = extension_rate(pos, zero, zero, zero, zero, g)
    np.testing.assert_allclose(out, [[-1.0, -1.0], [-2.0, -2.0]])


# ---------------------------------------------------------------------------- eq. (5)
def test_eq5_inputs() -> None:
    # v1 = |chi| = sqrt(1 + 1) = 1.41421
    # feedforward = (-chi2 chi1' + chi1 chi2') / |chi|^2 = (-1*0 + 1*2) / 2 = 1
    # heading error = x3 - angle(chi) = 0 - pi/4
    # v2 = 1 - kp * (-pi/4) = 1 + 2 pi/4 = 2.570796
    v1, v2 = flat_inputs(np.array([0.0]), v(1, 1), v(0, 2), 2.0)
    assert v1[0] == pytest.approx(math.sqrt(2))
    assert v2[0] == pytest.approx(1 + math.pi / 2)


def test_eq5_feedforward_is_the_turn_rate_of_chi() -> None:
    # chi = (3, 4) turning at 1 rad/s has chi' = 1 * (-4, 3); heading atan2(4, 3):
    # v1 = 5, v2 = (-4*-4 + 3*3) / 25 - 0 = 25/25 = 1 rad/s.
    v1, v2 = flat_inputs(np.array([math.atan2(4, 3)]), v(3, 4), v(-4, 3), 2.0)
    assert (v1[0], v2[0]) == pytest.approx((5.0, 1.0))


def test_eq5_chi_growing_along_the_heading_needs_no_turn() -> None:
    v1, v2 = flat_inputs(np.array([0.0]), v(2, 0), v(5, 0), 2.0)
    assert (v1[0], v2[0]) == (2.0, 0.0)


def test_eq5_arctan2_convention_angle_of_chi() -> None:
    # chi points along +x2 (angle pi/2), heading 0: the vehicle must turn left (v2 > 0):
    # v2 = 0 - 2 * (0 - pi/2) = pi.
    _, v2 = flat_inputs(np.array([0.0]), v(0, 1), v(0, 0), 2.0)
    assert v2[0] == pytest.approx(math.pi)


def test_eq5_heading_error_wraps_across_pi() -> None:
    # heading pi - 0.1, chi at angle -pi + 0.1: the error x3 - angle(chi) = 2 pi - 0.2
    # wraps to -0.2, so v2 = -2 * (-0.2) = +0.4 (turn left through pi),
    # not -2 (2 pi - 0.2).
    chi = v(math.cos(-math.pi + 0.1), math.sin(-math.pi + 0.1))
    _, v2 = flat_inputs(np.array([math.pi - 0.1]), chi, v(0, 0), 2.0)
    assert v2[0] == pytest.approx(0.4)


def test_eq5_unwrapped_heading_is_fine() -> None:
    # The physics never wraps x3: 0.3 + 4 pi is heading 0.3, aligned with chi.
    chi = v(math.cos(0.3), math.sin(0.3))
    _, v2 = flat_inputs(np.array([0.3 + 4 * math.pi]), chi, v(0, 0), 2.0)
    assert v2[0] == pytest.approx(0.0, abs=1e-12)


def test_eq5_at_chi_zero_holds_heading_without_nan() -> None:
    v1, v2 = flat_inputs(np.array([1.0]), v(0, 0), v(50, -80), 2.0)
    assert (v1[0], v2[0]) == (0.0, 0.0)


def test_eq5_at_rest_holds_the_heading_and_moves_along_it() -> None:
    # |chi| = 0.0005 < CHI_REST: the angle of chi means nothing. The heading is held
    # (v2 = 0, whatever chi') and v1 is chi's component along it: heading 0, chi
    # (0.0003, 0.0004): v1 = 0.0003; heading pi: v1 = -0.0003.
    assert 0.0005 < CHI_REST
    chi = v(0.0003, 0.0004)
    v1, v2 = flat_inputs(np.array([0.0]), chi, v(0, 1), 2.0)
    assert v1[0] == pytest.approx(0.0003) and v2[0] == 0.0
    v1, v2 = flat_inputs(np.array([math.pi]), chi, v(50, -80), 2.0)
    assert v1[0] == pytest.approx(-0.0003) and v2[0] == 0.0


def test_eq5_backward_is_eq5_for_minus_chi() -> None:
    # Travelling backward with chi = (-1, 0.1) and heading 0: v1 = -|chi|; the heading
    # error is measured to the angle of -chi = (1, -0.1), atan2(-0.1, 1) = -0.0997,
    # so v2 = ff - 2 (0 + 0.0997); chi' = (0, 1): ff = (-0.1 * 0 + -1 * 1) / 1.01.
    chi, rate = v(-1.0, 0.1), v(0.0, 1.0)
    back = np.array([TRAVEL_BACKWARD], dtype=np.int8)
    v1, v2 = flat_inputs(np.array([0.0]), chi, rate, 2.0, travel=back)
    assert v1[0] == pytest.approx(-math.hypot(1.0, 0.1))
    assert v2[0] == pytest.approx(-1.0 / 1.01 - 2.0 * math.atan2(0.1, 1.0))
    # the same state travelling forward turns round (heading error 3.04 rad)
    fwd = np.array([TRAVEL_FORWARD], dtype=np.int8)
    v1, v2 = flat_inputs(np.array([0.0]), chi, rate, 2.0, travel=fwd)
    assert v1[0] == pytest.approx(math.hypot(1.0, 0.1))
    assert v2[0] == pytest.approx(-1.0 / 1.01 - 2.0 * (0.0 - math.atan2(0.1, -1.0)))


@pytest.mark.parametrize(
    ("chi", "chi_next", "travel", "want"),
    [
        # forward, chi reverses through zero within a period: backward
        ((0.05, 0.0), (-0.02, 0.001), TRAVEL_FORWARD, TRAVEL_BACKWARD),
        # forward, chi slows along the heading: still forward
        ((0.05, 0.0), (0.02, 0.0), TRAVEL_FORWARD, TRAVEL_FORWARD),
        # forward, chi turns past a quarter turn without vanishing: still forward
        ((0.0, 1.0), (-0.1, 1.0), TRAVEL_FORWARD, TRAVEL_FORWARD),
        # at rest, chi comes back behind: backward (no turn round)
        ((0.0005, 0.0), (-0.5, 0.2), TRAVEL_FORWARD, TRAVEL_BACKWARD),
        # ... and ahead: forward
        ((0.0005, 0.0), (0.5, 0.2), TRAVEL_BACKWARD, TRAVEL_FORWARD),
        # never travelled: sets off forward whatever the side of chi
        ((0.0, 0.0), (-0.5, 0.0), TRAVEL_NONE, TRAVEL_FORWARD),
        # backward, chi points ahead: forward again
        ((-0.5, 0.0), (-0.5, 0.6), TRAVEL_BACKWARD, TRAVEL_BACKWARD),
        ((0.0, 0.5), (0.1, 0.5), TRAVEL_BACKWARD, TRAVEL_FORWARD),
        # chi_next at rest: unchanged
        ((0.05, 0.0), (-0.0005, 0.0), TRAVEL_FORWARD, TRAVEL_FORWARD),
        ((0.0, 0.0), (0.0, 0.0), TRAVEL_NONE, TRAVEL_NONE),
    ],
)
def test_the_direction_of_travel_is_chosen_when_chi_comes_back(
    chi: tuple, chi_next: tuple, travel: int, want: int
) -> None:
    # heading 0 (along +x1) throughout
    got = travel_direction(
        v(*chi), v(*chi_next), np.zeros(1), np.array([travel], dtype=np.int8)
    )
    assert got.dtype == np.int8 and got.tolist() == [want]


def test_a_vehicle_travels_backward_only_where_it_parks() -> None:
    # chi reverses behind a vehicle heading along +x1: backward where its target rests
    # within PARK_RADIUS, forward (the report's eq. (5)) where it does not
    pos = np.zeros((3, 2))
    aim = np.array([[-0.1, 0.0], [-0.1, 0.0], [-2.0, 0.0]])
    v_ref = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.0]])
    parks = parking(pos, aim, v_ref)
    assert parks.tolist() == [True, False, False]
    chi, chi_next = np.tile([0.05, 0.0], (3, 1)), np.tile([-0.02, 0.0], (3, 1))
    forward = np.full(3, TRAVEL_FORWARD, dtype=np.int8)
    got = travel_direction(chi, chi_next, np.zeros(3), forward, parks)
    assert got.tolist() == [TRAVEL_BACKWARD, TRAVEL_FORWARD, TRAVEL_FORWARD]


# ---------------------------------------------------------------------------- limits
def test_advance_without_limits_is_explicit_euler() -> None:
    # chi + dt chi' = (1 + 0.01*10, 2 + 0.01*(-20)) = (1.1, 1.8)
    nxt, applied = advance_extension(v(1, 2), v(10, -20), 0.01, INF, INF)
    np.testing.assert_allclose(nxt, [[1.1, 1.8]])
    np.testing.assert_allclose(applied, [[10.0, -20.0]])


def test_advance_acceleration_limit() -> None:
    # step = dt chi' = (3, 4), norm 5 > accel_max dt = 0.1: scaled by 0.02 to
    # (0.06, 0.08); the applied rate is (6, 8), of norm exactly accel_max = 10, in the
    # same direction.
    nxt, applied = advance_extension(v(0, 0), v(300, 400), 0.01, INF, np.array([10.0]))
    np.testing.assert_allclose(nxt, [[0.06, 0.08]])
    np.testing.assert_allclose(applied, [[6.0, 8.0]])


def test_advance_speed_limit_clamps_chi() -> None:
    # (1.5, 0) + 0.01 * (100, 0) = (2.5, 0), clamped to |chi| = v1_max = 2: (2, 0); the
    # applied rate is (2 - 1.5) / 0.01 = 50.
    nxt, applied = advance_extension(v(1.5, 0), v(100, 0), 0.01, np.array([2.0]), INF)
    np.testing.assert_allclose(nxt, [[2.0, 0.0]])
    np.testing.assert_allclose(applied, [[50.0, 0.0]])


def test_advance_anti_windup_no_stored_excess() -> None:
    # 100 steps pushing at 1000 m/s^2 against v1_max = 2 leave chi at (2, 0), not at
    # 2 + 100 * 0.01 * 1000; one step braking at -100 m/s^2 then gives 2 - 1 = 1
    # at once.
    chi, vmax = v(0, 0), np.array([2.0])
    for _ in range(100):
        chi, _ = advance_extension(chi, v(1000, 0), 0.01, vmax, INF)
    np.testing.assert_allclose(chi, [[2.0, 0.0]])
    chi, _ = advance_extension(chi, v(-100, 0), 0.01, vmax, INF)
    np.testing.assert_allclose(chi, [[1.0, 0.0]])


def test_advance_per_vehicle_limits() -> None:
    chi = np.zeros((2, 2))
    rate = np.array([[100.0, 0.0], [100.0, 0.0]])
    nxt, _ = advance_extension(
        chi, rate, 0.1, np.array([np.inf, 4.0]), np.array([np.inf, 20.0])
    )
    # vehicle 0: 0.1 * 100 = 10;
    # vehicle 1: the step 10 > 20 * 0.1 = 2, so 2 (< v1_max 4)
    np.testing.assert_allclose(nxt, [[10.0, 0.0], [2.0, 0.0]])


def test_limited_inputs_respect_the_limits() -> None:
    # v1 = |chi| after the clamp, so it never exceeds v1_max.
    rng = np.random.default_rng(1)
    chi = rng.normal(size=(50, 2))
    rate = rng.normal(scale=1e3, size=(50, 2))
    nxt, applied = advance_extension(
        chi * 0.1, rate, 0.01, np.full(50, 1.0), np.full(50, 5.0)
    )
    v1, _ = flat_inputs(np.zeros(50), nxt, applied, 2.0)
    assert np.all(v1 <= 1.0 + 1e-12)
    assert np.all(np.hypot(*applied.T) <= 5.0 + 1e-9)


# ---------------------------------------------------------------------------- stability
def test_spectral_radius_report_gains() -> None:
    # M = [[1, dt], [dt k_pos, 1 + dt k_vel]]: det(lambda - M) = (mu + 10 dt)^2 with
    # mu = lambda - 1 for k_pos = -100, k_vel = -20, a double eigenvalue 1 - 10 dt:
    # dt = 0.01 -> 0.9; dt = 0.1 -> 0 (dead-beat); dt = 0.2 -> |-1| = 1: the bound.
    assert discrete_spectral_radius(-100, -20, 0.01) == pytest.approx(0.9, abs=1e-6)
    assert discrete_spectral_radius(-100, -20, 0.1) == pytest.approx(0.0, abs=1e-6)
    assert discrete_spectral_radius(-100, -20, 0.19) == pytest.approx(0.9, abs=1e-6)
    assert discrete_spectral_radius(-100, -20, 0.199) < 1.0
    assert discrete_spectral_radius(-100, -20, 0.201) > 1.0


def test_spectral_radius_distinct_eigenvalues() -> None:
    # k_pos = -4, k_vel = -5, dt = 0.1: M = [[1, 0.1], [-0.4, 0.5]], trace 1.5,
    # det 0.5 + 0.04 = 0.54, lambda = 0.75 +- sqrt(0.5625 - 0.54) = 0.9 or 0.6.
    assert discrete_spectral_radius(-4, -5, 0.1) == pytest.approx(0.9)
