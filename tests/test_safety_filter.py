"""The control-barrier-function safety filter (``safety: {filter: cbf}``).

Scenario-level: head-on vehicles collide without the filter and keep ``d`` apart with
it; a vehicle stops short of a failed one and of a wall; a vehicle dodges a runaway.
Equation-level: the planar QP solver against a brute-force grid, the barrier rows
(half the budget toward a healthy neighbour, all of it toward a failed one), the slack
on an infeasible case. And ``filter: none`` is the run without the section.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sandbox import accel, load_scenario
from sandbox.behaviour.safety.cbf import (
    PARAMS,
    CBFState,
    barrier_rows,
    filter_commands,
)
from sandbox.behaviour.safety.qp import min_violation, solve
from sandbox.behaviour.safety.right_hand import stall_turn
from sandbox.cli import main
from sandbox.errors import SandboxWarning
from sandbox.loop.simulation import Simulation
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.contexts import FilterContext
from sandbox.run.metrics import compute_metrics
from sandbox.scenario import ObstacleSpec

ROOT = Path(__file__).resolve().parents[1]
HEAD_ON = ROOT / "scenarios" / "safety" / "head_on_swap.yaml"
#: The robot of the section-4 form-ups.
ROBOT = {"diameter": 0.5, "mass": 10.0, "v1_max": 2.0, "v2_max": 4.0, "max_accel": 5.0}
D = 0.5  # [m]


def run(doc_or_path, *sets: str):
    sc = load_scenario(doc_or_path, overrides=list(sets))
    r = Simulation(sc).run()
    return r, compute_metrics(r)


def point_doc(vehicles, duration=6.0, **extra):
    return {
        "duration": duration,
        "vehicle": ROBOT,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "vehicles": vehicles,
        **extra,
    }


def centre_distances(r) -> np.ndarray:
    p = r.pose[:, :, :2]
    return np.linalg.norm(p[:, 0] - p[:, 1], axis=-1)


# ------------------------------------------------------------------ scenario level
@pytest.mark.slow
def test_head_on_vehicles_collide_without_the_filter_and_not_with_it() -> None:
    sets = ["duration=6", "recovery.strategy=none"]
    _, bare = run(HEAD_ON, *sets)
    assert bare["collisions"]["vehicle_vehicle"] >= 1
    r, m = run(HEAD_ON, *sets, "safety.filter=cbf")
    assert m["collisions"]["total"] == 0
    # The barrier keeps the centres d + margin apart (margin 0.05 m), up to the
    # discretisation of one control period.
    assert m["min_distance"] >= D + 0.04
    assert np.min(centre_distances(r)) >= D + 0.04
    assert m["safety"]["filter"] == "cbf"
    assert m["safety"]["active_steps"] > 0
    assert m["safety"]["infeasible_steps"] == 0


@pytest.mark.slow
def test_a_vehicle_stops_short_of_a_failed_one() -> None:
    # a's slot (3, 0) lies straight beyond b, stopped at the origin from t = 0.
    doc = point_doc(
        [
            {"name": "a", "pose": [-3, 0, 0], "offset": [3, 0]},
            {"name": "b", "pose": [0, 0, 0], "offset": [0, 0]},
        ],
        failures=[{"vehicle": "b", "at": 0.0, "kind": "stop"}],
    )
    _, bare = run({**doc, "safety": {"filter": "none"}})
    assert bare["collisions"]["vehicle_vehicle"] == 1
    # The barrier alone (the right-hand rule off): a stops at it, for ever.
    r, m = run({**doc, "safety": {"filter": "cbf", "pass_right": 0}})
    assert m["collisions"]["total"] == 0
    gap = centre_distances(r)
    # Against b's centre: |p_a - c_b| >= d + l + margin = 0.65 m, so the centres stay
    # 0.75 m apart; a ends at rest there, short of b.
    assert gap.min() >= 0.74
    assert r.pose[-1, 0, 0] < -0.7
    assert abs(r.cmd[-1, 0, 0]) < 1e-3


@pytest.mark.slow
def test_the_right_hand_rule_passes_the_stopped_vehicle() -> None:
    # The same case with the filter's defaults (pass_right pi/2): held back nose to
    # nose, a turns its nominal velocity right, passes b and settles on its slot,
    # still without contact.
    doc = point_doc(
        [
            {"name": "a", "pose": [-3, 0, 0], "offset": [3, 0]},
            {"name": "b", "pose": [0, 0, 0], "offset": [0, 0]},
        ],
        duration=8.0,
        failures=[{"vehicle": "b", "at": 0.0, "kind": "stop"}],
        safety={"filter": "cbf"},
    )
    r, m = run(doc)
    assert m["collisions"]["total"] == 0
    assert centre_distances(r).min() >= 0.74
    assert m["vehicles"]["a"]["settling_time"] is not None
    assert m["vehicles"]["a"]["formation_error"]["final"] < 0.01
    # It went round on its right: below the line (negative x2) while passing.
    passing = np.abs(r.pose[:, 0, 0]) < 0.3
    assert np.all(r.pose[passing, 0, 1] < -0.5)


@pytest.mark.slow
def test_a_vehicle_dodges_a_runaway_driving_at_it() -> None:
    # r is driven open loop at 1 m/s straight at a, which holds its slot at the origin:
    # a neighbour that does not filter is the filter's full responsibility.
    doc = point_doc(
        [
            {"name": "a", "pose": [0, 0, 1.5707963], "offset": [0, 0]},
            {
                "name": "r",
                "pose": [-3, 0, 0],
                "drive": {"type": "commands", "schedule": [[0, 1.0, 0.0]]},
            },
        ]
    )
    _, bare = run({**doc, "safety": {"filter": "none"}})
    assert bare["collisions"]["vehicle_vehicle"] == 1
    r, m = run({**doc, "safety": {"filter": "cbf"}})
    assert m["collisions"]["total"] == 0
    assert centre_distances(r).min() >= D + 0.04


@pytest.mark.slow
def test_a_wall_is_respected() -> None:
    doc = point_doc(
        [{"name": "a", "pose": [-3, 0, 0], "offset": [3, 0]}],
        obstacles=[{"type": "wall", "from": [0, -2], "to": [0, 2], "thickness": 0.1}],
    )
    _, bare = run({**doc, "safety": {"filter": "none"}})
    assert bare["collisions"]["vehicle_obstacle"] == 1
    r, m = run({**doc, "safety": {"filter": "cbf", "pass_right": 0}})
    assert m["collisions"]["total"] == 0
    # p stays d/2 + l + margin = 0.4 m off the wall's face at x = -0.05 m.
    assert r.pose[:, 0, 0].max() <= -0.05 - 0.25 - 0.04
    # With the right-hand rule (the default) it goes round the wall's southern end,
    # still 0.4 m off every face, and reaches its slot.
    r, m = run({**doc, "safety": {"filter": "cbf"}}, "duration=10")
    assert m["collisions"]["total"] == 0
    x, y = r.pose[:, 0, 0], r.pose[:, 0, 1]
    beside = np.abs(x) <= 0.05 + 0.25
    assert np.all(y[beside] < -2.0 - 0.25)
    assert m["vehicles"]["a"]["formation_error"]["final"] < 0.05


@pytest.mark.slow
def test_infeasible_steps_are_counted_in_the_metrics() -> None:
    # 1 m/s^2 of braking against gamma = 20 1/s (a braking of 20 v demanded): the
    # barrier cannot be kept by the input bounds, the slack is used and counted.
    doc = point_doc(
        [{"name": "a", "pose": [-3, 0, 0], "offset": [3, 0]}],
        obstacles=[{"type": "wall", "from": [0, -2], "to": [0, 2], "thickness": 0.1}],
        safety={"filter": "cbf", "gamma": 20.0},
    )
    doc["vehicle"] = {**ROBOT, "max_accel": 1.0}
    _, m = run(doc)
    assert m["safety"]["infeasible_steps"] > 0
    assert m["safety"]["max_slack"] > 0


def test_filter_none_is_the_run_without_the_section() -> None:
    sets = ["duration=2", "recovery.strategy=none"]
    a, ma = run(HEAD_ON, *sets)
    doc_sets = [*sets, "safety={filter: none, gamma: 3.0, margin: 0.2}"]
    ignored = r"safety\.(gamma|margin): does nothing here"  # the cbf's keys, warned of
    with pytest.warns(SandboxWarning, match=ignored):
        b, mb = run(HEAD_ON, *doc_sets)
    for key in ("pose", "cmd", "chi", "slot", "target", "mode"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    assert "safety" not in ma and "safety" not in mb
    with pytest.warns(SandboxWarning, match=ignored):
        assert "safety" not in load_scenario(HEAD_ON, overrides=doc_sets).to_dict()


@pytest.mark.slow
def test_the_filtered_run_is_deterministic_and_works_with_sensing() -> None:
    sets = ["duration=3", "recovery.strategy=none", "safety.filter=cbf"]
    a, ma = run(HEAD_ON, *sets)
    b, mb = run(HEAD_ON, *sets)
    np.testing.assert_array_equal(a.pose, b.pose)
    np.testing.assert_array_equal(a.cmd, b.cmd)
    assert ma["safety"] == mb["safety"]
    # With a noisy, delayed broadcast each vehicle filters against what it receives.
    noisy = [*sets, "sensing.position_noise=0.01", "sensing.delay=0.02"]
    r, m = run(HEAD_ON, *noisy)
    assert m["collisions"]["total"] == 0
    assert m["min_distance"] >= D + 0.02
    assert not np.array_equal(r.cmd, a.cmd)


def test_the_section_round_trips_through_to_dict() -> None:
    sc = load_scenario(HEAD_ON, overrides=["safety={filter: cbf, gamma: 3.0}"])
    doc = sc.to_dict()
    assert doc["safety"]["filter"] == "cbf" and doc["safety"]["gamma"] == 3.0
    assert load_scenario(doc).safety == sc.safety


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("safety.filter=cbx", "safety.filter: unknown safety filter"),
        ("safety.gamma=0", "safety.gamma: must be greater than 0"),
        ("safety.projection=sideways", "expected one of: look_ahead, speed"),
        ("safety.max_constraints=40", "safety.max_constraints"),
    ],
)
def test_bad_safety_input_is_one_line(value, message, capsys) -> None:
    assert main(["validate", str(HEAD_ON), "--set", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert str(HEAD_ON.name) in err[0] and message in err[0]
    assert "Traceback" not in err[0]


def test_the_automatic_range_needs_speed_limits(tmp_path, capsys) -> None:
    path = tmp_path / "fast.yaml"
    path.write_text(
        "duration: 1\nreference: {type: point, position: [0, 0]}\n"
        "vehicles: [{name: a, pose: [0, 0, 0]}]\nsafety: {filter: cbf}\n",
        encoding="utf-8",
    )
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fast.yaml:4: safety.range: needed" in err[0], err
    assert main(["validate", str(path), "--set", "safety.range=3"]) == 0


# ------------------------------------------------------------------ the QP solver
def _grid_check(z0, a, b, z, tol=1e-9):
    """``z`` is feasible and no feasible grid point is nearer to ``z0``."""
    assert np.all(a @ z - b <= 1e-7)
    g = np.linspace(-3.0, 3.0, 151)
    pts = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    ok = np.all(pts @ a.T - b <= 0, axis=1)
    if ok.any():
        best = np.min(np.sum((pts[ok] - z0) ** 2, axis=1))
        assert np.sum((z - z0) ** 2) <= best + tol


def test_the_qp_is_exact_against_a_brute_force_grid() -> None:
    rng = np.random.default_rng(3)
    n, m = 160, 6
    box = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    angles = rng.uniform(0, 2 * np.pi, (n, m))
    normals = np.stack((np.cos(angles), np.sin(angles)), -1)
    a = np.concatenate((np.broadcast_to(box, (n, 4, 2)), normals), axis=1)
    b = np.concatenate((np.full((n, 4), 2.5), rng.uniform(-1.0, 1.5, (n, m))), 1)
    # Some rows padded out (a = 0, b = 1).
    pad = rng.random((n, m)) < 0.2
    a[:, 4:][pad] = 0.0
    b[:, 4:][pad] = 1.0
    z0 = rng.uniform(-3, 3, (n, 2))
    soft = np.zeros((n, 4 + m), dtype=bool)
    soft[:, 4:] = True
    z, slack = solve(z0, a, b, soft)
    feasible = slack == 0
    assert 20 < feasible.sum() < n - 20  # both kinds are exercised
    for k in np.flatnonzero(feasible):
        _grid_check(z0[k], a[k], b[k], z[k])
    g = np.linspace(-2.5, 2.5, 151)
    pts = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    for k in np.flatnonzero(~feasible)[:40]:
        # The least largest violation over the box, by brute force, is the slack.
        worst = np.max(pts @ a[k, 4:].T - b[k, 4:], axis=1)
        assert slack[k] > 0
        assert slack[k] <= worst.min() + 1e-9
        assert slack[k] >= worst.min() - 0.07  # the grid's resolution
        # z keeps the bounds and violates no barrier by more than the slack.
        assert np.all(a[k, :4] @ z[k] - b[k, :4] <= 1e-7)
        assert np.max(a[k, 4:] @ z[k] - b[k, 4:]) <= slack[k] + 1e-7


def test_min_violation_of_two_opposite_half_planes() -> None:
    # z1 <= -1 and -z1 <= -1 (z1 >= 1) within the box |z| <= 5: the least slack is 1
    # (both relaxed to z1 = 0).
    a = np.array([[[1, 0], [-1, 0], [0, 1], [0, -1], [1, 0], [-1, 0]]], dtype=float)
    b = np.array([[5, 5, 5, 5, -1, -1]], dtype=float)
    soft = np.array([[0, 0, 0, 0, 1, 1]], dtype=bool)
    s, z = min_violation(a, b, soft)
    assert s[0] == pytest.approx(1.0)
    assert z[0, 0] == pytest.approx(0.0)


# ------------------------------------------------------------------ barrier rows
def _ctx(pos, theta, v1, v2, failed=None, obstacles=(), **params):
    n = len(pos)
    values = {k: p.default for k, p in PARAMS.items()}
    values.update(params)
    return FilterContext(
        t=0.0,
        dt=0.01,
        pos=np.asarray(pos, dtype=float),
        theta=np.asarray(theta, dtype=float),
        vel=np.zeros((n, 2)),
        v1=np.asarray(v1, dtype=float),
        v2=np.asarray(v2, dtype=float),
        diameter=np.full(n, D),
        params=values,
        v1_prev=np.asarray(v1, dtype=float),
        v2_prev=np.asarray(v2, dtype=float),
        v1_max=2.0,
        v2_max=4.0,
        accel_max=5.0,
        known_failed=np.zeros(n, bool) if failed is None else np.asarray(failed),
        commanded=np.zeros(n, bool),
        obstacle_field=ObstacleField(tuple(obstacles)),
    )


def test_half_the_budget_toward_a_healthy_neighbour_all_of_it_toward_a_failed_one():
    # Both at rest, 1 m apart on x1, facing each other; gamma 2, l 0.1, margin 0.05.
    pos, theta = [[0.0, 0.0], [1.0, 0.0]], [0.0, np.pi]
    ctx = _ctx(pos, theta, [0.0, 0.0], [0.0, 0.0], neighbour_velocity="zero")
    state = CBFState(ctx)
    veh, a, b = barrier_rows(state, ctx, np.ones(2, bool))
    # p_0 = (0.1, 0), p_1 = (0.9, 0): |dp| = 0.8, D = 0.5 + 0.2 + 0.05 = 0.75,
    # h = 0.64 - 0.5625 = 0.0775; half the budget: 2 |dp| (closing) <= gamma h / 2,
    # closing speed <= 2 * 0.0775 / 2 / (2 * 0.8) = 0.0484375 m/s.
    row = np.flatnonzero(veh == 0)[0]
    np.testing.assert_allclose(a[row], [1.0, 0.0], atol=1e-12)
    assert b[row] == pytest.approx(0.0484375)
    # b failed: 0 toward b's centre, |p_0 - c_1| = 0.9, D' = 0.5 + 0.1 + 0.05 = 0.65,
    # h = 0.81 - 0.4225 = 0.3875, all the budget: gamma h / (2 |dp|) = 0.430556 m/s.
    ctx = _ctx(pos, theta, [0.0, 0.0], [0.0, 0.0], failed=[False, True])
    veh, a, b = barrier_rows(state, ctx, np.array([True, False]))
    assert veh.tolist() == [0]
    assert b[0] == pytest.approx(2 * 0.3875 / (2 * 0.9))


def test_broadcast_velocity_leaves_a_platoon_moving_together_alone() -> None:
    # Three vehicles in a column 1 m apart, all at 1 m/s along x1: with the broadcast
    # velocities nothing has to change; treating the others as standing still brakes.
    pos = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]
    theta, v1, v2 = np.zeros(3), np.ones(3), np.zeros(3)
    ctx = _ctx(pos, theta, v1, v2)
    out1, _, step = filter_commands(CBFState(ctx), ctx)
    assert not step.active.any() and out1.tolist() == [1.0, 1.0, 1.0]
    ctx = _ctx(pos, theta, v1, v2, neighbour_velocity="zero")
    out1, _, step = filter_commands(CBFState(ctx), ctx)
    assert step.active[:2].all() and np.all(out1[:2] < 1.0)


@pytest.mark.parametrize("velocity", ["broadcast", "zero"])
def test_dropping_pairs_that_cannot_bind_changes_nothing(velocity) -> None:
    # 60 vehicles at random in a 7 m square (some closer than D, some far), random
    # headings and last commands; one failed: the same commands with and without the
    # early pruning of pairs (both by numpy: the compiled step prunes too, and is
    # compared with numpy in test_compiled_paths.py).
    rng = np.random.default_rng(5)
    n = 60
    pos = rng.uniform(0, 7, (n, 2))
    theta = rng.uniform(-np.pi, np.pi, n)
    v1, v2 = rng.uniform(0, 2, n), rng.uniform(-4, 4, n)
    failed = np.zeros(n, bool)
    failed[7] = True
    ctx = _ctx(pos, theta, v1, v2, failed=failed, neighbour_velocity=velocity)
    ctx.v1_prev = np.clip(v1 + rng.normal(0, 0.03, n), 0, 2)
    ctx.v2_prev = rng.uniform(-4, 4, n)
    state = CBFState(ctx)
    with accel.switched_off("filter"):
        a1, a2, step = filter_commands(state, ctx)
        b1, b2, full = filter_commands(state, ctx, prune=False)
    assert step.active.sum() > 5
    np.testing.assert_array_equal(a1, b1)
    np.testing.assert_array_equal(a2, b2)
    np.testing.assert_array_equal(step.slack, full.slack)
    assert step.rows == full.rows


def test_speed_projection_keeps_the_turn_rate() -> None:
    pos, theta = [[0.0, 0.0], [0.9, 0.05]], [0.0, np.pi]
    ctx = _ctx(pos, theta, [1.0, 1.0], [0.5, -0.3], projection="speed")
    v1, v2, step = filter_commands(CBFState(ctx), ctx)
    assert step.active.all()
    assert v2.tolist() == [0.5, -0.3]
    assert np.all(v1 < 1.0)
    ctx = _ctx(pos, theta, [1.0, 1.0], [0.5, -0.3])
    _, v2, _ = filter_commands(CBFState(ctx), ctx)
    assert not np.allclose(v2, [0.5, -0.3])


def test_an_infeasible_step_is_relaxed_and_counted() -> None:
    # At 2 m/s, 0.05 m from where the barrier of a wall starts, with 5 m/s^2: the
    # speed may drop by 0.05 m/s in one period, the barrier asks for about -0.1 m/s.
    wall = ObstacleSpec("wall", "w", start=(0.0, -2.0), end=(0.0, 2.0), thickness=0.1)
    x = -0.05 - 0.4 - 0.1 + 0.05  # the centre; p = x + 0.1
    ctx = _ctx([[x, 0.0]], [0.0], [2.0], [0.0], obstacles=[wall])
    from sandbox.behaviour.safety.cbf import cbf

    v1, _ = cbf(ctx)
    step = ctx.memory["last"]
    assert step.slack[0] > 0
    assert ctx.stats["infeasible_steps"] == 1
    assert v1[0] == pytest.approx(2.0 - 5.0 * 0.01)  # braking as hard as it can


def _jammed_ring(n: int, **params):
    # n vehicles heading to the centre, at rest, whose look-ahead points are D apart
    # (every neighbouring barrier binds, h = 0), each asking for 1 m/s inward.
    chord = D + 2 * 0.1 + 0.05 + 1e-9
    r_p = chord / (2 * np.sin(np.pi / n))
    angle = 2 * np.pi * np.arange(n) / n
    pos = (r_p + 0.1) * np.stack((np.cos(angle), np.sin(angle)), -1)
    ctx = _ctx(pos, angle + np.pi, np.ones(n), np.zeros(n), **params)
    ctx.v1_prev, ctx.v2_prev = np.zeros(n), np.zeros(n)
    return ctx


@pytest.mark.parametrize("n", [3, 8, 20])
def test_the_right_hand_rule_frees_a_ring_jammed_in_its_corners(n) -> None:
    # The corner of two barriers whose normals lie at +-a from the way out admits
    # the velocities within 90 deg - a of it; the ring has a = 90 - 180 / n degrees,
    # so the nominal velocity (straight into the corner) must turn by more than a.
    a = np.pi / 2 - np.pi / n
    for turn, free in ((0.0, False), (a - 0.05, False), (np.pi / 2, True)):
        ctx = _jammed_ring(n, pass_right=turn)
        v1, v2, step = filter_commands(CBFState(ctx), ctx)
        speed = np.hypot(v1, 0.1 * v2)
        if free:
            assert np.all(speed > 0.05), (n, turn)
            # every vehicle the same, turned to its right (clockwise: v2 < 0)
            np.testing.assert_allclose(speed, speed[0], rtol=1e-9)
            assert np.all(v2 < 0)
        else:
            assert np.all(speed < 1e-6), (n, turn)
        assert np.all(step.slack <= 1e-9)


def test_the_right_hand_rule_leaves_a_vehicle_at_its_slot_alone() -> None:
    # stall_turn: nothing below half kept, a right angle at a tenth kept, and in
    # proportion to the nominal speed below 0.2 m/s.
    z0 = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.1, 0.0], [0.0, 0.0]])
    z = np.array([[0.6, 0.0], [0.3, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    turn = stall_turn(z0, z, np.pi / 2)
    np.testing.assert_allclose(turn, [0.0, np.pi / 4, np.pi / 2, np.pi / 4, 0.0])
