"""Static obstacles and collision counting.

Every obstacle type is a static pymunk shape that stops a vehicle driven into it and
counts one ``vehicle_obstacle`` contact episode; the distances used by avoidance
(:meth:`ObstacleField.nearest`) match hand-computed values; a collision event is one
contact onset of a pair (pymunk ``begin``), with its time and names in metrics.json.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import PAPER, collisions

from sandbox import load_scenario, simulate
from sandbox.model.obstacle_field import ObstacleField
from sandbox.run.metrics import compute_metrics
from sandbox.scenario import ObstacleSpec

D = 0.5  # vehicle diameter [m]


def rammer(obstacle: dict, schedule: list, duration: float = 4.0) -> dict:
    """One vehicle at the origin heading +x1, driven open loop by ``schedule``."""
    return {
        "name": "rammer",
        "duration": duration,
        "dt": 0.01,
        "vehicle": {"diameter": D},
        "vehicles": [
            {
                "name": "car",
                "pose": [0, 0, 0],
                "drive": {"type": "commands", "schedule": schedule},
            },
        ],
        "obstacles": [obstacle],
    }


# Each obstacle's face nearest to the car is the plane x1 = 2 (so the car stops with its
# centre at x1 = 2 - d/2 = 1.75).
OBSTACLES = {
    "circle": {"type": "circle", "name": "post", "center": [2.5, 0.0], "radius": 0.5},
    "box": {"type": "box", "name": "crate", "center": [3.0, 0.0], "size": [2.0, 3.0]},
    "rotated box": {
        "type": "box",
        "name": "crate",
        "center": [2.0 + math.sqrt(2), 0.0],
        "size": [2.0, 2.0],
        "angle": math.pi / 4,
    },  # a corner at x1 = 2
    "polygon": {
        "type": "polygon",
        "name": "rock",
        "points": [[2.0, -1.0], [4.0, -1.5], [4.0, 1.5], [2.0, 1.0]],
    },
    "wall": {
        "type": "wall",
        "name": "wall",
        "from": [2.1, -3.0],
        "to": [2.1, 3.0],
        "thickness": 0.2,
    },
}


@pytest.mark.parametrize("kind", sorted(OBSTACLES))
def test_a_vehicle_driven_into_an_obstacle_stops_and_counts_one_collision(kind):
    run = simulate(load_scenario(rammer(OBSTACLES[kind], [[0.0, 1.0, 0.0]])))
    m = compute_metrics(run)
    x_final = run.pose[-1, 0, 0]
    assert x_final == pytest.approx(
        2.0 - D / 2, abs=0.01
    )  # at the face, not through it
    assert np.max(run.pose[:, 0, 0]) < 2.0 - D / 2 + 0.01
    # it keeps pushing (v1 = 1 commanded) but no longer moves
    assert np.ptp(run.pose[-100:, 0, 0]) < 1e-3
    col = m["collisions"]
    assert (col["total"], col["vehicle_obstacle"], col["vehicle_vehicle"]) == (1, 1, 0)
    event = col["events"][0]
    assert event["a"] == "car" and event["b"] == OBSTACLES[kind]["name"]
    # contact at 1.75 m from the start at 1 m/s: t = 1.75 s (within a control period)
    assert event["t"] == pytest.approx(1.75, abs=0.02)


def test_contact_episodes_are_counted_once_each():
    # Push the wall, back off, push again: two contact onsets, two events.
    schedule = [[0.0, 1.0, 0.0], [2.5, -1.0, 0.0], [3.5, 1.0, 0.0]]
    run = simulate(load_scenario(rammer(OBSTACLES["wall"], schedule, duration=6.0)))
    events = compute_metrics(run)["collisions"]["events"]
    assert len(events) == 2
    assert events[0]["t"] == pytest.approx(1.75, abs=0.02)
    assert events[1]["t"] > 3.5


def test_vehicle_vehicle_collision_has_time_and_names():
    # Head-on at 1 m/s each from 3 m apart (centres): contact when 0.5 m apart, at
    # t = (3 - 0.5) / 2 = 1.25 s.
    doc = {
        "duration": 3.0,
        "vehicle": {"diameter": D},
        "vehicles": [
            {
                "name": "east",
                "pose": [0, 0, 0],
                "drive": {"type": "commands", "schedule": [[0, 1.0, 0]]},
            },
            {
                "name": "west",
                "pose": [3, 0, math.pi],
                "drive": {"type": "commands", "schedule": [[0, 1.0, 0]]},
            },
        ],
        "formation": {"law": "virtual"},
        "reference": {"type": "point", "position": [0, 5]},
    }
    m = compute_metrics(simulate(load_scenario(doc)))
    col = m["collisions"]
    assert (col["total"], col["vehicle_vehicle"], col["vehicle_obstacle"]) == (1, 1, 0)
    assert col["events"][0]["a"] == "east" and col["events"][0]["b"] == "west"
    assert col["events"][0]["t"] == pytest.approx(1.25, abs=0.02)
    assert m["min_distance"] == pytest.approx(D, abs=0.01)


# ------------------------------------------------------------- distances for avoidance
def field(*specs: ObstacleSpec) -> ObstacleField:
    return ObstacleField(tuple(specs))


def test_nearest_circle():
    # centre (3, 0), radius 1: from the origin the surface is 3 - 1 = 2 away, at (2, 0);
    # from (3, 4) it is 4 - 1 = 3 away, at (3, 0) + (0, 4)/4 * 1 = (3, 1).
    f = field(ObstacleSpec("circle", "c", center=(3.0, 0.0), radius=1.0))
    dist, point = f.nearest(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 0.5]]))
    np.testing.assert_allclose(dist[:, 0], [2.0, 3.0, -0.5])
    np.testing.assert_allclose(point[:2, 0], [[2.0, 0.0], [3.0, 1.0]])


def test_nearest_wall():
    # from (0, 2) to (4, 2), 0.2 thick (a capsule of radius 0.1):
    # (1, 0): foot (1, 2), 2 - 0.1 = 1.9 away, surface point (1, 1.9);
    # (-3, 6): nearest the end (0, 2), sqrt(9 + 16) - 0.1 = 4.9 away,
    #          surface point (0, 2) + (-3, 4)/5 * 0.1 = (-0.06, 2.08).
    f = field(
        ObstacleSpec("wall", "w", start=(0.0, 2.0), end=(4.0, 2.0), thickness=0.2)
    )
    dist, point = f.nearest(np.array([[1.0, 0.0], [-3.0, 6.0]]))
    np.testing.assert_allclose(dist[:, 0], [1.9, 4.9])
    np.testing.assert_allclose(point[:, 0], [[1.0, 1.9], [-0.06, 2.08]])


def test_nearest_box():
    # centre (0, 0), size 2 x 1: (3, 0) is 3 - 1 = 2 from the face x1 = 1, at (1, 0);
    # (2, 1.5) is nearest the corner (1, 0.5): sqrt(1 + 1) = 1.4142 away.
    f = field(ObstacleSpec("box", "b", center=(0.0, 0.0), size=(2.0, 1.0)))
    dist, point = f.nearest(np.array([[3.0, 0.0], [2.0, 1.5]]))
    np.testing.assert_allclose(dist[:, 0], [2.0, math.sqrt(2)])
    np.testing.assert_allclose(point[:, 0], [[1.0, 0.0], [1.0, 0.5]])


def test_nearest_rotated_box():
    # a 2 x 2 box turned by 45 degrees has its corners at distance sqrt(2) on the axes:
    # (3, 0) is 3 - sqrt(2) = 1.5858 from the corner (sqrt(2), 0).
    f = field(
        ObstacleSpec("box", "b", center=(0.0, 0.0), size=(2.0, 2.0), angle=math.pi / 4)
    )
    dist, point = f.nearest(np.array([[3.0, 0.0]]))
    np.testing.assert_allclose(dist[:, 0], [3.0 - math.sqrt(2)])
    np.testing.assert_allclose(point[:, 0], [[math.sqrt(2), 0.0]], atol=1e-12)


def test_nearest_polygon():
    # triangle (0,0), (4,0), (0,3): the hypotenuse is 3 x1 + 4 x2 = 12.
    # (2, 2): |6 + 8 - 12| / 5 = 0.4 outside,
    #         foot (2, 2) - 0.4 (0.6, 0.8) = (1.76, 1.68);
    # (1, 1): inside, 1 from each of the three sides -> -1;
    # (-1, -1): nearest the vertex (0, 0), sqrt(2) away.
    f = field(ObstacleSpec("polygon", "p", points=((0.0, 0.0), (4.0, 0.0), (0.0, 3.0))))
    dist, point = f.nearest(np.array([[2.0, 2.0], [1.0, 1.0], [-1.0, -1.0]]))
    np.testing.assert_allclose(dist[:, 0], [0.4, -1.0, math.sqrt(2)])
    np.testing.assert_allclose(point[[0, 2], 0], [[1.76, 1.68], [0.0, 0.0]], atol=1e-12)


def test_nearest_matches_the_physics_for_every_type():
    # The avoidance distance of each obstacle equals pymunk's own point query of the
    # static shapes the vehicles really hit (over a grid of points around them).
    import pymunk

    from sandbox.physics.world import World

    for obstacle in OBSTACLES.values():
        scenario = load_scenario(rammer(obstacle, [[0.0, 0.0, 0.0]]))
        spec = scenario.obstacles[0]
        world = World(scenario.vehicles, scenario.obstacles)
        grid = np.stack(np.meshgrid(np.linspace(-1, 6, 15), np.linspace(-3, 3, 13)), -1)
        pts = grid.reshape(-1, 2)
        dist, _ = ObstacleField((spec,)).nearest(pts)
        for p, d in zip(pts, dist[:, 0], strict=True):
            q = world.space.point_query_nearest(tuple(p), 20.0, pymunk.ShapeFilter())
            if q.shape is None or q.shape.body is not world.space.static_body:
                continue
            assert d == pytest.approx(q.distance, abs=1e-6), (spec.type, p)


def test_the_collision_helper_asserts_a_count_in_two_lines():
    assert collisions(PAPER / "fig12_no_recovery.yaml", duration=4)["total"] >= 1
    assert collisions(PAPER / "fig14_discontinuous_beta5.yaml")["total"] == 0
