"""Batches of the features a sweep turns on, against their runs alone and the physics.

For each scene (a bundled scenario, as written unless the table says otherwise) it
times, in one process: the bare physics (the scene's pymunk world, the same bodies,
joints and obstacles, stepped for the whole run with fixed commands: the floor),
single runs (``Simulation(scenario).run()``) and a batch of ``--worlds`` seeds of the
scene in the one loop (``Simulation.stacked(scenarios).run_all()``). Each row prints
the time per run of each, the batch's speed-up over single runs, and the physics'
time over the batch's (1.0: the batch runs at the physics' own speed). The bare
physics is timed before and after each scene; the medians of ``--repeat``
repetitions are printed.

    python benchmarks/bench_batch_features.py               # 32 worlds, 3 repetitions
    python benchmarks/bench_batch_features.py --quick       # 8 worlds, 1 repetition

The scenes: the plain form-up (fig15, 12 s); a leader crashing and handed over to the
nearest follower (``leader_crash_elect``: reconfiguration, a handover and a
reassignment in every world) or to the virtual leader (``leader_crash_virtual``); a
leader driven by a command schedule (``leader_ref_drift``); a follower stopping
(``follower_stop``: a failure in every world, applied at once from four worlds on);
and three traffic scenes of several platoons (``failure_crash``: two platoons and the
CBF filter; ``merge_one_lane``: waypoint references; ``merge_split``: a merge and a
split in every world).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_sweep import step_bare  # noqa: E402

from sandbox.loop.simulation import Simulation  # noqa: E402
from sandbox.scenario import load_scenario  # noqa: E402

#: (row name, bundled scenario, overrides).
SCENES = (
    ("plain form-up", "paper/fig15_continuous_beta1", ["duration=12"]),
    ("leader handover (elect)", "failures/leader_crash_elect", []),
    ("leader handover (virtual)", "failures/leader_crash_virtual", []),
    ("command schedule", "paper/leader_ref_drift", ["duration=20"]),
    ("follower stop", "failures/follower_stop", []),
    ("platoons, CBF filter", "traffic/failure_crash", []),
    ("platoons, waypoints", "traffic/merge_one_lane", []),
    ("platoons, merge and split", "traffic/merge_split", []),
)


def bare_physics(sc, runs: int) -> float:
    """Seconds per run to step the scene's world for its duration, fixed commands."""
    return step_bare(sc, runs) / runs


def single(sc, runs: int) -> float:
    """Seconds per single run."""
    t0 = time.perf_counter()
    for _ in range(runs):
        Simulation(sc).run()
    return (time.perf_counter() - t0) / runs


def batch(scenarios: list) -> float:
    """Seconds per run of the scenarios as one batch of the one loop."""
    t0 = time.perf_counter()
    Simulation.stacked(scenarios).run_all()
    return (time.perf_counter() - t0) / len(scenarios)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--worlds", type=int, default=32, help="seeds in each batch")
    p.add_argument("--single", type=int, default=2, help="single runs per repetition")
    p.add_argument("--bare", type=int, default=4, help="bare runs beside each scene")
    p.add_argument("--repeat", type=int, default=3, help="repetitions (median)")
    p.add_argument("--quick", action="store_true", help="8 worlds, 1 repetition")
    args = p.parse_args(argv)
    if args.quick:
        args.worlds, args.repeat, args.single, args.bare = 8, 1, 1, 2
    warnings.simplefilter("ignore")  # the scenes' own warnings are not the subject
    print(
        f"| scene | single [ms] | batch of {args.worlds} [ms/run] | "
        "batch / single | physics / batch |"
    )
    print("|---|---:|---:|---:|---:|")
    for row, name, overrides in SCENES:
        sc = load_scenario(name, overrides=overrides)
        seeds = [sc.with_overrides(f"seed={k}") for k in range(args.worlds)]
        phys, alone, together = [], [], []
        for _ in range(args.repeat):
            phys.append(bare_physics(sc, args.bare))
            alone.append(single(sc, args.single))
            together.append(batch(seeds))
            phys.append(bare_physics(sc, args.bare))
        one, many = statistics.median(alone), statistics.median(together)
        print(
            f"| {row} (`{name}`) | {1000 * one:.0f} | {1000 * many:.1f} | "
            f"{one / many:.1f}x | {statistics.median(phys) / many:.3f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
