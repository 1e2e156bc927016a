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
"""

from __future__ import annotations

import argparse
import time
import warnings

from sandbox import Simulation, load_scenario
from sandbox.errors import SandboxWarning

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


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 100, 1000])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--worlds", type=int, default=64)
    args = parser.parse_args()
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
