"""ORCA as a safety filter (``safety: {filter: orca}``).

Equation-level: the ORCA half-plane of two discs computed by hand (a leg, the cut-off
circle, overlapping discs) and its reciprocity; the planar program on hand cases
(nearest point of a corner, of the speed disc), its 3-D fallback (the least violation,
the hard lines kept), and against a brute-force grid; the unicycle's holonomic
velocity and commands, and the tracking error they keep. Filter-level: a vehicle with
no neighbour passes unchanged, two closing vehicles are slowed, a failed one is avoided
alone. Scenario-level: head-on with no contact, the rings of 8 (the exact one a
documented deadlock), an obstacle field, and a world in a batch is its run alone.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from helpers import SCENARIOS, run_scenario
from test_one_loop import assert_batch_is_alone

from sandbox import load_scenario
from sandbox.behaviour.safety.constrained import record_episodes
from sandbox.behaviour.safety.holonomic import (
    CORNERS,
    admissible_speed,
    align_time,
    drive_lines,
    holonomic_velocity,
    speed_factor,
    unicycle_commands,
)
from sandbox.behaviour.safety.orca import PARAMS, ORCAState, orca_commands
from sandbox.behaviour.safety.orca_lines import surface_lines, vehicle_lines
from sandbox.behaviour.safety.orca_program import HalfPlanes, det, solve
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.contexts import FilterContext
from sandbox.run.constrained import constrained_mask, filter_name

SAFETY = SCENARIOS / "safety"


def planes(lines: list[tuple], hard: int = 0) -> HalfPlanes:
    """One program from ``(point, direction)`` pairs, the first ``hard`` kept hard."""
    point = np.array([[p for p, _ in lines]], dtype=float)
    direction = np.array([[d for _, d in lines]], dtype=float)
    return HalfPlanes(
        point, direction, np.ones((1, len(lines)), dtype=bool), np.array([hard])
    )


# -------------------------------------------------------------- the half-planes
def test_the_half_plane_of_two_discs_on_a_leg_by_hand() -> None:
    # B 4 m ahead of A, closing at 2 m/s, R = 1 m, tau = 4 s: the cut-off centre
    # rel_pos / tau = (1, 0) lies behind rel_vel = (2, 0) (w = (1, 0), w . rel_pos > 0),
    # so the nearest boundary is a leg. w is along rel_pos (det = 0): the right leg,
    # -(x leg + y R, -x R + y leg) / |rel_pos|^2 = -(4 sqrt15, -4) / 16, and
    # u = (rel_vel . d) d - rel_vel = (15/8 - 2, -sqrt15/8) = (-1/8, -sqrt15/8),
    # of length 2 sin(asin(1/4)) = 0.5 m/s.
    d, u = vehicle_lines(
        np.array([[4.0, 0.0]]), np.array([[2.0, 0.0]]), np.array([1.0]), 4.0, 0.01
    )
    s15 = np.sqrt(15.0)
    np.testing.assert_allclose(d, [[-s15 / 4.0, 0.25]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(u, [[-1.0 / 8.0, -s15 / 8.0]], rtol=0, atol=1e-15)
    assert np.hypot(*u[0]) == pytest.approx(0.5, abs=1e-15)


def test_the_half_plane_on_the_cut_off_circle_and_of_overlapping_discs() -> None:
    # Cut-off: rel_vel (1.75, 0) is 0.25 m/s inside the circle of radius R / tau =
    # 0.5 about rel_pos / tau = (2, 0): u = (-0.25, 0), the line vertical.
    d, u = vehicle_lines(
        np.array([[4.0, 0.0]]), np.array([[1.75, 0.0]]), np.array([1.0]), 2.0, 0.01
    )
    assert d.tolist() == [[0.0, 1.0]] and u.tolist() == [[-0.25, 0.0]]
    # Overlapping (0.5 m apart, R = 1 m) at rest: separate within one period h =
    # 0.01 s: w = -rel_pos / h = (-50, 0), u = (R / h - |w|) w / |w| = (-50, 0).
    d, u = vehicle_lines(
        np.array([[0.5, 0.0]]), np.array([[0.0, 0.0]]), np.array([1.0]), 2.0, 0.01
    )
    assert d.tolist() == [[0.0, 1.0]] and u.tolist() == [[-50.0, 0.0]]


def test_the_two_half_planes_of_a_pair_are_reciprocal() -> None:
    # A sees B at rel_pos with rel_vel; B sees A at -rel_pos with -rel_vel: B's change
    # is minus A's (u_B = -u_A) and its line the mirror image, so that half of the
    # change each leaves the pair exactly on the boundary of the velocity obstacle.
    rng = np.random.default_rng(7)
    rel_pos = rng.uniform(-4, 4, (50, 2))
    rel_vel = rng.uniform(-3, 3, (50, 2))
    radius = np.full(50, 0.75)
    d_a, u_a = vehicle_lines(rel_pos, rel_vel, radius, 2.0, 0.01)
    d_b, u_b = vehicle_lines(-rel_pos, -rel_vel, radius, 2.0, 0.01)
    np.testing.assert_allclose(u_b, -u_a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d_b, -d_a, rtol=0, atol=1e-12)


def test_a_wall_allows_closing_at_its_clearance_over_the_horizon() -> None:
    # A wall 0.5 m ahead (normal (-1, 0)), obstacle horizon 1 s: v_x <= 0.5 m/s.
    p, d = surface_lines(np.array([[-1.0, 0.0]]), np.array([0.5]), 1.0)
    inside, outside = np.array([0.49, 3.0]), np.array([0.51, -3.0])
    assert det(d[0], inside - p[0]) >= 0.0 > det(d[0], outside - p[0])


# -------------------------------------------------------------- the programs
def test_the_planar_program_on_hand_cases() -> None:
    # v_x <= 1 (through (1, 0), direction (0, 1)) and v_y <= 1 (through (0, 1),
    # direction (-1, 0)); preferred (2, 2), speeds to 5 m/s: the corner (1, 1).
    corner = planes([((1, 0), (0, 1)), ((0, 1), (-1, 0))])
    v, slack = solve(corner, np.array([5.0]), np.array([[2.0, 2.0]]))
    np.testing.assert_allclose(v, [[1.0, 1.0]], rtol=0, atol=1e-15)
    assert slack.tolist() == [0.0]
    # v_x <= 1 only, preferred (0, 3), speeds to 2 m/s: the disc's point (0, 2).
    v, _ = solve(planes([((1, 0), (0, 1))]), np.array([2.0]), np.array([[0.0, 3.0]]))
    np.testing.assert_allclose(v, [[0.0, 2.0]], rtol=0, atol=1e-15)


def test_the_three_dimensional_program_least_violation_and_hard_lines() -> None:
    # v_x >= 1 and v_x <= -1, both soft: no common point; the least largest
    # violation is 1 m/s, at v_x = 0.
    apart = planes([((1, 0), (0, -1)), ((-1, 0), (0, 1))])
    v, slack = solve(apart, np.array([5.0]), np.array([[0.0, 0.0]]))
    assert v[0, 0] == pytest.approx(0.0, abs=1e-12)
    assert slack[0] == pytest.approx(1.0, abs=1e-12)
    # The same with v_x <= -0.5 hard (first): it is kept, the soft line v_x >= 1 is
    # violated by 1.5 m/s.
    kept = planes([((-0.5, 0), (0, 1)), ((1, 0), (0, -1))], hard=1)
    v, slack = solve(kept, np.array([5.0]), np.array([[0.0, 0.0]]))
    assert v[0, 0] == pytest.approx(-0.5, abs=1e-12)
    assert slack[0] == pytest.approx(1.5, abs=1e-12)


def test_the_planar_program_against_a_brute_force_grid() -> None:
    # Feasible programs (every line keeps the origin), 1 to 6 lines, speeds to 2:
    # the solution keeps every line and the disc, and no grid point that does is
    # nearer to the preferred velocity (grid 0.01 m/s: within its half-diagonal).
    rng = np.random.default_rng(11)
    grid = np.stack(np.meshgrid(*[np.linspace(-2, 2, 401)] * 2), -1).reshape(-1, 2)
    for _ in range(40):
        m = int(rng.integers(1, 7))
        normal = rng.normal(size=(m, 2))
        normal /= np.hypot(*normal.T)[:, None]
        offset = rng.uniform(0.0, 1.0, m)  # n . v >= -offset keeps the origin
        point = -offset[:, None] * normal
        direction = np.stack((normal[:, 1], -normal[:, 0]), -1)
        lines = planes(list(zip(point.tolist(), direction.tolist(), strict=True)))
        pref = rng.uniform(-3, 3, (1, 2))
        v, slack = solve(lines, np.array([2.0]), pref)
        assert slack[0] == 0.0
        assert (det(direction, v[0] - point) >= -1e-9).all()
        assert np.hypot(*v[0]) <= 2.0 + 1e-9
        ok = (grid @ normal.T >= -offset).all(axis=1) & (np.hypot(*grid.T) <= 2.0)
        best = np.min(np.hypot(*(grid[ok] - pref[0]).T))
        assert np.hypot(*(v[0] - pref[0])) <= best + 0.0071


# -------------------------------------------------------------- the unicycle
def test_commands_and_holonomic_velocities_are_inverse() -> None:
    # phi = v2 T within (-pi, pi) and V = v1 / ((phi / 2) / tan(phi / 2)).
    rng = np.random.default_rng(3)
    v2 = rng.uniform(-3.5, 3.5, 200)
    v1 = rng.uniform(0.0, 0.5, 200)
    theta = rng.uniform(-np.pi, np.pi, 200)
    u = holonomic_velocity(v1, v2, theta, 0.4, np.full(200, 2.0))
    back1, back2 = unicycle_commands(u, theta, 0.4, np.full(200, 4.0))
    np.testing.assert_allclose(back1, v1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back2, v2, rtol=0, atol=1e-12)


def test_an_admissible_velocity_is_followed_within_the_tracking_error() -> None:
    # From the origin heading along x1: the commands of u at its admissible speed,
    # held for T_phi, end the arc within E of x + u T_phi (and at E for phi != 0).
    error, align, turn_max = 0.1, 0.4, np.array(4.0)
    for phi in np.linspace(-3.0, 3.0, 13):
        if phi == 0.0:
            continue
        speed = float(admissible_speed(np.array(phi), error, align, turn_max))
        u = speed * np.array([[np.cos(phi), np.sin(phi)]])
        v1, v2 = unicycle_commands(u, np.zeros(1), align, turn_max[None])
        horizon = float(align_time(np.array(phi), align, turn_max))
        turn = v2[0] * horizon  # = phi
        arc = v1[0] / v2[0] * np.array([np.sin(turn), 1.0 - np.cos(turn)])
        gap = np.hypot(*(arc - u[0] * horizon))
        assert gap == pytest.approx(error, rel=1e-9), phi
        assert abs(v2[0]) <= turn_max + 1e-12
    assert speed_factor(np.array([np.pi])).tolist() == [pytest.approx(0.0, abs=1e-16)]


def test_the_drive_polygon_lies_in_the_admissible_set() -> None:
    # Points of the polygon (convex combinations of neighbouring corners and the
    # origin) are followed within E: speed <= E / (T_phi |sin(phi / 2)|).
    theta = np.array([0.7])
    corner, edge = drive_lines(theta, np.array([2.0]), 0.1, 0.4, np.array([4.0]))
    assert corner.shape == (1, CORNERS, 2)
    rng = np.random.default_rng(5)
    for k in range(CORNERS):
        a, b = corner[0, k], corner[0, (k + 1) % CORNERS]
        assert det(edge[0, k], np.zeros(2) - a) > 0.0  # the origin inside
        for w in rng.uniform(0, 1, (20, 2)):
            s, t = sorted(w)
            point = s * a + (t - s) * b  # within the triangle (0, a, b)
            phi = np.arctan2(point[1], point[0]) - theta[0]
            phi = (phi + np.pi) % (2 * np.pi) - np.pi
            limit = admissible_speed(np.array(phi), 0.1, 0.4, np.array(4.0))
            assert np.hypot(*point) <= min(float(limit), 2.0) + 1e-9


# -------------------------------------------------------------- the filter
def context(pos, theta, v1, v2, failed=None, obstacles=()) -> FilterContext:
    n = len(pos)
    values = {k: p.default for k, p in PARAMS.items()}
    return FilterContext(
        t=0.0,
        dt=0.01,
        pos=np.asarray(pos, dtype=float),
        theta=np.asarray(theta, dtype=float),
        vel=np.zeros((n, 2)),
        v1=np.asarray(v1, dtype=float),
        v2=np.asarray(v2, dtype=float),
        diameter=np.full(n, 0.5),
        params=values,
        v1_max=2.0,
        v2_max=4.0,
        accel_max=np.inf,
        known_failed=np.zeros(n, bool) if failed is None else np.asarray(failed),
        commanded=np.zeros(n, bool),
        obstacle_field=ObstacleField(tuple(obstacles)),
    )


def test_a_vehicle_alone_passes_unchanged_bit_for_bit() -> None:
    ctx = context([[0, 0], [20, 0]], [0.3, 1.0], [1.234567, 0.5], [0.123, -0.7])
    v1, v2, step = orca_commands(ORCAState(ctx), ctx)
    assert v1.tobytes() == ctx.v1.tobytes() and v2.tobytes() == ctx.v2.tobytes()
    assert not step.active.any()


def test_two_closing_vehicles_share_the_change_and_a_failed_one_is_left_alone() -> None:
    # Head-on 2 m apart at rest, both asking for 2 m/s at each other. Radii d/2 + E
    # = 0.35 m, R = 0.7 + margin 0.05 = 0.75 m, tau = 2 s: the relative velocity 0
    # is outside the cut-off circle of radius R / tau = 0.375 about (1, 0) m/s
    # (w = -(1, 0)), so u = (1 - 0.375) (1, 0) = (0.625, 0): each may close at half
    # of it, 0.3125 m/s. With the east one failed, only the west one is filtered and
    # takes all of it, 0.625 m/s.
    pos, theta = [[-1.0, 0.0], [1.0, 0.0]], [0.0, np.pi]
    ctx = context(pos, theta, [2.0, 2.0], [0.0, 0.0])
    v1, v2, step = orca_commands(ORCAState(ctx), ctx)
    assert step.active.all()
    np.testing.assert_allclose(v1, [0.3125, 0.3125], rtol=0, atol=1e-12)
    np.testing.assert_allclose(v2, [0.0, 0.0], rtol=0, atol=1e-12)
    ctx = context(pos, theta, [2.0, 2.0], [0.0, 0.0], failed=[False, True])
    alone, _, step = orca_commands(ORCAState(ctx), ctx)
    assert step.active.tolist() == [True, False] and alone[1] == 2.0
    assert alone[0] == pytest.approx(0.625, abs=1e-12)


# -------------------------------------------------------------- scenario level
@pytest.mark.slow
def test_head_on_vehicles_pass_without_contact() -> None:
    sets = ("safety.filter=orca", "recovery.strategy=none")
    bare = run_scenario(SAFETY / "head_on_swap.yaml", "recovery.strategy=none")[1]
    assert bare["collisions"]["vehicle_vehicle"] >= 1  # the counter works
    _, m = run_scenario(SAFETY / "head_on_swap.yaml", *sets)
    assert m["collisions"]["total"] == 0 and m["converged"]
    assert m["safety"]["filter"] == "orca" and m["safety"]["active_steps"] > 0
    assert m["min_distance"] >= 0.5 + 0.05


@pytest.mark.slow
def test_the_rings_of_eight_the_exact_one_a_deadlock() -> None:
    # ORCA's known deadlock: in the exactly symmetric ring every vehicle brakes
    # straight toward the centre (each pair's half-plane faces it head-on), and they
    # stop short of it, without contact. Jittered by 0.1 m, the ring swaps, slowly.
    sets = ("safety.filter=orca", "recovery.strategy=none")
    _, m = run_scenario(SAFETY / "circle_swap_8.yaml", *sets)
    assert m["collisions"]["total"] == 0 and not m["converged"]
    assert len(m["deadlocks"]) == 1 and len(m["deadlocks"][0]["vehicles"]) == 8
    _, m = run_scenario(SAFETY / "circle_swap_8_jittered.yaml", *sets, duration=24)
    assert m["collisions"]["total"] == 0 and m["converged"]
    assert not m["deadlocks"]


@pytest.mark.slow
def test_the_obstacle_field_is_crossed_without_contact() -> None:
    sets = ("safety.filter=orca", "recovery.strategy=none")
    _, m = run_scenario(SAFETY / "obstacle_field_random.yaml", *sets, duration=30)
    assert m["collisions"]["total"] == 0 and m["converged"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "fixed"),
    [
        ("safety/circle_swap_3_jittered", ["duration=3"]),
        ("safety/door", ["duration=3"]),
        (
            "failures/detect_uncontrolled_into_leader",
            ["duration=5", "sensing.delay=0.03", "recovery.strategy=none"],
        ),
    ],
)
def test_a_world_in_a_batch_is_its_run_alone(name, fixed, tmp_path) -> None:
    scenarios = [
        load_scenario(name, overrides=[*fixed, "safety.filter=orca", f"seed={s}"])
        for s in range(3)
    ]
    runs = assert_batch_is_alone(scenarios, tmp_path)
    assert any(r.info["safety"]["active_steps"] for r in runs)


# -------------------------------------------------------------- what a filter did
def test_the_episodes_of_constrained_vehicles_merge_short_gaps() -> None:
    # Two worlds of two vehicles; vehicle 1 of world 0 constrained at 0.00-0.02 s,
    # free at 0.03, again at 0.04 (a gap of 0.02 s < MERGE_GAP: one episode), free
    # from 0.30 s; vehicle 0 of world 1 from 0.10 s to the end.
    memory: dict = {}
    stats: list[dict] = [{}, {}]
    for k in range(40):
        t = round(0.01 * k, 2)
        active = np.zeros(4, dtype=bool)  # rows: world 0's 0 and 1, world 1's 0, 1
        active[1] = t < 0.3 and t != 0.03
        active[2] = t >= 0.1
        record_episodes(memory, stats, t, active, 2)
    assert stats[0]["constrained"] == [[1, 0.0, 0.3]]
    assert stats[1]["constrained"] == [[0, 0.1, None]]


def test_the_mask_of_a_run_from_its_episodes() -> None:
    run = SimpleNamespace(
        t=np.arange(5) * 0.1,
        n_vehicles=2,
        scenario=None,
        info={
            "safety": {"filter": "orca", "constrained": [[0, 0.1, 0.3], [1, 0.2, None]]}
        },
    )
    mask = constrained_mask(run)
    assert mask.astype(int).tolist() == [[0, 0], [1, 0], [1, 1], [0, 1], [0, 1]]
    assert filter_name(run) == "orca"
    run.info = {}
    assert constrained_mask(run) is None and filter_name(run) is None
