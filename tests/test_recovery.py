"""Recovery strategies of section 4: weights alpha, avoidance vectors, modes.

Equation-level tests use hand-computed values (arithmetic in the comments); the
scenario-level tests check that the shift really acts in a run, for every formation law.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sandbox import SandboxWarning, load_scenario, simulate
from sandbox.behaviour.recovery import WEIGHTS, avoidance_shift
from sandbox.model.laws import LAWS, BackwardDifference
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins import register_strategy
from sandbox.run.metrics import compute_metrics
from sandbox.run.record import MODE_AVOID
from sandbox.scenario import ObstacleSpec

R, r = 1.5, 0.75  # R = 3d and r = R/2 for d = 0.5 m
NO_OBSTACLES = ObstacleField(())


# ------------------------------------------------------------------------- the weights
@pytest.mark.parametrize(
    ("strategy", "dist", "alpha"),
    [
        ("none", 0.5, 0.0),
        ("discontinuous", 0.5, 1.0),
        ("discontinuous", 1.49, 1.0),
        ("discontinuous", 1.5, 0.0),  # the switch: alpha = 1 only strictly inside R
        ("discontinuous", 2.0, 0.0),
        # eq. (27): 1 below r, 1 - (dist - r)/(R - r) between, 0 above R
        ("continuous", 0.5, 1.0),
        ("continuous", 0.75, 1.0),
        ("continuous", 1.125, 0.5),  # 1 - 0.375/0.75
        ("continuous", 1.3, 1.0 - 0.55 / 0.75),  # = 0.2667
        ("continuous", 1.5, 0.0),
        ("continuous", 2.0, 0.0),
        # tanh transition, steepness s = 2, centre c = 1.125, half-width w = 0.375:
        # alpha = (tanh(s (c - dist)/w) + tanh(s)) / (2 tanh(s))
        ("smooth", 0.5, 1.0),
        ("smooth", 0.75, 1.0),  # (tanh 2 + tanh 2)/(2 tanh 2)
        ("smooth", 1.125, 0.5),  # (0 + tanh 2)/(2 tanh 2)
        (
            "smooth",
            0.9375,
            (math.tanh(1) + math.tanh(2)) / (2 * math.tanh(2)),
        ),  # 0.8950
        ("smooth", 1.5, 0.0),
        ("smooth", 2.0, 0.0),
    ],
)
def test_alpha_hand_values(strategy, dist, alpha):
    got = WEIGHTS[strategy](np.array([dist]), R, r, 2.0)
    assert got[0] == pytest.approx(alpha, abs=1e-12)


@pytest.mark.parametrize("strategy", ["continuous", "smooth"])
def test_alpha_is_continuous_monotone_and_symmetric(strategy):
    d = np.linspace(0.0, 3.0, 3001)
    a = WEIGHTS[strategy](d, R, r, 2.0)
    assert np.all(np.diff(a) <= 1e-15)  # never increases with the distance
    assert np.max(np.abs(np.diff(a))) < 0.01  # no jump on a 1 mm grid
    # Point symmetry about the middle of [r, R]: alpha(c + x) = 1 - alpha(c - x).
    x = np.linspace(0.0, 0.375, 50)
    w = WEIGHTS[strategy]
    np.testing.assert_allclose(
        w(1.125 + x, R, r, 2.0), 1 - w(1.125 - x, R, r, 2.0), atol=1e-12
    )


def test_smooth_is_flatter_than_the_ramp_at_both_ends():
    # The point of the conclusion's proposal: the mode changes more gently at r and R.
    eps = 1e-4
    for edge, sign in ((r, +1), (R, -1)):
        ramp = abs(
            WEIGHTS["continuous"](np.array([edge + sign * eps]), R, r, 2.0)[0]
            - WEIGHTS["continuous"](np.array([edge]), R, r, 2.0)[0]
        )
        tanh = abs(
            WEIGHTS["smooth"](np.array([edge + sign * eps]), R, r, 2.0)[0]
            - WEIGHTS["smooth"](np.array([edge]), R, r, 2.0)[0]
        )
        # slope ratio s (1 - tanh(s)^2) / tanh(s) = 0.147 for s = 2
        assert tanh / ramp == pytest.approx(
            2 * (1 - math.tanh(2) ** 2) / math.tanh(2), rel=1e-2
        )


def test_registering_a_strategy_twice_is_refused():
    with pytest.raises(ValueError, match="already registered"):
        register_strategy("continuous")(lambda ctx: (ctx.pos * 0, ctx.failed))


# ------------------------------------------------------------- the avoidance vector sum
#   A = (0, 0), B = (1, 0), C = (0, -1.2); R = 1.5.
#   A-B: 1.0 apart; A-C: 1.2 apart; B-C: sqrt(1 + 1.44) = 1.562 > R (ignored).
#   eqs. (23)-(25): vect = (x - x_i) / dist^2
#   on A: from B (-1, 0)/1 = (-1, 0); from C (0, 1.2)/1.44 = (0, 0.8333)
#   on B: from A (1, 0)/1 = (1, 0);   on C: from A (0, -1.2)/1.44 = (0, -0.8333)
THREE = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, -1.2]])
ALL = np.ones(3, dtype=bool)


def test_discontinuous_shift_is_beta_times_the_sum_of_vectors():
    shift, active = avoidance_shift(
        THREE, ALL, "discontinuous", 2.0, R, None, 2.0, NO_OBSTACLES
    )
    # eq. (22) with beta = 2
    expected = 2.0 * np.array([[-1.0, 1.2 / 1.44], [1.0, 0.0], [0.0, -1.2 / 1.44]])
    np.testing.assert_allclose(shift, expected, atol=1e-12)
    assert active.tolist() == [True, True, True]


def test_continuous_shift_weights_each_vector_by_its_alpha():
    shift, _ = avoidance_shift(THREE, ALL, "continuous", 2.0, R, r, 2.0, NO_OBSTACLES)
    # alpha(A-B, 1.0) = 1 - 0.25/0.75 = 2/3 ; alpha(A-C, 1.2) = 1 - 0.45/0.75 = 0.4
    a_ab, a_ac = 2.0 / 3.0, 0.4
    expected = 2.0 * np.array(
        [[-a_ab, a_ac * 1.2 / 1.44], [a_ab, 0.0], [0.0, -a_ac * 1.2 / 1.44]]
    )  # eq. (26)
    np.testing.assert_allclose(shift, expected, atol=1e-12)


def test_non_avoiders_get_no_shift_but_still_repel():
    # The leader (A) does not avoid (leader_avoids: false): its shift is zero, B and C
    # still steer away from it.
    avoiders = np.array([False, True, True])
    shift, active = avoidance_shift(
        THREE, avoiders, "discontinuous", 1.0, R, None, 2.0, NO_OBSTACLES
    )
    np.testing.assert_allclose(shift[0], [0.0, 0.0])
    np.testing.assert_allclose(shift[1], [1.0, 0.0])
    np.testing.assert_allclose(shift[2], [0.0, -1.2 / 1.44])
    assert active.tolist() == [False, True, True]


def test_no_shift_outside_the_safe_zone_and_with_strategy_none():
    far = np.array([[0.0, 0.0], [1.6, 0.0]])
    for strategy in ("discontinuous", "continuous", "smooth"):
        shift, active = avoidance_shift(
            far, np.ones(2, bool), strategy, 1.0, R, r, 2.0, NO_OBSTACLES
        )
        assert not shift.any() and not active.any()
    shift, active = avoidance_shift(THREE, ALL, "none", 1.0, R, r, 2.0, NO_OBSTACLES)
    assert not shift.any() and not active.any()


def test_static_obstacle_repels_from_its_nearest_surface_point():
    # A circle of radius 0.2 centred at (1.2, 0): the vehicle at the origin is 1.0 from
    # its surface point (1.0, 0): vect = ((0, 0) - (1, 0)) / 1.0^2 = (-1, 0).
    # A wall from (-2, 1.25) to (2, 1.25), 0.5 thick: surface at y = 1.0, point (0, 1):
    # vect = (0, -1) / 1.0^2. Beta = 0.5 -> shift = 0.5 * (-1, -1).
    field = ObstacleField(
        (
            ObstacleSpec("circle", "post", center=(1.2, 0.0), radius=0.2),
            ObstacleSpec(
                "wall", "wall", start=(-2.0, 1.25), end=(2.0, 1.25), thickness=0.5
            ),
        )
    )
    shift, active = avoidance_shift(
        np.zeros((1, 2)), np.ones(1, bool), "discontinuous", 0.5, R, None, 2.0, field
    )
    np.testing.assert_allclose(shift, [[-0.5, -0.5]], atol=1e-12)
    assert active.tolist() == [True]


def test_obstacle_push_points_outward_even_from_inside():
    # A centre that ends up inside an obstacle (it can only start there) is pushed out
    # of it, never further in.
    field = ObstacleField(
        (
            ObstacleSpec("box", "box", center=(0.0, 0.0), size=(4.0, 2.0)),
            ObstacleSpec("circle", "post", center=(10.0, 0.0), radius=1.0),
        )
    )
    pos = np.array([[0.0, 0.7], [10.0, -0.5]])
    shift, _ = avoidance_shift(
        pos, np.ones(2, bool), "discontinuous", 1.0, R, None, 2.0, field
    )
    assert shift[0, 1] > 0  # nearest face of the box is y = +1: out is +y
    assert shift[1, 1] < 0  # nearest surface point of the circle is below


# --------------------------------------------------------------- target derivatives
def test_backward_differences_are_linear_so_estimate_reads_the_shifted_target():
    # `target_derivatives: estimate` adds the backward-Euler derivatives of the shift to
    # the law's derivatives. Because eqs. (8)-(9) are linear, for a law that estimates
    # its slot's motion (own_estimate, eqs. (18)-(19)) this equals estimating the
    # derivatives of the shifted target slot + shift itself, the conclusion's proposal.
    rng = np.random.default_rng(1)
    slot, shift = rng.normal(size=(20, 3, 2)), rng.normal(size=(20, 3, 2))
    a, b, c = (
        BackwardDifference(0.01),
        BackwardDifference(0.01),
        BackwardDifference(0.01),
    )
    for k in range(20):
        v_sum, acc_sum = a.update(slot[k] + shift[k])
        v1, a1 = b.update(slot[k])
        v2, a2 = c.update(shift[k])
        np.testing.assert_allclose(v_sum, v1 + v2, atol=1e-9)
        np.testing.assert_allclose(acc_sum, a1 + a2, atol=1e-6)


# ----------------------------------------------------------------- in a simulation
LAWS_THAT_REPEL = {"potential", "flocking"}  # eqs. of [2] and [3]: repulsion built in


def crossing(law: str, strategy: str, **recovery) -> dict:
    """Two followers that must swap sides behind a leader on a straight line."""
    doc = {
        "name": f"crossing-{law}",
        "duration": 6.0,
        "dt": 0.01,
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "formation": {"law": law},
        "vehicle": {"diameter": 0.5, "v1_max": 2.0, "max_accel": 5.0, "v2_max": 4.0},
        "recovery": {"strategy": strategy, "R": "3d", **recovery},
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [-2.0, -1.0, 0], "offset": [-2.0, 1.0]},
            {"name": "green", "pose": [-2.2, 1.0, 0], "offset": [-2.0, -1.0]},
        ],
    }
    return doc


@pytest.mark.slow
@pytest.mark.parametrize("law", sorted(LAWS))
def test_recovery_acts_with_every_formation_law(law):
    # The followers cross each other's path: without recovery the report's laws let them
    # collide, while the laws of [2] and [3] carry their own repulsion and keep them
    # apart; with the discontinuous strategy (beta = 2.5) the targets are shifted, the
    # mode is `avoid` while they pass, and they get through without touching.
    off = compute_metrics(simulate(load_scenario(crossing(law, "none"))))
    run = simulate(load_scenario(crossing(law, "discontinuous", beta=2.5)))
    on = compute_metrics(run)
    if law in LAWS_THAT_REPEL:
        assert off["collisions"]["total"] == 0
    else:
        assert off["collisions"]["vehicle_vehicle"] >= 1
    assert on["collisions"]["total"] == 0
    avoid = run.mode[:, 1:] == MODE_AVOID
    assert avoid.any()
    # Where a follower avoids, its target is its slot shifted; elsewhere it is the slot.
    shifted = np.linalg.norm(run.target[:, 1:] - run.slot[:, 1:], axis=-1) > 1e-12
    assert np.array_equal(shifted, avoid)
    assert on["min_distance"] > 0.5


def test_leader_avoids_only_when_asked():
    for leader_avoids in (False, True):
        doc = crossing(
            "rotating", "discontinuous", beta=1.0, leader_avoids=leader_avoids
        )
        # red starts just beside the leader, within its safe zone
        doc["vehicles"][1]["pose"] = [0.0, -1.0, 0.0]
        run = simulate(load_scenario(doc))
        assert bool((run.mode[:, 0] == MODE_AVOID).any()) is leader_avoids


def test_estimated_target_derivatives_change_nothing_without_avoidance():
    # With nobody in a safe zone the shift is zero, so are its estimated derivatives.
    doc = crossing("rotating", "continuous", R=0.3, r=0.2)  # zones smaller than d
    with pytest.warns(SandboxWarning, match="smaller than the vehicle diameter"):
        hold = simulate(load_scenario(doc))
    doc["recovery"]["target_derivatives"] = "estimate"
    with pytest.warns(SandboxWarning, match="smaller than the vehicle diameter"):
        est = simulate(load_scenario(doc))
    assert not (hold.mode == MODE_AVOID).any()
    np.testing.assert_array_equal(hold.pose, est.pose)


def test_estimated_target_derivatives_act_when_avoiding():
    doc = crossing("rotating", "continuous", beta=2.5)
    hold = simulate(load_scenario(doc))
    doc["recovery"]["target_derivatives"] = "estimate"
    est = simulate(load_scenario(doc))
    assert (est.mode == MODE_AVOID).any()
    assert np.max(np.abs(hold.pose - est.pose)) > 1e-3


def lone_vehicle_past_a_post(beta: float) -> dict:
    """A vehicle without limits on a line, a post beside it, avoiding with estimate."""
    return {
        "duration": 10.0,
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "vehicles": [{"name": "car", "pose": [0, 0, 0], "leader": True}],
        "vehicle": {"diameter": 0.5},
        "recovery": {
            "strategy": "continuous",
            "beta": beta,
            "R": "3d",
            "leader_avoids": True,
            "target_derivatives": "estimate",
        },
        "obstacles": [{"type": "circle", "center": [5, 0.8], "radius": 0.2}],
    }


@pytest.mark.slow
def test_estimated_shift_derivatives_destabilize_a_steep_shift():
    # The shift depends on the vehicle's own position: its estimated acceleration feeds
    # the vehicle's acceleration back with the gain J = d shift / d x. A gentle push
    # (beta = 0.3) passes the post smoothly; a steep one (beta = 2.5, |J| > 1 within
    # the safe zone) makes v2 chatter at the control rate (over 10x the turn-rate
    # effort), and beta = 5 blows up: without limits the extension states reach
    # thousands of m/s.
    gentle = simulate(load_scenario(lone_vehicle_past_a_post(0.3)))
    steep = simulate(load_scenario(lone_vehicle_past_a_post(2.5)))
    steeper = simulate(load_scenario(lone_vehicle_past_a_post(5.0)))
    assert np.abs(gentle.chi).max() < 2.0
    effort = [
        compute_metrics(r)["vehicles"]["car"]["effort_v2"] for r in (gentle, steep)
    ]
    assert effort[1] > 10 * effort[0]
    assert np.abs(steeper.chi).max() > 50.0
    with_hold = lone_vehicle_past_a_post(2.5)
    with_hold["recovery"]["target_derivatives"] = "hold"
    assert np.abs(simulate(load_scenario(with_hold)).chi).max() < 5.0
