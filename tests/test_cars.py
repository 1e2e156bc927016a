"""Cars in the loop: the keys, the limits they keep, the record, the batch.

A car (``model: bicycle``) is driven through the same velocity constraints as a
unicycle with the turn rate ``v1 tan(delta) / L``; every command it executes keeps
``|delta| <= max_steer``, the steering rate and ``v2 = 0`` at rest.
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings

import numpy as np
import pytest
from helpers import run_scenario

from sandbox import Simulation, load_run, load_scenario
from sandbox.errors import SandboxWarning, ScenarioError
from sandbox.model.bicycle import min_turning_radius

#: A small car: d = 0.5 m, wheelbase 2 d, max_steer 0.5 rad (least radius 1.83 m).
CAR = {
    "model": "bicycle",
    "wheelbase": 1.0,
    "max_steer": 0.5,
    "v1_max": 2.0,
    "max_accel": 4.0,
}


def circle_platoon(model: str = "bicycle", **vehicle) -> dict:
    """Three vehicles on a circle of radius 5 m under the rotating virtual law."""
    return {
        "duration": 8.0,
        "vehicle": {**CAR, "model": model, **vehicle},
        "reference": {"type": "circle", "radius": 5.0, "speed": 1.0},
        "formation": {"law": "virtual", "rotate": True},
        "vehicles": [
            {"name": "lead", "pose": [5, 0, 1.5708], "leader": True},
            {"name": "red", "pose": [6, -1, 1.5708], "offset": [-1, -1]},
            {"name": "green", "pose": [4, -1, 1.5708], "offset": [-1, 1]},
        ],
    }


def test_every_command_a_car_executes_is_one_it_can() -> None:
    run, _ = run_scenario(circle_platoon(max_steer_rate=5.0))
    steer, v1, v2 = run.steer, run.cmd[..., 0], run.cmd[..., 1]
    assert steer.shape == (len(run.t), 3)
    assert np.abs(steer).max() <= 0.5  # never beyond max_steer
    # the rate limit: 5 rad/s over 0.01 s is 0.05 rad a period at most, and binds
    rate = np.abs(np.diff(steer, axis=0))
    assert rate.max() <= 0.05 + 1e-12 and np.count_nonzero(rate > 0.05 - 1e-12)
    # the turn rate is the car's: v1 tan(delta) / L
    np.testing.assert_allclose(v2, v1 * np.tan(steer) / 1.0, rtol=1e-12, atol=1e-15)
    # and the platoon holds the circle (least radius 1.83 m < 4 m) as unicycles do:
    # the followers' 5.65 cm is eq. (12)'s error of the rotating slots
    uni, _ = run_scenario(circle_platoon("unicycle"))
    late = run.t > 6.0
    np.testing.assert_allclose(
        run.formation_error[late], uni.formation_error[late], atol=1e-3
    )


def test_a_car_at_rest_does_not_turn_where_a_unicycle_does() -> None:
    # A target behind the vehicle: the unicycle turns in place first, the car drives.
    doc = {
        "duration": 1.0,
        "reference": {"type": "point", "position": [-3, 0]},
        "vehicle": {**CAR, "model": "unicycle", "v2_max": 3.0},
        "vehicles": [{"name": "red", "pose": [0, 0, 0]}],
    }
    uni, _ = run_scenario(doc)
    car, _ = run_scenario(doc, "vehicle.model=bicycle")
    slow = uni.cmd[:, 0, 0] < 1e-3
    assert np.abs(uni.cmd[slow, 0, 1]).max() > 1.0  # the unicycle spins at rest
    at_rest = car.cmd[:, 0, 0] == 0.0
    assert at_rest.any() and np.all(car.cmd[at_rest, 0, 1] == 0.0)
    assert car.cmd[:, 0, 0].max() > 0.5  # the car drives to turn


#: One car driven open loop: 1 m/s and 5 rad/s asked from t = 0, 0 rad/s from 4 s.
FULL_LOCK = {
    "duration": 6.0,
    "reference": {"type": "point", "position": [0, 0]},
    "vehicle": CAR,
    "vehicles": [
        {
            "name": "red",
            "pose": [0, 0, 0],
            "drive": {"type": "commands", "schedule": [[0, 1.0, 5.0], [4, 1.0, 0]]},
        }
    ],
}


def test_an_open_loop_car_at_full_lock_turns_on_its_least_radius() -> None:
    # Asked 1 m/s and 5 rad/s (a unicycle's radius 0.2 m), the car steers to
    # max_steer = 0.5 rad and drives a circle of radius 1 / tan(0.5) = 1.8305 m.
    run, _ = run_scenario({**FULL_LOCK, "duration": 3.9})
    radius = float(min_turning_radius(1.0, 0.5))
    centre = np.array([0.0, radius])  # a left turn from the origin heading +x1
    later = run.t > 1.0  # after the drive's acceleration
    dist = np.hypot(*(run.pose[later, 0, :2] - centre).T)
    np.testing.assert_allclose(dist, radius, atol=0.01)
    assert np.all(run.steer[later, 0] == 0.5)


def test_metrics_report_the_time_at_the_steering_limit() -> None:
    # At full lock from t = 0 to 4 s, straight from 4 s to 6 s: 4 s of 6 at the limit.
    _, m = run_scenario(FULL_LOCK)
    block = m["vehicles"]["red"]["steering"]
    assert block["saturated_time"] == pytest.approx(4.0, abs=0.011)
    assert block["saturated_fraction"] == pytest.approx(4.0 / 6.0, abs=0.002)
    assert block["max_abs"] == 0.5 and block["max_steer"] == 0.5
    _, m = run_scenario(circle_platoon("unicycle"), duration=1.0)
    assert all("steering" not in v for v in m["vehicles"].values())


def test_the_steering_angle_is_saved_and_loaded_with_the_run(tmp_path) -> None:
    from helpers import write_yaml

    from sandbox.cli import main

    path = write_yaml(tmp_path, {**circle_platoon(), "duration": 1.0})
    assert main(["run", str(path), "--out", str(tmp_path / "car")]) == 0
    car = load_run(tmp_path / "car")
    alone = Simulation(load_scenario(path)).run()
    assert car.steer.shape == (101, 3) and np.array_equal(car.steer, alone.steer)
    doc = {**circle_platoon("unicycle"), "duration": 1.0}
    uni = write_yaml(tmp_path, doc, "u.yaml")
    assert main(["run", str(uni), "--out", str(tmp_path / "uni")]) == 0
    assert load_run(tmp_path / "uni").steer is None  # a run without cars as before


def test_a_mixed_world_records_nan_for_its_unicycles() -> None:
    doc = circle_platoon()
    doc["vehicles"][0]["model"] = "unicycle"
    run, _ = run_scenario(doc, duration=1.0)
    assert np.isnan(run.steer[:, 0]).all() and np.isfinite(run.steer[:, 1:]).all()


def test_a_world_in_a_batch_is_byte_for_byte_its_single_run() -> None:
    # Cars and unicycles, several seeds and a sweep over the model: one loop.
    docs = [
        circle_platoon("bicycle"),
        circle_platoon("unicycle"),
        {**circle_platoon("bicycle", max_steer=0.3), "seed": 3},
        {**circle_platoon("bicycle", max_steer_rate=1.0), "seed": 5},
    ]
    scenarios = [load_scenario({**d, "duration": 2.0}) for d in docs]
    sim = Simulation.stacked(scenarios)  # one structure: the model is per row
    batched = sim.run_all()
    for sc, got in zip(scenarios, batched, strict=True):
        alone = Simulation(sc).run()
        for name in ("pose", "cmd", "chi", "target", "mode"):
            assert np.array_equal(getattr(got, name), getattr(alone, name)), name
        if alone.steer is None:
            assert got.steer is None
        else:
            assert np.array_equal(got.steer, alone.steer, equal_nan=True)


def test_unicycles_are_untouched_by_cars_in_other_worlds() -> None:
    # The unicycle world's commands with and without a car world beside it.
    uni = load_scenario({**circle_platoon("unicycle"), "duration": 2.0})
    car = load_scenario({**circle_platoon("bicycle"), "duration": 2.0})
    pair = Simulation.stacked([uni, car]).run_all()
    alone = Simulation(uni).run()
    assert np.array_equal(pair[0].cmd, alone.cmd)
    assert not np.array_equal(pair[1].cmd, alone.cmd)  # the car does differ


BAD = [
    (
        {"vehicle": {"model": "bicycle"}},
        "vehicles[0].wheelbase: required with model: bicycle",
    ),
    ({"vehicle": {"model": "car"}}, "vehicle.model: unknown model value (got 'car'"),
    (
        {"vehicle": {"model": "bicycle", "wheelbase": 1, "max_steer": 1.6}},
        "vehicle.max_steer: must be less than pi/2 (got 1.6",
    ),
    (
        {"vehicle": {"model": "bicycle", "wheelbase": 0, "max_steer": 0.5}},
        "vehicle.wheelbase: must be greater than 0 (got 0",
    ),
    (
        {"vehicle": {**CAR, "max_steer_rate": -1}},
        "vehicle.max_steer_rate: must be greater than 0 (got -1",
    ),
]


@pytest.mark.parametrize(("extra", "message"), BAD)
def test_bad_car_keys_are_one_line_errors(extra, message) -> None:
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"name": "red", "pose": [1, 0, 0]}],
        **extra,
    }
    with pytest.raises(ScenarioError, match=re.escape(message)) as info:
        load_scenario(doc)
    # one line per problem (a car without both keys: one for each)
    lines = str(info.value).splitlines()
    assert all(line.startswith("<scenario>: vehicle") for line in lines)
    assert len(lines) == (2 if "required" in message else 1)


def test_a_slot_inside_a_tight_turn_is_warned_of() -> None:
    # Circle of radius 5 m; the slot 1 m inside turns at 4 m; the car's least radius
    # is 1 / tan(0.2187) = 4.5 m: it cannot hold that slot, and the warning says so.
    doc = circle_platoon(max_steer=0.2187)
    doc["vehicles"][2].update(pose=[4, 0, 1.5708], offset=[0, 1])  # 1 m inside
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scenario(doc)
    lines = [str(w.message) for w in caught if w.category is SandboxWarning]
    about = [line for line in lines if "least turning radius" in line]
    assert len(about) == 1 and "vehicle green" in about[0]
    assert "radius 4.00 m" in about[0] and "4.50 m" in about[0]
    # with a wider turn (max_steer 0.3 rad: 3.09 m) nothing is said
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scenario(circle_platoon(max_steer=0.3))
    assert not [w for w in caught if "least turning radius" in str(w.message)]


def test_the_turning_limit_breaks_the_slot_it_warns_of() -> None:
    # The warned car falls outside its slot; the others hold theirs.
    doc = circle_platoon(max_steer=0.2187)
    doc["vehicles"][2].update(pose=[4, 0, 1.5708], offset=[0, 1])
    doc["duration"] = 12.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SandboxWarning)
        run, _ = run_scenario(doc)
    late = run.t > 8.0
    err = run.formation_error[late]
    assert err[:, 2].min() > 0.1  # green (inside) never reaches its slot
    assert err[:, 1].max() < 0.06  # red (outside) holds it (eq. (12): 5.65 cm)
    assert np.mean(np.abs(run.steer[late, 2]) >= 0.2187 - 1e-9) > 0.9
    assert math.isclose(float(np.abs(run.steer).max()), 0.2187)


def test_a_car_agents_action_is_its_speed_and_steering_angle() -> None:
    pytest.importorskip("gymnasium")
    from sandbox.envs import VehicleEnv
    from sandbox.envs.vector import VehicleVectorEnv

    doc = {**circle_platoon(), "duration": 2.0}
    env = VehicleEnv(doc, agent="red", action="commands")
    env.reset(seed=1)
    for _ in range(60):  # a full action: 2 m/s at full lock, 0.5 rad
        env.step(np.array([1.0, 1.0], dtype=np.float32))
    sim, red = env.task.sim, 1
    assert sim.fleet.steer[red] == pytest.approx(0.5)
    assert sim.fleet.v1[red] == pytest.approx(2.0)
    # half the steering action: 0.25 rad
    env.step(np.array([1.0, 0.5], dtype=np.float32))
    assert sim.fleet.steer[red] == pytest.approx(0.25)
    venv = VehicleVectorEnv(doc, num_envs=2, agent="red", action="commands")
    venv.reset(seed=1)
    for _ in range(60):
        venv.step(np.tile(np.array([1.0, -1.0], dtype=np.float32), (2, 1)))
    assert venv.vector.cohorts[0][0].fleet.steer[1] == pytest.approx(-0.5)


def test_a_car_parks_at_a_point_instead_of_orbiting_it() -> None:
    # Section 2.2.2 with a car: it arrives, creeps past the point by a few centimetres
    # and, the point now behind it and within its least turning radius (1.83 m),
    # stops there; keeping its speed it would loop a 1.83 m circle every 11 s.
    from helpers import PAPER

    car = ["vehicle.model=bicycle", "vehicle.wheelbase=1", "vehicle.max_steer=0.5"]
    run, m = run_scenario(PAPER / "stabilization.yaml", *car, duration=40)
    late = run.t > 5.0
    assert run.formation_error[late, 0].max() < 0.05  # never leaves the point again
    assert m["converged"] is True


def test_a_platoons_vehicle_section_makes_its_vehicles_cars() -> None:
    car = ["wheelbase=1", "max_steer=0.5", "model=bicycle"]
    sc = load_scenario(
        "traffic/intersection_two",
        overrides=[f"platoons[1].vehicle.{c}" for c in car] + ["duration=1"],
    )
    assert [v.model for v in sc.vehicles] == ["unicycle"] * 3 + ["bicycle"] * 3
    assert load_scenario(sc.to_dict()) == sc  # the document reads back the same
    run = Simulation(sc).run()
    assert np.isnan(run.steer[:, :3]).all() and np.isfinite(run.steer[:, 3:]).all()
    assert run.platoon("north").steer.shape == (len(run.t), 3)


def test_the_pictures_draw_the_cars_steering() -> None:
    from sandbox.render.animation import render_frame
    from sandbox.render.replay import replay_html

    run, _ = run_scenario(FULL_LOCK, duration=1.0)
    frame = render_frame(run, size=200)
    straight = dataclasses.replace(run, steer=np.zeros_like(run.steer))
    assert not np.array_equal(frame, render_frame(straight, size=200))
    page = replay_html(run)
    assert "function drawCars" in page and '"cars":' in page
    uni, _ = run_scenario(circle_platoon("unicycle"), duration=0.5)
    assert "drawCars" not in replay_html(uni)
