"""The range sensor: beam geometry, ordering, noise, rate, bad input, sensed recovery.

Distances are checked against hand-computed geometry: a vehicle at the origin facing
+x1 and a wall whose face is at x1 = 2.9 m reads 2.9 m straight ahead and
2.9 / cos(a) along a beam at angle a.
"""

from __future__ import annotations

import math
import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import SCENARIOS, write_yaml

from sandbox import Simulation, load_scenario
from sandbox.behaviour.ranges import beam_layout
from sandbox.errors import SandboxWarning, ScenarioError
from sandbox.loop.plan import structure_key
from sandbox.model.obstacle_field import ObstacleField
from sandbox.physics.ranges import HIT_OBSTACLE, HIT_VEHICLE, RangeCaster
from sandbox.physics.world import World


def scene(
    obstacles: list[dict[str, Any]] | None = None,
    others: list[list[float]] | None = None,
    **rng: Any,
) -> dict[str, Any]:
    """One sensing vehicle at the origin facing +x1, still; others parked."""
    vehicles = [
        {
            "name": "eye",
            "pose": [0, 0, 0],
            "drive": {"type": "commands", "schedule": [[0, 0, 0]]},
        }
    ]
    for k, pose in enumerate(others or []):
        vehicles.append(
            {
                "name": f"o{k}",
                "pose": pose,
                "drive": {"type": "commands", "schedule": [[0, 0, 0]]},
            }
        )
    return {
        "duration": 0.1,
        "formation": {"law": "virtual"},
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": vehicles,
        "obstacles": obstacles or [],
        "sensors": {"range": {"max_range": 5.0, **rng}},
    }


def first_scan(doc: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    sim = Simulation(load_scenario(doc))
    obs = sim.observe()
    return obs.ranges[0], obs.beam_angles[0]


WALL = {"type": "wall", "from": [3, -10], "to": [3, 10], "thickness": 0.2}


def test_a_wall_at_a_known_distance() -> None:
    ranges, angles = first_scan(scene([WALL], beams=9, fov=1.0))
    # the face at x1 = 3 - 0.1 = 2.9 m; along angle a: 2.9 / cos(a)
    np.testing.assert_allclose(ranges, 2.9 / np.cos(angles), rtol=1e-9)
    np.testing.assert_allclose(angles, np.linspace(-0.5, 0.5, 9))


def test_a_box_on_the_left_and_nothing_on_the_right() -> None:
    box = {"type": "box", "center": [0, 2], "size": [1, 1]}
    ranges, angles = first_scan(scene([box], beams=3, fov=math.pi))
    # beams from -pi/2 (right) to +pi/2 (left); the box's near face at x2 = 1.5 m
    np.testing.assert_allclose(angles, [-math.pi / 2, 0.0, math.pi / 2])
    assert ranges[0] == 5.0 and ranges[1] == 5.0  # nothing: max_range
    assert ranges[2] == pytest.approx(1.5, abs=1e-9)


def test_another_vehicle_and_not_the_own_disc() -> None:
    ranges, _ = first_scan(scene(others=[[2, 0, 0]], beams=4))
    # full turn: -pi, -pi/2, 0, pi/2; the other disc (d = 0.5 m) at 2 - 0.25 m ahead
    assert ranges[2] == pytest.approx(1.75, abs=1e-9)
    assert list(ranges[[0, 1, 3]]) == [5.0, 5.0, 5.0]  # its own disc is not seen


def test_beam_layout_orders_right_to_left() -> None:
    assert beam_layout(1, 2.0) == (0.0, 0.0)
    first, step = beam_layout(5, math.pi)
    assert first == -math.pi / 2 and step == pytest.approx(math.pi / 4)
    first, step = beam_layout(8, 2 * math.pi)
    assert first == -math.pi and step == pytest.approx(math.pi / 4)


def test_both_casting_methods_agree() -> None:
    rng = np.random.default_rng(3)
    obstacles = [
        WALL,
        {"type": "circle", "center": [-2, 1], "radius": 0.4},
        {"type": "box", "center": [0.5, -2.5], "size": [1, 0.4], "angle": 0.3},
        {"type": "polygon", "points": [[-1, 3], [0, 3.2], [-0.5, 4]]},
    ]
    others = [[float(x), float(y), float(a)] for x, y, a in rng.uniform(-4, 2, (12, 3))]
    others = [p for p in others if math.hypot(p[0], p[1]) > 0.6]
    sc = load_scenario(scene(obstacles, others[:6], beams=90))
    field = ObstacleField(sc.obstacles)
    out = []
    for method in ("prefilter", "space"):
        world = World(sc.vehicles, sc.obstacles)
        state = world.read_state()
        n = len(sc.vehicles)
        first, step = beam_layout(90, 2 * math.pi)
        scan = RangeCaster(world, field, method).cast(
            state.pos,
            state.theta,
            np.arange(n),
            np.full(n, first),
            np.full(n, step),
            np.full(n, 90),
            np.full(n, 5.0),
        )
        out.append(scan)
    a, b = out
    np.testing.assert_array_equal(a.dist, b.dist)
    np.testing.assert_array_equal(a.kind, b.kind)
    np.testing.assert_array_equal(a.index, b.index)
    assert (a.kind == HIT_OBSTACLE).sum() > 20 and (a.kind == HIT_VEHICLE).sum() > 20


def test_noise_is_seeded_and_leaves_the_motion_alone() -> None:
    doc = scene([WALL], beams=16, noise=0.05)
    a, _ = first_scan(doc)
    b, _ = first_scan(doc)
    c, _ = first_scan({**doc, "seed": 1})
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    clean, _ = first_scan(scene([WALL], beams=16))
    hit = clean < 5.0
    assert np.all(np.abs(a[hit] - clean[hit]) < 0.3) and np.any(a[hit] != clean[hit])
    np.testing.assert_array_equal(a[~hit], 5.0)  # a miss reads max_range


def moving(rate: float | None) -> dict[str, Any]:
    doc = scene([WALL], beams=3, fov=1.0)
    doc["vehicles"][0]["drive"]["schedule"] = [[0, 1.0, 0]]
    doc["duration"] = 0.5
    if rate is not None:
        doc["sensors"]["range"]["rate"] = rate
    return doc


def test_a_scan_is_held_until_the_next_at_the_rate() -> None:
    run = Simulation(load_scenario(moving(10.0))).run()
    ahead = run.ranges[:, 0, 1]
    # 10 Hz with dt = 0.01 s: a new reading every 10 samples
    changes = np.flatnonzero(np.diff(ahead) != 0) + 1
    assert len(changes) >= 3
    assert np.all(changes % 10 == 0)
    every = Simulation(load_scenario(moving(None))).run().ranges[:, 0, 1]
    assert np.all(np.diff(every[5:]) < 0)  # a new reading each period
    # the reading is the distance to the wall's face from the pose of the scan
    x = run.pose[:, 0, 0]
    scanned = np.floor(run.t * 10 + 1e-9) * 10
    np.testing.assert_allclose(ahead, 2.9 - x[scanned.astype(int)], atol=1e-9)


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"beams": 0}, "sensors.range.beams: out of range (got 0"),
        ({"beams": 1025}, "expected a whole number from 1 to 1024"),
        ({"fov": 0}, "sensors.range.fov: must be at least 0.001 (got 0"),
        ({"fov": 7}, "sensors.range.fov: must be at most 6.28319 (got 7"),
        ({"max_range": 0}, "sensors.range.max_range: must be greater than 0"),
        ({"max_range": -1}, "sensors.range.max_range:"),
        ({"noise": -0.1}, "sensors.range.noise: must be at least 0 (got -0.1"),
        ({"rate": 0}, "sensors.range.rate: must be greater than 0 (got 0"),
        ({"beam": 3}, "sensors.range.beam: unknown key"),
    ],
)
def test_bad_input_is_one_line_with_file_line_and_field(
    tmp_path: Path, bad: dict[str, Any], message: str
) -> None:
    doc = scene([WALL])
    doc["sensors"] = {"range": bad}
    path = write_yaml(tmp_path, doc)
    line = next(
        i + 1
        for i, row in enumerate(path.read_text().splitlines())
        if row.strip().startswith(f"{next(iter(bad))}:")
    )
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    text = str(err.value)
    assert len(text.splitlines()) == 1
    assert text.startswith(f"{path}:{line}: ")
    assert message in text


def test_a_vehicle_sensor_is_merged_over_the_fleet_one(tmp_path: Path) -> None:
    doc = scene([WALL], beams=8)
    doc["vehicles"][0]["sensors"] = {"range": {"fov": 1.0}}
    sc = load_scenario(doc)
    (own,) = sc.range_specs()
    assert (own.beams, own.fov, own.max_range) == (8, 1.0, 5.0)
    assert load_scenario(sc.to_dict()).range_specs() == [own]
    doc["vehicles"][0]["sensors"] = {"range": {"fov": -1}}
    with pytest.raises(ScenarioError, match=re.escape("vehicles[0].sensors.range.fov")):
        load_scenario(doc)


def test_sensed_obstacles_need_a_sensor() -> None:
    doc = scene([WALL])
    del doc["sensors"]
    doc["recovery"] = {"strategy": "continuous", "obstacles": "sensed"}
    with pytest.raises(ScenarioError, match="recovery.obstacles: sensed obstacles"):
        load_scenario(doc)


def test_observation_obstacles_from_the_map() -> None:
    box = {"type": "box", "name": "crate", "center": [0, 2], "size": [1, 1]}
    far = {"type": "circle", "name": "far", "center": [20, 0], "radius": 1}
    obs = Simulation(load_scenario(scene([box, far], beams=4))).observe()
    near = obs.obstacles
    assert near.name == ("crate",) and near.kind == ("box",)
    assert near.distance[0] == pytest.approx(1.5)
    np.testing.assert_allclose(near.point[0], [0, 1.5])
    assert near.of(0).name == ("crate",)


def test_contexts_see_the_ranges_and_sensors_are_a_structure() -> None:
    sim = Simulation(load_scenario(scene([WALL], beams=5, fov=1.0)))
    ctx = sim.law_context(0.0, None)
    assert ctx.ranges.shape == (1, 5) and ctx.beam_angles.shape == (1, 5)
    other = load_scenario(scene([WALL], beams=5, fov=1.0), overrides=["seed=3"])
    assert structure_key(sim.scenario) == structure_key(other)  # batched together
    own = scene([WALL])
    own["vehicles"][0]["sensors"] = own.pop("sensors")  # a vehicle's own only
    assert structure_key(load_scenario(own)) != structure_key(sim.scenario)
    plain = scene([WALL])
    del plain["sensors"]
    sim = Simulation(load_scenario(plain))
    assert sim.observe().ranges is None and sim.law_context(0.0, None).ranges is None


def box_run(obstacles: str, strategy: str = "continuous") -> Any:
    """A vehicle driving along x1 at 1 m/s at a crate covering x2 in [0, 0.6] m."""
    doc = {
        "duration": 14.0,
        "vehicle": {"v1_max": 1.5, "max_accel": 3.0, "v2_max": 6.0},
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "vehicles": [{"name": "solo", "pose": [0, 0, 0]}],
        "recovery": {
            "strategy": strategy,
            "beta": 2.5,
            "R": "3d",
            "r": "1.5d",
            "leader_avoids": True,
            "obstacles": obstacles,
        },
        "obstacles": [{"type": "box", "center": [6, 0.3], "size": [0.6, 0.6]}],
        "sensors": {"range": {"beams": 72, "max_range": 2.0}},
    }
    return Simulation(load_scenario(doc)).run()


@pytest.mark.slow
def test_sensed_recovery_avoids_a_box() -> None:
    with pytest.warns(SandboxWarning, match="does nothing here"):
        hit = box_run("sensed", strategy="none")  # beta, r: the continuous strategy's
    assert any(e.kind == "vehicle_obstacle" for e in hit.events)  # the counter works
    run = box_run("sensed")
    assert not run.events
    assert run.pose[-1, 0, 0] > 11.0  # past the box, back on the line
    assert (run.mode == 1).any()


def test_without_sensors_the_outputs_keep_their_members(tmp_path: Path) -> None:
    from sandbox.cli import main

    out = tmp_path / "run"
    path = SCENARIOS / "failures" / "obstacle_field.yaml"
    assert main(["run", str(path), "--out", str(out), "--duration", "0.5"]) == 0
    with zipfile.ZipFile(out / "run.npz") as zf:
        names = {i.filename for i in zf.infolist()}
    assert "ranges.npy" not in names and "beam_angles.npy" not in names
    text = (out / "scenario.yaml").read_text()
    assert "sensors" not in text and "obstacles: map" not in text
    # the same scenario with a sensor: the same motion (map recovery), scans kept
    sensed = tmp_path / "sensed"
    sets = ["--set", "sensors={range: {beams: 8}}", "--duration", "0.5"]
    assert main(["run", str(path), "--out", str(sensed), *sets]) == 0
    from sandbox import load_run

    a, b = load_run(out), load_run(sensed)
    np.testing.assert_array_equal(a.pose, b.pose)
    assert b.ranges.shape == (len(b.t), 4, 8) and a.ranges is None


def test_the_environments_observe_the_ranges() -> None:
    pytest.importorskip("gymnasium")
    from sandbox.envs import VehicleEnv

    doc = {
        "duration": 0.5,
        "vehicle": {"v1_max": 1.0, "v2_max": 2.0},
        "formation": {"law": "fixed"},
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [
            {"name": "lead", "pose": [0, 0, 0], "leader": True},
            {"name": "eye", "pose": [-1, 1, 0], "offset": [-1, 1]},
        ],
        "obstacles": [WALL],
        "sensors": {"range": {"beams": 8, "max_range": 5.0}},
    }
    env = VehicleEnv(doc, "eye", observe=("neighbours", "ranges"), neighbours=1)
    box = env.observation_space
    assert box.shape == (7 + 6 + 8,)
    np.testing.assert_array_equal(box.low[-8:], 0.0)
    np.testing.assert_array_equal(box.high[-8:], 5.0)
    obs, _ = env.reset(seed=0)
    assert box.contains(obs)
    # beam 4 of 8 points ahead (-pi + 4 pi/4 = 0): the wall's face 2.9 m + 1 m away
    assert obs[7 + 6 + 4] == pytest.approx(3.9, abs=1e-5)
    alone = VehicleEnv(doc, "eye", observe=("ranges",))
    assert alone.observation_space.shape == (7 + 8,)
    del doc["sensors"]
    with pytest.raises(ValueError, match="no range sensor"):
        VehicleEnv(doc, "eye", observe=("neighbours", "ranges"))
    with pytest.raises(ValueError, match="observe: expected some of"):
        VehicleEnv(doc, "eye", observe=("lidar",))


def test_the_sensed_point_of_a_wall_is_its_foot_and_memory_holds_it() -> None:
    from sandbox.behaviour.ranges import RangeSensor
    from sandbox.scenario import RangeSpec

    sc = load_scenario(scene([WALL], beams=7, fov=1.0))
    field = ObstacleField(sc.obstacles)
    sensor = RangeSensor(
        [RangeSpec(beams=7, fov=1.0, max_range=5.0, memory=1.0)],
        World(sc.vehicles, sc.obstacles),
        field,
        seed=0,
    )
    # beams at -0.5 ... 0.5 rad: hits on the face x1 = 2.9 m at 2.9 tan(a) sideways;
    # the outline's nearest point to the origin is the foot (2.9, 0), not a hit
    sensor.update(0.0, np.array([[0.0, 0.3]]), np.array([0.1]))
    np.testing.assert_allclose(sensor.field.point, [[2.9, 0.3]], atol=1e-9)
    assert sensor.field.order.tolist() == [0]
    # turned away (nothing in view): the point is kept for memory = 1 s, then dropped
    away = np.array([math.pi])
    sensor.update(0.5, np.array([[0.0, 0.3]]), away)
    np.testing.assert_allclose(sensor.field.point, [[2.9, 0.3]], atol=1e-9)
    sensor.update(1.5, np.array([[0.0, 0.3]]), away)
    assert sensor.field.empty
