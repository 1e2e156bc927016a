"""The cost of cars (``model: bicycle``) in the loop, against the same unicycles.

A platoon of N vehicles generated on a grid (the workload of ``bench_scale.py``:
the ``virtual`` law on a straight reference at 1 m/s, ``continuous`` recovery with R =
1.5 m) runs as unicycles and as cars (wheelbase 1 m, max_steer 0.5 rad), alternately
in one process, best of ``--repeat``; the table gives control periods per second of
each and their ratio. The cars' extra work is their rows' controller step again with
the car's anti-windup, and the steering stage (``sandbox/loop/steering.py``).

    python benchmarks/bench_cars.py              # N = 10, 100, 1000
    python benchmarks/bench_cars.py --sizes 10 100 --steps 500 --repeat 5

A last row runs a batch of ``--worlds`` seeds of
``scenarios/studies/random_formup.yaml`` (three vehicles each, one loop: a sweep's
work) as unicycles and as cars.

A second table times one step of the CBF filter (``safety: {filter: cbf}``, the
velocity barrier) on N vehicles on a grid 1 m apart, random headings, each asked
for 1.5 m/s and a turn of 3 rad/s: as unicycles (the compiled step), as cars (the
compiled step, then numpy for the cars' rows with their cones:
``sandbox/behaviour/safety/cars.py``) and as cars with every row by numpy (the
compiled paths off), best of ``--repeat`` rounds of 20 steps, alternately.

    python benchmarks/bench_cars.py --filter-sizes 10 100 --sizes
"""

from __future__ import annotations

import argparse
import time
import warnings
from contextlib import nullcontext

import numpy as np

from sandbox import Simulation, accel, load_scenario
from sandbox.behaviour.safety.cbf import PARAMS, filter_commands
from sandbox.behaviour.safety.state import CBFState
from sandbox.errors import SandboxWarning
from sandbox.model.bicycle import CarSteering
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.contexts import FilterContext

CAR = {"model": "bicycle", "wheelbase": 1.0, "max_steer": 0.5}


def scenario(n: int, steps: int, car: bool) -> object:
    """The grid platoon of ``n`` vehicles for ``steps`` periods of 0.01 s."""
    doc = {
        "duration": steps * 0.01,
        "dt": 0.01,
        "substeps": 4,
        "vehicle": {"v1_max": 2.0, "max_accel": 5.0, **(CAR if car else {})},
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "formation": {"law": "virtual"},
        "recovery": {"strategy": "continuous", "R": 1.5, "r": 0.75},
        "platoon": {"count": n, "pattern": "grid", "spacing": 1.25},
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SandboxWarning)
        return load_scenario(doc)


def periods_per_second(sc: object, steps: int) -> float:
    """Control periods per second of one run of ``sc``."""
    start = time.perf_counter()
    Simulation(sc).run()
    return steps / (time.perf_counter() - start)


def batch_periods_per_second(worlds: int, steps: int, car: bool) -> float:
    """Control periods per second of a batch of ``worlds`` random form-ups."""
    sets = ["vehicle.wheelbase=1", "vehicle.max_steer=0.5", f"duration={steps / 100}"]
    if car:
        sets.append("vehicle.model=bicycle")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SandboxWarning)
        scenarios = [
            load_scenario("studies/random_formup", overrides=[*sets, f"seed={s}"])
            for s in range(worlds)
        ]
    start = time.perf_counter()
    Simulation.batch(scenarios)
    return steps / (time.perf_counter() - start)


def filter_context(n: int, car: bool) -> FilterContext:
    """The filter's view of ``n`` vehicles on a grid 1 m apart (cars or unicycles)."""
    rng = np.random.default_rng(0)
    side = int(np.ceil(np.sqrt(n)))
    pos = np.array([(i % side, i // side) for i in range(n)], dtype=float)
    theta = rng.uniform(-np.pi, np.pi, n)
    steering = CarSteering(
        np.ones(n), np.full(n, 0.5), np.full(n, np.inf), rng.uniform(-0.5, 0.5, n)
    )
    return FilterContext(
        t=1.0,
        dt=0.01,
        pos=pos,
        theta=theta,
        vel=np.column_stack((np.cos(theta), np.sin(theta))),
        v1=np.full(n, 1.5),
        v2=np.where(np.arange(n) % 2, 3.0, -3.0),
        diameter=np.full(n, 0.5),
        params={k: p.default for k, p in PARAMS.items()},
        v1_prev=np.ones(n),
        v2_prev=np.zeros(n),
        v1_max=2.0,
        v2_max=4.0,
        accel_max=5.0,
        known_failed=np.zeros(n, bool),
        commanded=np.zeros(n, bool),
        obstacle_field=ObstacleField(()),
        steering=steering if car else None,
    )


def filter_steps_per_second(ctx: FilterContext, numpy_only: bool) -> float:
    """Steps per second of the CBF filter on ``ctx`` (20 steps)."""
    state = CBFState(ctx)
    with accel.switched_off() if numpy_only else nullcontext():
        filter_commands(state, ctx)  # the first step builds the filter's arguments
        start = time.perf_counter()
        for _ in range(20):
            filter_commands(state, ctx)
        return 20 / (time.perf_counter() - start)


def filter_table(sizes: list[int], repeat: int) -> None:
    """Print the filter's table (see the module docstring)."""
    print("| N | unicycles [steps/s] | cars [steps/s] | cars, numpy only [steps/s] |")
    print("|---:|---:|---:|---:|")
    for n in sizes:
        runs = {
            "uni": (filter_context(n, False), False),
            "car": (filter_context(n, True), False),
            "numpy": (filter_context(n, True), True),
        }
        best = dict.fromkeys(runs, 0.0)
        for _ in range(repeat):
            for key, (ctx, numpy_only) in runs.items():
                best[key] = max(best[key], filter_steps_per_second(ctx, numpy_only))
        print(
            f"| {n:,} | {best['uni']:,.0f} | {best['car']:,.0f} "
            f"({best['car'] / best['uni']:.2f}) | {best['numpy']:,.0f} "
            f"({best['numpy'] / best['uni']:.2f}) |"
        )


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[10, 100, 1000])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--worlds", type=int, default=64)
    parser.add_argument("--filter-sizes", type=int, nargs="*", default=[])
    args = parser.parse_args()
    if args.filter_sizes:
        filter_table(args.filter_sizes, args.repeat)
    if not args.sizes:
        return
    print("| N | unicycles [periods/s] | cars [periods/s] | cars / unicycles |")
    print("|---:|---:|---:|---:|")
    for n in args.sizes:
        uni, car = scenario(n, args.steps, False), scenario(n, args.steps, True)
        best = {"uni": 0.0, "car": 0.0}
        for _ in range(args.repeat):  # alternately: the ratio is the steadier number
            best["uni"] = max(best["uni"], periods_per_second(uni, args.steps))
            best["car"] = max(best["car"], periods_per_second(car, args.steps))
        ratio = best["car"] / best["uni"]
        print(f"| {n:,} | {best['uni']:,.0f} | {best['car']:,.0f} | {ratio:.2f} |")
    best = {"uni": 0.0, "car": 0.0}
    for _ in range(args.repeat):
        for key, car in (("uni", False), ("car", True)):
            rate = batch_periods_per_second(args.worlds, 300, car)
            best[key] = max(best[key], rate)
    ratio = best["car"] / best["uni"]
    label = f"{args.worlds} x 3 (batch)"
    print(f"| {label} | {best['uni']:,.0f} | {best['car']:,.0f} | {ratio:.2f} |")


if __name__ == "__main__":
    main()
