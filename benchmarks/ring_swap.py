"""Write a jittered N-vehicle ring swap as a scenario file, for sweeps over its seeds.

``python benchmarks/ring_swap.py N OUT.yaml [--radius R] [--duration S]`` writes the
pattern of ``scenarios/safety/circle_swap_8_jittered.yaml`` for N vehicles: evenly on
a circle of radius R [m] (default ``max(3, N / 2)``), each driving to the antipodal
point, each start drawn within 0.1 m and 0.1 rad of the exact one (``randomize:``,
from the seed), the benchmark's robot (d = 0.5 m, 10 kg, v1_max = 2 m/s, v2_max =
4 rad/s, max_accel = 5 m/s^2; dt = 0.01 s, 4 substeps) and the report's continuous
approach (beta = 1, R = 3d, r = R/2). ``sandbox sweep OUT.yaml --seeds 0:200`` then
gives the rates (docs/results/safety-benchmark.md).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

JITTER_POS = 0.1  # [m]
JITTER_ANGLE = 0.1  # [rad]


def ring_yaml(n: int, radius: float, duration: float) -> str:
    """The scenario's text."""
    lines = [
        f"name: circle_swap_{n}_jittered",
        "description: >-",
        f"  Antipodal circle swap of {n} vehicles (starts jittered by up to 0.1 m and",
        f"  0.1 rad) on a {radius:g} m circle (benchmarks/ring_swap.py).",
        f"duration: {duration:g}",
        "dt: 0.01",
        "substeps: 4",
        "seed: 0",
        "vehicle: {diameter: 0.5, mass: 10.0, v1_max: 2.0, v2_max: 4.0, "
        "max_accel: 5.0}",
        "reference: {type: point, position: [0, 0]}",
        "formation: {law: virtual}",
        "recovery: {strategy: continuous, beta: 1.0, R: 3d, r: 1.5d, tangential: 0}",
        "vehicles:",
    ]
    draws = ["randomize:"]
    for k in range(n):
        a = 2.0 * math.pi * k / n
        x, y, heading = radius * math.cos(a), radius * math.sin(a), a - math.pi
        lines.append(
            f"  - {{name: v{k}, pose: [{x!r}, {y!r}, {heading!r}], "
            f"offset: [{-x!r}, {-y!r}]}}"
        )
        lo = [x - JITTER_POS, y - JITTER_POS, heading - JITTER_ANGLE]
        hi = [x + JITTER_POS, y + JITTER_POS, heading + JITTER_ANGLE]
        draws.append(
            f"  vehicles[{k}].pose: {{uniform: [[{', '.join(f'{v:.4f}' for v in lo)}]"
            f", [{', '.join(f'{v:.4f}' for v in hi)}]]}}"
        )
    return "\n".join([*lines, *draws]) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write the file; return 0."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("n", type=int, help="vehicles (at least 2)")
    parser.add_argument("out", type=Path, help="the scenario file to write")
    parser.add_argument("--radius", type=float, help="[m] (default max(3, N / 2))")
    parser.add_argument("--duration", type=float, default=15.0, help="[s]")
    args = parser.parse_args(argv)
    radius = args.radius if args.radius is not None else max(3.0, args.n / 2)
    args.out.write_text(ring_yaml(args.n, radius, args.duration))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
