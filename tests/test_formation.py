"""Formation laws of section 3, eqs. (7)-(20): slots and derivatives by hand."""

import math

import numpy as np
import pytest

from sandbox.model.laws import (
    LAWS,
    BackwardDifference,
    FormationLaw,
    LawInputs,
    register_law,
    rotate_offsets,
)

#: Leader, red (leader frame: behind-left), green (behind-right), as in the scenarios.
DELTA = np.array([[0.0, 0.0], [-1.0, 1.0], [-1.0, -1.0]])


# ---------------------------------------------------------------------------- (8)-(9)
def test_backward_difference_first_steps_and_after() -> None:
    # h = 0.1, x = (0,0), (1,0), (3,1), (6,3):
    #   step 0: no history              -> x' = 0, x'' = 0
    #   step 1: x' = (1-0, 0-0)/0.1   = (10, 0), x'' still 0 (no earlier x')
    #   step 2: x' = (3-1, 1-0)/0.1   = (20, 10), x'' = (20-10, 10-0)/0.1 = (100, 100)
    #   step 3: x' = (6-3, 3-1)/0.1   = (30, 20), x'' = (30-20, 20-10)/0.1 = (100, 100)
    est = BackwardDifference(0.1)
    out = [
        est.update(np.array(x, dtype=float)) for x in ((0, 0), (1, 0), (3, 1), (6, 3))
    ]
    expected = [
        ((0, 0), (0, 0)),
        ((10, 0), (0, 0)),
        ((20, 10), (100, 100)),
        ((30, 20), (100, 100)),
    ]
    for (vel, acc), (ev, ea) in zip(out, expected, strict=True):
        np.testing.assert_allclose(vel, ev, atol=1e-9)
        np.testing.assert_allclose(acc, ea, atol=1e-7)


def test_backward_difference_reset_and_copy() -> None:
    est = BackwardDifference(0.5)
    x = np.array([1.0, 2.0])
    est.update(x)
    x += 10.0  # the estimator kept its own copy
    vel, _ = est.update(np.array([1.5, 2.0]))
    np.testing.assert_allclose(vel, [1.0, 0.0])  # (1.5 - 1) / 0.5
    est.reset()
    vel, acc = est.update(np.array([100.0, 100.0]))
    np.testing.assert_array_equal(vel, [0.0, 0.0])
    np.testing.assert_array_equal(acc, [0.0, 0.0])


def test_backward_difference_exact_on_a_parabola() -> None:
    # x = t^2 sampled at h: x'(t) estimate = (t^2 - (t-h)^2)/h = 2t - h (lags h/2),
    # x'' estimate = ((2t - h) - (2(t-h) - h))/h = 2 exactly.
    h = 0.01
    est = BackwardDifference(h)
    for k in range(5):
        vel, acc = est.update(np.array([(k * h) ** 2]))
    t = 4 * h
    assert vel[0] == pytest.approx(2 * t - h)
    assert acc[0] == pytest.approx(2.0)


# ---------------------------------------------------------------------------- (11)
def test_rotate_offsets_eq11() -> None:
    # delta = (1, 2), angle 30 deg:
    #   Delta1 = 1 cos30 - 2 sin30 = 0.866025 - 1     = -0.133975
    #   Delta2 = 2 cos30 + 1 sin30 = 1.732051 + 0.5   =  2.232051
    out = rotate_offsets(np.array([[1.0, 2.0]]), math.pi / 6)
    np.testing.assert_allclose(out, [[-0.1339746, 2.2320508]], atol=1e-7)


def test_rotate_offsets_quarter_turns_and_arrays() -> None:
    # Leader heading +x2 (pi/2): "behind-left" (-1, 1) is (-1, -1) in the world frame
    # and "behind-right" (-1, -1) is (1, -1).
    out = rotate_offsets(DELTA, math.pi / 2)
    np.testing.assert_allclose(out, [[0, 0], [-1, -1], [1, -1]], atol=1e-12)
    # one angle per row
    out = rotate_offsets(np.array([[1.0, 0.0], [1.0, 0.0]]), np.array([0.0, math.pi]))
    np.testing.assert_allclose(out, [[1, 0], [-1, 0]], atol=1e-12)


# ---------------------------------------------------------------------------- the laws
def inputs(pos=(5.0, 0.0), theta=math.pi / 2, ref=None) -> LawInputs:
    return LawInputs(np.array(pos, dtype=float), theta, ref)


CIRCLE_REF = (np.array([5.0, 0.0]), np.array([0.0, 1.0]), np.array([-0.2, 0.0]))


def test_registry_has_the_five_laws() -> None:
    report = {"fixed", "rotating", "virtual", "leader_ref", "own_estimate"}
    assert set(LAWS) == report | {"potential", "flocking"}  # and references [2], [3]
    assert not LAWS["virtual"].needs_leader
    assert all(
        LAWS[k].needs_leader
        for k in ("fixed", "rotating", "leader_ref", "own_estimate")
    )
    assert LAWS["virtual"].needs_reference and LAWS["leader_ref"].needs_reference


def test_registering_a_duplicate_law_fails() -> None:
    with pytest.raises(ValueError, match="already registered"):
        register_law("rotating")(FormationLaw)


def test_fixed_eq7_world_offsets_and_estimated_leader_motion() -> None:
    law = LAWS["fixed"](np.array([[0.0, 0.0], [-1.0, -1.0], [1.0, -1.0]]), 0.1)
    slot, vel, acc = law.targets(inputs((5.0, 0.0), theta=0.7))
    # slot = leader + delta, whatever the heading (0.7 rad here)
    np.testing.assert_allclose(slot, [[5, 0], [4, -1], [6, -1]])
    np.testing.assert_array_equal(vel, np.zeros((3, 2)))
    law.targets(inputs((5.0, 0.1)))
    slot, vel, acc = law.targets(inputs((5.01, 0.3)))
    # x' = (5.01 - 5, 0.3 - 0.1)/0.1 = (0.1, 2); previous x' = (0, 1);
    # x'' = (0.1 - 0, 2 - 1)/0.1 = (1, 10); the same for every vehicle
    np.testing.assert_allclose(vel, [[0.1, 2.0]] * 3)
    np.testing.assert_allclose(acc, [[1.0, 10.0]] * 3)
    np.testing.assert_allclose(slot[2], [6.01, -0.7])


def test_rotating_eq10_eq11_leader_frame_offsets() -> None:
    law = LAWS["rotating"](DELTA, 0.1)
    slot, vel, _ = law.targets(inputs((5.0, 0.0), theta=math.pi / 2))
    # Delta = R(pi/2) delta: red (-1, -1), green (1, -1) -> slots (4, -1), (6, -1)
    np.testing.assert_allclose(slot, [[5, 0], [4, -1], [6, -1]], atol=1e-12)
    slot, vel, _ = law.targets(inputs((5.0, 0.1), theta=math.pi))
    # heading pi: Delta = -delta: red (1, -1), green (1, 1); x' = (0, 0.1)/0.1 = (0, 1)
    np.testing.assert_allclose(slot, [[5, 0.1], [6, -0.9], [6, 1.1]], atol=1e-12)
    np.testing.assert_allclose(vel, [[0.0, 1.0]] * 3)


@pytest.mark.parametrize("rotate", [False, True])
def test_virtual_eq13_to_eq15(rotate: bool) -> None:
    law = LAWS["virtual"](DELTA, 0.1, rotate)
    # The real leader's state is ignored: give it nonsense.
    slot, vel, acc = law.targets(LawInputs(np.array([99.0, 99.0]), 3.0, CIRCLE_REF))
    # rotate: theta = atan2(x2ref', x1ref') = atan2(1, 0) = pi/2 (eq. (15)), Delta as in
    # the rotating test; else Delta = delta.
    delta = [[0, 0], [-1, -1], [1, -1]] if rotate else DELTA
    np.testing.assert_allclose(slot, np.array([5.0, 0.0]) + delta, atol=1e-12)
    np.testing.assert_allclose(vel, [[0.0, 1.0]] * 3)
    np.testing.assert_allclose(acc, [[-0.2, 0.0]] * 3)


def test_leader_ref_eq16_leader_position_reference_derivatives() -> None:
    law = LAWS["leader_ref"](DELTA, 0.1, True)
    # The leader is off the reference (4.9, 0.2) and heads 0; the offsets still turn
    # with the reference's tangent (pi/2), and the derivatives are the reference's.
    slot, vel, acc = law.targets(inputs((4.9, 0.2), theta=0.0, ref=CIRCLE_REF))
    np.testing.assert_allclose(slot, [[4.9, 0.2], [3.9, -0.8], [5.9, -0.8]], atol=1e-12)
    np.testing.assert_allclose(vel, [[0.0, 1.0]] * 3)
    np.testing.assert_allclose(acc, [[-0.2, 0.0]] * 3)


def test_own_estimate_eq17_to_eq20_each_slot_differentiated() -> None:
    law = LAWS["own_estimate"](np.array([[0.0, 0.0], [1.0, 0.0]]), 0.1)
    # step 0: leader (0, 0) heading 0: slots (0, 0), (1, 0); no history: zeros
    slot, vel, acc = law.targets(inputs((0.0, 0.0), theta=0.0))
    np.testing.assert_allclose(slot, [[0, 0], [1, 0]])
    np.testing.assert_array_equal(vel, np.zeros((2, 2)))
    # step 1: leader (0.1, 0) heading pi/2: follower slot (0.1, 1);
    #   x'_leader = (1, 0); x'_follower = (0.1 - 1, 1 - 0)/0.1 = (-9, 10); x'' = 0
    slot, vel, acc = law.targets(inputs((0.1, 0.0), theta=math.pi / 2))
    np.testing.assert_allclose(slot[1], [0.1, 1.0], atol=1e-12)
    np.testing.assert_allclose(vel, [[1, 0], [-9, 10]], atol=1e-9)
    np.testing.assert_array_equal(acc, np.zeros((2, 2)))
    # step 2: leader (0.2, 0) heading pi: follower slot (-0.8, 0);
    #   x'_follower = (-0.8 - 0.1, 0 - 1)/0.1 = (-9, -10);
    #   x''_follower = (-9 - -9, -10 - 10)/0.1 = (0, -200)
    slot, vel, acc = law.targets(inputs((0.2, 0.0), theta=math.pi))
    np.testing.assert_allclose(vel, [[1, 0], [-9, -10]], atol=1e-9)
    np.testing.assert_allclose(acc, [[0, 0], [0, -200]], atol=1e-6)
