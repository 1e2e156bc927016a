"""Physical invariants of the pymunk world (and of a whole run)."""

import math

import numpy as np
import pytest
from helpers import PAPER, run_scenario

from sandbox.model.dynamics import unicycle_step
from sandbox.model.flatness import CHI_REST
from sandbox.physics.world import World
from sandbox.scenario import ObstacleSpec, VehicleSpec

H = 0.01  # control period [s]
SUBSTEPS = 4


def drive(world: World, v1: float, v2: float, steps: int, t0: float = 0.0):
    """Apply constant commands to every vehicle for ``steps`` periods; return states."""
    states = [world.read_state()]
    n = len(world.bodies)
    for k in range(steps):
        s = states[-1]
        world.write_commands(s.theta, np.full(n, v1), np.full(n, v2), H)
        world.step(H, SUBSTEPS, t0 + k * H)
        states.append(world.read_state())
    return states


def test_zero_command_gives_zero_motion() -> None:
    poses = [(0.0, 0.0, 0.3), (1.0, 2.0, -2.0), (-3.0, 0.5, 4.0)]
    world = World(tuple(VehicleSpec(f"v{i}", p) for i, p in enumerate(poses)), ())
    states = drive(world, 0.0, 0.0, 200)
    np.testing.assert_array_equal(states[-1].pos, [p[:2] for p in poses])
    np.testing.assert_array_equal(states[-1].theta, [p[2] for p in poses])
    np.testing.assert_array_equal(states[-1].vel, np.zeros((3, 2)))
    assert world.events == []


def test_no_lateral_slip_on_an_arc() -> None:
    # v1 = 1 m/s, v2 = 0.5 rad/s for 4 s: a 2 m-radius arc. During each period the body
    # moves along the mean heading (x3(k) + x3(k+1))/2, the chord of eq. (1)'s arc: no
    # lateral velocity. Relative to the heading at the end of the period the offset is
    # v2 h / 2, i.e. a lateral component v1 sin(v2 h/2) = 2.5 mm/s, no more.
    world = World((VehicleSpec("a", (0.0, 0.0, 0.3)),), ())
    states = drive(world, 1.0, 0.5, 400)
    lateral_mid, lateral_end = [], []
    for before, after in zip(states[1:-1], states[2:], strict=True):
        mid = 0.5 * (before.theta[0] + after.theta[0])
        vx, vy = after.vel[0]
        lateral_mid.append(-math.sin(mid) * vx + math.cos(mid) * vy)
        end = after.theta[0]
        lateral_end.append(-math.sin(end) * vx + math.cos(end) * vy)
    assert np.max(np.abs(lateral_mid)) < 1e-9
    assert np.max(np.abs(lateral_end)) < 1.0 * math.sin(0.5 * H / 2) + 1e-9
    speed = np.hypot(*states[-1].vel[0])
    assert speed == pytest.approx(1.0, abs=1e-9)


def test_arc_matches_open_loop_unicycle() -> None:
    # The same arc by eq. (1): each period's motion is the unicycle's from the pose read
    # at its start (to about v1 h * v2 h / 4 = 1.25e-5 m: the heading is integrated in
    # substeps), and after 4 s the physics is within a centimetre of the closed form
    # (the only drift is the start-up lag of one substep from rest: 2.5 mm along the
    # track and v2 h / 4 = 1.25 mrad of heading).
    pose0 = np.array([[0.0, 0.0, 0.3]])
    world = World((VehicleSpec("a", tuple(pose0[0])),), ())
    states = drive(world, 1.0, 0.5, 400)
    one_step = [
        np.hypot(
            *(
                unicycle_step(
                    np.array([[*a.pos[0], a.theta[0]]]),
                    np.array([1.0]),
                    np.array([0.5]),
                    H,
                )[0, :2]
                - b.pos[0]
            )
        )
        for a, b in zip(states[1:-1], states[2:], strict=True)
    ]
    assert max(one_step) < 2e-5
    expected = unicycle_step(pose0, np.array([1.0]), np.array([0.5]), 4.0)[0]
    end = states[-1]
    assert np.hypot(*(end.pos[0] - expected[:2])) < 0.01
    assert end.theta[0] == pytest.approx(expected[2], abs=0.002)


def test_equal_commands_keep_distances() -> None:
    # Same heading and the same (v1, v2): every vehicle traces the same arc, translated.
    poses = [(0.0, 0.0, 1.0), (1.5, 0.0, 1.0), (0.0, -2.0, 1.0), (3.0, 3.0, 1.0)]
    world = World(tuple(VehicleSpec(f"v{i}", p) for i, p in enumerate(poses)), ())
    states = drive(world, 1.2, 0.3, 500)

    def distances(pos: np.ndarray) -> np.ndarray:
        i, j = np.triu_indices(len(pos), 1)
        return np.hypot(*(pos[i] - pos[j]).T)

    d0 = distances(states[0].pos)
    worst = max(np.max(np.abs(distances(s.pos) - d0)) for s in states)
    assert worst < 1e-9
    assert np.hypot(*(states[-1].pos[0] - states[0].pos[0])) > 3.0  # it did move


@pytest.mark.parametrize("speed", [0.5, 1.0, 5.0])
def test_vehicle_driven_into_a_wall_stops_at_it(speed: float) -> None:
    # Wall x1 = 2 m, 0.1 m thick: its face is at 1.95 m; the vehicle's radius is
    # 0.25 m, so its centre must stop at 1.95 - 0.25 = 1.70 m (pymunk tolerates 2 mm
    # of overlap).
    wall = ObstacleSpec(
        "wall", "wall", start=(2.0, -2.0), end=(2.0, 2.0), thickness=0.1
    )
    world = World((VehicleSpec("a", (0.0, 0.0, 0.0), diameter=0.5),), (wall,))
    steps = int(round(2.0 / speed / H)) + 300  # reach the wall, then push for 3 s
    end = drive(world, speed, 0.0, steps)[-1]
    assert end.pos[0, 0] == pytest.approx(1.70, abs=0.003)
    assert end.pos[0, 1] == pytest.approx(0.0, abs=1e-9)
    assert [(e.a, e.b, e.kind) for e in world.events] == [
        ("a", "wall", "vehicle_obstacle")
    ]
    # the contact begins when the vehicle arrives, (1.70 m at `speed`), not before
    assert world.events[0].t == pytest.approx(1.70 / speed, abs=2 * H)


def test_head_on_vehicles_collide_once() -> None:
    a = VehicleSpec("a", (0.0, 0.0, 0.0))
    b = VehicleSpec("b", (3.0, 0.0, math.pi))
    world = World((a, b), ())
    end = drive(world, 1.0, 0.0, 300)[-1]
    # both push with equal motors: they stop touching (centres one diameter apart)
    assert np.hypot(*(end.pos[0] - end.pos[1])) == pytest.approx(0.5, abs=0.003)
    assert [(e.a, e.b, e.kind) for e in world.events] == [("a", "b", "vehicle_vehicle")]


def test_wall_collision_counted_in_a_run(tmp_path) -> None:
    doc = {
        "duration": 4.0,
        "vehicles": [
            {
                "name": "cart",
                "pose": [0, 0, 0],
                "drive": {"type": "commands", "schedule": [[0, 1.0, 0.0]]},
            }
        ],
        "obstacles": [{"type": "wall", "name": "wall", "from": [2, -2], "to": [2, 2]}],
    }
    run, metrics = run_scenario(doc)
    assert metrics["collisions"]["total"] == 1
    assert metrics["collisions"]["vehicle_obstacle"] == 1
    assert metrics["collisions"]["events"][0]["b"] == "wall"
    assert run.pose[-1, 0, 0] == pytest.approx(1.70, abs=0.003)


def test_commanded_limits_are_never_exceeded() -> None:
    # The rotating platoon with its followers started 3.6 m and 4.2 m from their slots,
    # facing away from them, so that the report's gains ask for far more than the limits
    # (2 m/s, 3 rad/s, 10 m/s^2).
    run, metrics = run_scenario(
        PAPER / "rotating_circle.yaml",
        "vehicles[1].pose=[1, -3, 3.14]",
        "vehicles[2].pose=[9, -4, 0]",
        duration=6.0,
    )
    assert metrics["status"] == "ok"
    v1, v2 = run.cmd[..., 0], run.cmd[..., 1]
    chi_speed = np.hypot(run.chi[..., 0], run.chi[..., 1])
    assert v1.max() == pytest.approx(2.0)  # the limit is reached ...
    assert np.all(v1 <= 2.0 + 1e-12)  # ... and never exceeded
    assert np.abs(v2).max() == pytest.approx(3.0)
    assert np.all(np.abs(v2) <= 3.0 + 1e-12)
    dchi = np.hypot(*np.diff(run.chi, axis=0).transpose(2, 0, 1))
    assert dchi.max() == pytest.approx(10.0 * H)
    assert np.all(dchi <= 10.0 * H + 1e-12)
    # eq. (5): |v1| = |chi|; at rest (|chi| < CHI_REST) the heading is held and v1 is
    # chi's component along it, never more than |chi|
    moving = chi_speed >= CHI_REST
    assert moving.any() and (~moving).any()
    np.testing.assert_allclose(np.abs(v1[moving]), chi_speed[moving], atol=1e-12)
    assert np.all(np.abs(v1[~moving]) <= chi_speed[~moving] + 1e-12)
    # the bodies obey too: measured speed never above v1_max (plus the motor's lag)
    step_speed = np.hypot(*np.diff(run.pose[..., :2], axis=0).transpose(2, 0, 1)) / H
    assert step_speed.max() <= 2.0 + 1e-6
