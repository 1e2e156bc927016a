"""The laws of the report's references [2] and [3] (``potential``, ``flocking``).

Equation-level: the potential's attraction, repulsion and saturation on hand cases;
flocking's sigma-norm, bump, action function, alignment and the virtual leader's term;
the moving target's integration. Metrics: ``formation_goal`` measures the goals, the
reference plus the offsets. Scenario-level: a form-up of section 4 with each law, the
potential's trap behind a stopped vehicle, and a world in a batch is its run alone.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import SCENARIOS, run_scenario
from test_one_loop import assert_batch_is_alone

from sandbox import load_scenario
from sandbox.model.flocking import (
    PARAMS as FLOCKING,
)
from sandbox.model.flocking import (
    action,
    bump,
    flocking_acceleration,
    sigma_length,
    sigma_norm,
)
from sandbox.model.moving_target import advance, moving_target
from sandbox.model.potential import PARAMS as POTENTIAL
from sandbox.model.potential import potential_velocity, repulsion
from sandbox.plugins.contexts import LawContext
from sandbox.run.goals import goal_slots

STUDIES = SCENARIOS / "studies"


def law_context(pos, vel=None, params=None, offset=None, ref_velocity=(0.0, 0.0)):
    """One world's context: the reference at the origin, moving at ``ref_velocity``."""
    pos = np.asarray(pos, dtype=float)
    n = len(pos)
    return LawContext(
        t=0.0,
        dt=0.01,
        pos=pos,
        theta=np.zeros(n),
        vel=np.zeros((n, 2)) if vel is None else np.asarray(vel, dtype=float),
        offset=np.zeros((n, 2)) if offset is None else np.asarray(offset, float),
        leader=-1,
        leader_pos=None,
        leader_theta=None,
        reference=(np.zeros(2), np.asarray(ref_velocity, dtype=float), np.zeros(2)),
        params=params,
        memory={},
    )


def defaults(table, **values):
    """A law's values with the defaults of ``table`` (lengths for d = 0.5 m)."""
    lengths = {"3d": 1.5, "1d": 0.5, "2.5d": 1.25}
    out = {k: lengths.get(p.default, p.default) for k, p in table.items()}
    out.update(values)
    return out


# -------------------------------------------------------------- potential
def test_the_potential_attracts_to_the_goal_and_saturates() -> None:
    # One vehicle 1 m east of its goal (the origin): (P2) -k_att (q - g) = (-1, 0)
    # m/s; 5 m east: (-5, 0) scaled down to max_speed 2 m/s; the leader moving at
    # (0.5, 0) adds its velocity (P1).
    ctx = law_context([[1.0, 0.0]], params=defaults(POTENTIAL))
    v = potential_velocity(ctx, ctx.pos, np.zeros((1, 2)))
    np.testing.assert_allclose(v, [[-1.0, 0.0]], rtol=0, atol=1e-15)
    v = potential_velocity(ctx, np.array([[5.0, 0.0]]), np.zeros((1, 2)))
    np.testing.assert_allclose(v, [[-2.0, 0.0]], rtol=0, atol=1e-15)
    ctx = law_context([[1.0, 0.0]], params=defaults(POTENTIAL), ref_velocity=(0.5, 0))
    v = potential_velocity(ctx, ctx.pos, np.zeros((1, 2)))
    np.testing.assert_allclose(v, [[-0.5, 0.0]], rtol=0, atol=1e-15)


def test_the_potential_repels_within_r_only() -> None:
    # Two vehicles at their goals 1 m apart on x1: gap rho = 1 - d_c = 0.5 m,
    # rho_0 = R - d_c = 1 m: (P3) k_rep (1 / 0.5 - 1 / 1) = 0.5 m/s each, apart.
    # At 1.5 m (= R) and beyond nothing repels.
    pos = np.array([[0.0, 0.0], [1.0, 0.0]])
    ctx = law_context(pos, params=defaults(POTENTIAL))
    v = potential_velocity(ctx, pos, pos)
    np.testing.assert_allclose(v, [[-0.5, 0.0], [0.5, 0.0]], rtol=0, atol=1e-15)
    far = np.array([[0.0, 0.0], [1.5, 0.0]])
    ctx = law_context(far, params=defaults(POTENTIAL))
    assert np.all(potential_velocity(ctx, far, far) == 0.0)
    # The gap is floored at MIN_GAP = 0.01 m: overlapping, 0.5 (100 - 1) m/s.
    assert repulsion(np.array([[0.3, 0.0]]), 0.5, 1.5, 0.5)[0, 0] == -49.5


# -------------------------------------------------------------- flocking
def test_the_sigma_norm_and_the_bump_by_hand() -> None:
    # |z|_s = (sqrt(1 + 0.1 |z|^2) - 1) / 0.1: for |z|^2 = 10, (sqrt(2) - 1) / 0.1.
    z = np.array([[1.0, 3.0]])
    assert float(sigma_norm(z)[0]) == pytest.approx((math.sqrt(2) - 1) / 0.1)
    assert sigma_length(math.sqrt(10.0)) == pytest.approx((math.sqrt(2) - 1) / 0.1)
    # rho_h: 1 below h = 0.2, (1 + cos(pi (z - h) / (1 - h))) / 2 between, 0 at 1 on.
    b = bump(np.array([0.0, 0.2, 0.6, 1.0, 1.2]), 0.2)
    np.testing.assert_allclose(b, [1.0, 1.0, 0.5, 0.0, 0.0], rtol=0, atol=1e-15)


def test_the_action_repels_below_d_attracts_up_to_r_and_vanishes_beyond() -> None:
    # a = b = 5: phi(z) = 5 s1(z) (c = 0), so phi_a(d_s) = 0, negative below,
    # positive above, and 0 from r_s = |1.2 d|_s on.
    d = 1.25
    d_s, r_s = sigma_length(d), sigma_length(1.2 * d)
    z = np.array([0.5 * d_s, d_s, 0.5 * (d_s + r_s), r_s, 2 * r_s])
    phi = action(z, 5.0, 5.0, d_s, r_s)
    assert phi[0] < 0.0 and phi[1] == 0.0 and phi[2] > 0.0
    assert phi[3] == 0.0 and phi[4] == 0.0
    # at z = d_s / 2: rho_h(z / r_s) 5 s1(z - d_s), s1(x) = x / sqrt(1 + x^2)
    expect = bump(np.array(0.5 * d_s / r_s), 0.2) * 5.0 * (-0.5 * d_s)
    expect /= math.sqrt(1.0 + (0.5 * d_s) ** 2)
    assert phi[0] == pytest.approx(float(expect), rel=1e-12)


def test_flocking_at_its_goal_with_the_leader_s_velocity_is_at_rest() -> None:
    # A lone agent at its goal moving with the virtual leader: u = 0. Displaced by
    # (1, 0) at rest, leader at rest: u = -c1 s1((1, 0)) = -(1 / sqrt(2), 0).
    params = defaults(FLOCKING)
    ctx = law_context([[0.0, 0.0]], params=params, ref_velocity=(1.0, 0.0))
    u = flocking_acceleration(ctx, ctx.pos, np.array([[1.0, 0.0]]), np.zeros((1, 2)))
    assert np.all(u == 0.0)
    ctx = law_context([[1.0, 0.0]], params=params)
    u = flocking_acceleration(ctx, ctx.pos, np.zeros((1, 2)), np.zeros((1, 2)))
    np.testing.assert_allclose(u, [[-1.0 / math.sqrt(2.0), 0.0]], rtol=0, atol=1e-15)


def test_flocking_aligns_with_a_neighbour_and_keeps_its_distance() -> None:
    # Two agents d = 1.25 m apart (phi_a = 0), at their goals, the second moving at
    # (0, 1) m/s and the leader at rest: the first gets only the alignment, c_al a_12
    # (v_2 - p_1) with a_12 = rho_h(d_s / r_s), d_s / r_s > 0.2 (so within the ramp).
    params = defaults(FLOCKING)
    pos = np.array([[0.0, 0.0], [1.25, 0.0]])
    vel = np.array([[0.0, 0.0], [0.0, 1.0]])
    ctx = law_context(pos, vel=vel, params=params)
    u = flocking_acceleration(ctx, pos, np.zeros((2, 2)), pos)
    a12 = float(bump(np.array(sigma_length(1.25) / sigma_length(1.5)), 0.2))
    np.testing.assert_allclose(u[0], [0.0, a12], rtol=0, atol=1e-12)


def test_the_moving_target_starts_at_the_vehicle_and_integrates() -> None:
    ctx = law_context([[1.0, 2.0]], vel=[[0.5, 0.0]], params={})
    target = moving_target(ctx)
    assert target.position.tolist() == [[1.0, 2.0]]
    q, v, a = advance(target, np.array([[1.0, 0.0]]), 0.01)
    assert q.tolist() == [[1.0, 2.0]] and a.tolist() == [[0.0, 0.0]]  # first step
    q, v, a = advance(target, np.array([[2.0, 0.0]]), 0.01)
    assert q.tolist() == [[1.01, 2.0]]  # 1 m/s over 0.01 s
    assert a.tolist() == [[100.0, 0.0]]  # (2 - 1) / 0.01, eq. (19)


# -------------------------------------------------------------- goals and runs
@pytest.mark.slow
@pytest.mark.parametrize("law", ["potential", "flocking"])
def test_a_form_up_with_each_law_and_its_goals(law) -> None:
    run, m = run_scenario(
        STUDIES / "random_formup.yaml",
        f"formation={{law: {law}, rotate: true}}",
        "recovery.strategy=none",
        seed=1,
    )
    goal = goal_slots(run)
    sc = run.scenario
    # the goals: the reference point plus each offset (a line at heading 0)
    p = sc.reference.build().evaluate(np.asarray(run.t))[0]
    offset = np.array([v.offset for v in sc.vehicles])
    np.testing.assert_allclose(goal, p[:, None, :] + offset, rtol=0, atol=1e-12)
    assert m["collisions"]["total"] == 0
    # The moving targets are tracked from the start (the run's own settling: once
    # the drives are up to speed); the goals are reached later, or (flocking, the
    # virtual leader's pull saturated at c1) not in 15 s.
    block = m["formation_goal"]
    tracked = max(v["settling_time"] for v in m["vehicles"].values())
    assert m["converged"]
    if law == "potential":
        assert block["converged"]
        formed = max(v["settling_time"] for v in block["vehicles"].values())
        assert formed > tracked + 1.0


@pytest.mark.slow
def test_the_potential_s_trap_behind_a_stopped_vehicle() -> None:
    # The classic local minimum of potential fields: orange's goal straight beyond
    # the stopped green, attraction and repulsion cancel, orange stays behind it to
    # the end (a deadlock against its goal), without contact.
    _, m = run_scenario(
        STUDIES / "failure_formup.yaml",
        "formation={law: potential, rotate: true}",
        "recovery.strategy=none",
        "failures[0].kind=stop",
        seed=0,
    )
    assert m["collisions"]["total"] == 0
    trapped = m["formation_goal"]["deadlocks"]
    assert [d["vehicles"] for d in trapped] == [["orange"]]
    assert trapped[0]["t"] + trapped[0]["duration"] == pytest.approx(15.0)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "fixed"),
    [
        ("studies/random_formup", ["formation={law: potential, rotate: true}"]),
        ("studies/random_formup", ["formation={law: flocking, rotate: true}"]),
        (
            "safety/obstacle_field_random",
            [
                "formation={law: potential}",
                "sensors={range: {beams: 24, max_range: 4}}",
            ],
        ),
        (
            "studies/failure_formup",
            ["formation={law: flocking, rotate: true}", "recovery.strategy=none"],
        ),
        # worlds that re-form apart: each world's own law on its rows
        (
            "failures/follower_stop",
            ["formation.law=potential", "reconfigure.assign=hungarian"],
        ),
        (
            "failures/follower_stop",
            ["formation={law: flocking, rotate: true}", "reconfigure.assign=hungarian"],
        ),
    ],
)
def test_a_world_in_a_batch_is_its_run_alone(name, fixed, tmp_path) -> None:
    scenarios = [
        load_scenario(name, overrides=[*fixed, "duration=4", f"seed={s}"])
        for s in range(3)
    ]
    assert_batch_is_alone(scenarios, tmp_path)
