"""The range sensor's cost per control step at 10, 100 and 1,000 vehicles.

A world of ``n`` vehicles (d = 0.5 m) on a jittered grid 1.5 m apart, driving at
1 m/s in slightly different headings through a field of posts and crates (one
obstacle per 8 vehicles), each with a 32-beam full-turn range sensor reaching
``10d`` = 5 m. Per control step (h = 0.01 s, 4 substeps) it times, interleaved in the
same run:

- **physics**: the bare pymunk step of the world (commands written, 4 substeps);
- **prefilter**: one scan of every vehicle by :class:`sandbox.behaviour.ranges.
  RangeSensor` with the default caster (bounding circles in numpy, then
  ``cpShapeSegmentQuery`` per (beam, shape) pair that can touch);
- **space**: the same scan with ``cpSpaceSegmentQueryFirst`` per beam.

The ratio is the scan's time over the bare physics step (1.0: a scan costs one more
physics step). The scans of the two methods are checked equal.

    python benchmarks/bench_ranges.py              # 10 / 100 / 1000 vehicles
    python benchmarks/bench_ranges.py --sizes 10 100 --steps 50
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from sandbox.behaviour.ranges import RangeSensor  # noqa: E402
from sandbox.model.obstacle_field import ObstacleField  # noqa: E402
from sandbox.physics.world import World  # noqa: E402
from sandbox.scenario import ObstacleSpec, RangeSpec, VehicleSpec  # noqa: E402

H, SUBSTEPS, BEAMS, REACH = 0.01, 4, 32, 5.0


def world_specs(n: int, seed: int = 0) -> tuple[list, list]:
    """The vehicles and obstacles of the benchmark world of ``n`` vehicles."""
    rng = np.random.default_rng(seed)
    cols = math.ceil(math.sqrt(n))
    vehicles = []
    for i in range(n):
        x, y = 1.5 * (i % cols), 1.5 * (i // cols)
        x, y = x + rng.uniform(-0.2, 0.2), y + rng.uniform(-0.2, 0.2)
        heading = float(rng.uniform(-0.3, 0.3))
        vehicles.append(VehicleSpec(name=f"v{i}", pose=(x, y, heading), mass=10.0))
    side = 1.5 * cols
    obstacles = []
    for k in range(max(1, n // 8)):
        cx, cy = (float(c) for c in rng.uniform(-3.0, side + 3.0, 2))
        # Obstacles sit outside the grid's rows: shifted half a spacing.
        cx, cy = cx + 0.75, cy + 0.75
        if k % 2:
            obstacles.append(
                ObstacleSpec("circle", f"post{k}", center=(cx, cy), radius=0.2)
            )
        else:
            obstacles.append(
                ObstacleSpec("box", f"crate{k}", center=(cx, cy), size=(0.3, 0.3))
            )
    return vehicles, obstacles


def clear(vehicles: list, obstacles: list) -> list:
    """The vehicles that do not start inside an obstacle."""
    field = ObstacleField(tuple(obstacles))
    pos = np.array([v.pose[:2] for v in vehicles])
    if field.empty:
        return vehicles
    signed, _ = field.nearest(pos)
    ok = np.all(signed > 0.3, axis=1)
    return [v for v, keep in zip(vehicles, ok, strict=True) if keep]


def measure(n: int, steps: int) -> dict[str, float]:
    """Median seconds per step of the physics and of each method's scan."""
    vehicles, obstacles = world_specs(n)
    vehicles = clear(vehicles, obstacles)
    specs = [RangeSpec(beams=BEAMS, max_range=REACH)] * len(vehicles)
    worlds, sensors = {}, {}
    for method in ("prefilter", "space"):
        world = World(tuple(vehicles), tuple(obstacles), substeps=SUBSTEPS)
        worlds[method] = world
        field = ObstacleField(tuple(obstacles))
        sensors[method] = RangeSensor(specs, world, field, seed=0, method=method)
    times: dict[str, list[float]] = {"physics": [], "prefilter": [], "space": []}
    m = len(vehicles)
    v1, v2 = np.ones(m), np.zeros(m)
    for k in range(steps):
        for method in ("prefilter", "space"):
            world, sensor = worlds[method], sensors[method]
            state = world.read_state()
            t0 = time.perf_counter()
            sensor.update(k * H, state.pos, state.theta)
            times[method].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            world.write_commands(state.theta, v1, v2, H)
            world.step(H, SUBSTEPS, k * H)
            if method == "prefilter":
                times["physics"].append(time.perf_counter() - t0)
        a, b = sensors["prefilter"].ranges, sensors["space"].ranges
        if not np.array_equal(a, b):
            raise SystemExit(f"n = {n}: the two methods' scans differ at step {k}")
    out = {key: statistics.median(v) for key, v in times.items()}
    out["vehicles"] = m
    out["hits"] = float(np.mean(sensors["prefilter"].ranges < REACH))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[10, 100, 1000])
    p.add_argument("--steps", type=int, default=None, help="steps (default by size)")
    args = p.parse_args(argv)
    print(
        "| vehicles | beams hit | physics step [ms] | prefilter scan [ms] (x physics) "
        "| space scan [ms] (x physics) |"
    )
    print("|---|---|---|---|---|")
    for n in args.sizes:
        steps = args.steps or max(10, 2000 // n)
        r = measure(n, steps)
        phys = r["physics"]
        print(
            f"| {int(r['vehicles'])} | {100 * r['hits']:.0f} % | {1e3 * phys:.3f} "
            f"| {1e3 * r['prefilter']:.3f} ({r['prefilter'] / phys:.1f}x) "
            f"| {1e3 * r['space']:.3f} ({r['space'] / phys:.1f}x) |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
