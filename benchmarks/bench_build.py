"""Building a loop of a large fleet: time and memory, up to 100,000 vehicles.

The workload of ``bench_scale.py`` (a grid on a straight ``virtual`` reference,
``continuous`` recovery, whose neighbours come from a Verlet list), for each N: the
seconds to load the scenario, to build its :class:`~sandbox.loop.simulation.Simulation`
(the pymunk world, the stacked arrays, the stages, the record and the loop metrics)
and to step it once, and the peak memory of the process after each N (the largest
resident set so far, which only grows: run one N a process for each N's own peak).
Nothing of the build may grow as N^2 in time or memory: the pairs of vehicles a fleet
above :data:`~sandbox.geometry.neighbours.BRUTE_FORCE_MAX` checks come from a KD-tree.
Not a test: a table.

    python benchmarks/bench_build.py                  # N = 1,000, 10,000, 100,000
    python benchmarks/bench_build.py --n 100000       # one N
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_scale import scenario_doc  # noqa: E402

from sandbox.loop.simulation import Simulation  # noqa: E402
from sandbox.scenario import load_scenario  # noqa: E402


def peak_mb() -> float:
    """The process's largest resident set so far [MB] (Linux: ru_maxrss in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def measure(n: int) -> tuple[float, float, float, float]:
    """Seconds to load, build and step once a fleet of ``n``; the peak [MB]."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the loader's notes of a dense grid
        scenario = load_scenario(scenario_doc(n, 2))
    t1 = time.perf_counter()
    sim = Simulation(scenario)
    t2 = time.perf_counter()
    sim.step(observe=False)
    t3 = time.perf_counter()
    if sim.status != "ok":
        raise RuntimeError(f"N = {n}: the step ended with status {sim.status}")
    return t1 - t0, t2 - t1, t3 - t2, peak_mb()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, action="append", help="fleet sizes (repeatable)")
    args = p.parse_args()
    sizes = args.n or [1_000, 10_000, 100_000]
    print("| N | load [s] | build [s] | one step [s] | peak memory [MB] |")
    print("|---:|---:|---:|---:|---:|")
    for n in sizes:
        load, build, step, peak = measure(n)
        print(f"| {n:,} | {load:.2f} | {build:.2f} | {step:.2f} | {peak:,.0f} |")


if __name__ == "__main__":
    main()
