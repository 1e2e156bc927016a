"""The CBF filter with cars: the car's reachable set as two hard rows of its QP.

A car executes only the turn rate ``v1 tan(delta) / L`` of a steering angle within
its reach this period (``sandbox/behaviour/safety/cars.py``); the filter's command
for a car is one the steering stage after it executes as it is, and a unicycle's
command is the one it has without cars.
"""

from __future__ import annotations

import dataclasses
from contextlib import nullcontext

import numpy as np
import pytest

from sandbox import Simulation, accel, load_scenario
from sandbox.behaviour.safety.cars import CarCone, solved_groups
from sandbox.behaviour.safety.cbf import PARAMS, filter_commands
from sandbox.behaviour.safety.qp import bounded_problems
from sandbox.behaviour.safety.state import CBFState
from sandbox.model.bicycle import CarLimits, CarSteering, steer_commands
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.contexts import FilterContext

DT = 0.01
#: The small car: wheelbase 1 m, max_steer 0.5 rad.
L, MAX_STEER = 1.0, 0.5


def ring(
    n: int, cars: np.ndarray, rate: float = np.inf, seed: int = 0
) -> FilterContext:
    """``n`` vehicles on a 1.2 m circle, each driving at 1 m/s across it.

    ``cars`` marks the cars (wheelbase 1 m, max_steer 0.5 rad, ``max_steer_rate``
    ``rate``, last angles random within the limit); the nominal commands ask for
    1.5 m/s and a turn rate of +-3 rad/s, beyond a car's reach.
    """
    rng = np.random.default_rng(seed)
    angle = 2 * np.pi * np.arange(n) / n
    pos = 1.2 * np.column_stack((np.cos(angle), np.sin(angle)))
    theta = angle + np.pi + rng.uniform(-0.3, 0.3, n)
    v1_prev = np.ones(n)
    v2_prev = rng.uniform(-0.5, 0.5, n)
    values = {k: p.default for k, p in PARAMS.items()}
    steering = CarSteering(
        wheelbase=np.where(cars, L, np.nan),
        max_steer=np.where(cars, MAX_STEER, np.nan),
        max_steer_rate=np.where(cars, rate, np.inf),
        held=np.where(cars, rng.uniform(-MAX_STEER, MAX_STEER, n), 0.0),
    )
    return FilterContext(
        t=1.0,
        dt=DT,
        pos=pos,
        theta=theta,
        vel=v1_prev[:, None] * np.column_stack((np.cos(theta), np.sin(theta))),
        v1=np.full(n, 1.5),
        v2=np.where(np.arange(n) % 2, 3.0, -3.0),
        diameter=np.full(n, 0.5),
        params=values,
        v1_prev=v1_prev,
        v2_prev=v2_prev,
        v1_max=2.0,
        v2_max=4.0,
        accel_max=5.0,
        known_failed=np.zeros(n, bool),
        commanded=np.zeros(n, bool),
        obstacle_field=ObstacleField(()),
        steering=steering,
    )


def executed(ctx: FilterContext, v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
    """The turn rates [rad/s] the cars of ``ctx`` execute of the commands (v1, v2)."""
    s = ctx.steering
    car = np.isfinite(s.wheelbase)
    limits = CarLimits.of(
        wheelbase=s.wheelbase[car],
        max_steer=s.max_steer[car],
        max_steer_rate=s.max_steer_rate[car],
        v2_max=np.full(np.count_nonzero(car), 4.0),
    )
    return steer_commands(v1[car], v2[car], s.held[car], limits, ctx.dt)[0]


@pytest.mark.parametrize("rate", [np.inf, 5.0])
@pytest.mark.parametrize("compiled", [True, False])
def test_a_cars_filtered_command_is_one_it_executes(rate, compiled) -> None:
    # Eight cars crossing a 1.2 m circle: the filter cuts them, and the steering
    # stage after it leaves each car's filtered turn rate as it is (to rounding).
    cars = np.ones(8, dtype=bool)
    ctx = ring(8, cars, rate)
    with accel.switched_off() if not compiled else nullcontext():
        v1, v2, step = filter_commands(CBFState(ctx), ctx)
    assert step.active.all()
    np.testing.assert_allclose(executed(ctx, v1, v2), v2, rtol=0, atol=1e-8)
    # Without the cone (the filter blind to the cars) the steering stage changes
    # the filter's turn rates by up to a radian a second: the check can fail.
    blind = dataclasses.replace(ctx, steering=None)
    v1b, v2b, _ = filter_commands(CBFState(blind), blind)
    assert np.abs(executed(ctx, v1b, v2b) - v2b).max() > 0.5


def test_the_cars_cones_forward_and_reverse_and_no_turn_at_rest() -> None:
    # A car at rest, the box -0.05 <= v1 <= 0.05 m/s (5 m/s^2 over 0.01 s), no
    # steering-rate limit: in z = (v1, l v2) the cones z2 = k z1 with |k| <= l
    # tan(0.5) / L = 0.0546, forward (z1 >= 0) and reverse (z1 <= 0).
    ctx = dataclasses.replace(
        ring(1, np.ones(1, bool)),
        v1=np.zeros(1),
        v2=np.full(1, 2.0),
        v1_prev=np.zeros(1),
        v2_prev=np.zeros(1),
        steering=CarSteering(
            np.ones(1), np.full(1, 0.5), np.full(1, np.inf), np.zeros(1)
        ),
    )
    box = (np.full(1, -0.05), np.full(1, 0.05), np.full(1, -0.4), np.full(1, 0.4))
    cone = CarCone.of(ctx, 0.1, False, box, np.arange(1))
    assert cone is not None
    k = 0.1 * np.tan(0.5) / 1.0
    none = np.zeros(0, dtype=np.intp)
    bare = bounded_problems(box, none, np.zeros((0, 2)), np.zeros(0), none, 0)
    forward, reverse = (cone.add(np.arange(1), bare, half) for half in (0, 1))
    # z2 - k z1 <= 0 and -k z1 - z2 <= 0 (unit normals), and their mirror images
    edges = np.array([[-k, 1.0], [-k, -1.0]]) / np.hypot(k, 1.0)
    np.testing.assert_allclose(forward[0][0, 4:], edges)
    np.testing.assert_allclose(reverse[0][0, 4:], -edges)
    assert not forward[2][0, 4:].any() and not reverse[2][0, 4:].any()  # hard rows
    # full lock either way is in a cone; a turn at rest and sideways are in none
    for z, inside in [((1.0, k), True), ((-1.0, k), True), ((0.0, 0.01), False)]:
        got = [
            bool(np.all(c[0][0, 4:] @ np.array(z) <= 1e-12)) for c in (forward, reverse)
        ]
        assert any(got) is inside
    # asked to turn at 2 rad/s at rest, the car turns by what its speed allows:
    # the QP's optimum is on an edge, |z2| = k |z1| with |z1| <= 0.05 m/s
    z0 = np.array([[0.0, 0.2]])
    z, slack, _ = cone.solve(np.arange(1), z0, bare)
    assert slack[0] == 0.0 and abs(z[0, 0]) <= 0.05 + 1e-12
    np.testing.assert_allclose(abs(z[0, 1]), k * abs(z[0, 0]), rtol=1e-9)


def test_a_unicycles_filtered_command_is_the_one_it_has_without_cars() -> None:
    # Cars and unicycles in one ring: the unicycles' commands, to the bit, are those
    # of the same ring where no vehicle is a car (their problems are solved apart).
    cars = np.arange(8) % 3 == 0
    ctx = ring(8, cars)
    none = dataclasses.replace(ctx, steering=None)
    for off in (False, True):
        with accel.switched_off() if off else nullcontext():
            v1, v2, _ = filter_commands(CBFState(ctx), ctx)
            v1n, v2n, _ = filter_commands(CBFState(none), none)
        assert np.array_equal(v1[~cars], v1n[~cars])
        assert np.array_equal(v2[~cars], v2n[~cars])
        assert not np.array_equal(v2[cars], v2n[cars])


def test_groups_keep_unicycles_apart_from_cars() -> None:
    ctx = ring(6, np.array([1, 0, 1, 0, 0, 1], bool))
    box = tuple(np.zeros(6) for _ in range(4))
    cone = CarCone.of(ctx, 0.1, False, box, np.arange(6))
    counts = np.array([0, 0, 1, 1, 2, 2])
    got = [(m, g.tolist()) for m, g in solved_groups(np.arange(6), counts, cone)]
    # no rows: the car 0 only (the unicycle 1 is clipped apart); then each count's
    # unicycles, then its cars
    assert got == [(0, [0]), (1, [3]), (1, [2]), (2, [4]), (2, [5])]
    kept = solved_groups(np.arange(6), counts, cone, clipped=False)
    assert [(m, g.tolist()) for m, g in kept][:2] == [(0, [1]), (0, [0])]


@pytest.mark.slow
@pytest.mark.parametrize("barrier", ["velocity", "braking"])
def test_a_batch_of_cars_and_unicycles_with_the_filter_is_each_world_alone(
    barrier,
) -> None:
    over = ["duration=3", "safety.filter=cbf", f"safety.barrier={barrier}"]
    car = ["vehicle.model=bicycle", "vehicle.wheelbase=1", "vehicle.max_steer=0.5"]
    scenarios = [
        load_scenario("safety/circle_swap_8", over),
        load_scenario("safety/circle_swap_8", [*over, *car]),
        load_scenario(
            "safety/circle_swap_8", [*over, *car, "vehicle.max_steer_rate=3"]
        ),
    ]
    batched = Simulation.stacked(scenarios).run_all()
    for sc, got in zip(scenarios, batched, strict=True):
        alone = Simulation(sc).run()
        for name in ("pose", "cmd", "chi"):
            assert np.array_equal(getattr(got, name), getattr(alone, name)), name
        assert got.info["safety"] == alone.info["safety"]
    # the cars do change what the filter does
    assert not np.array_equal(batched[0].cmd, batched[1].cmd)
