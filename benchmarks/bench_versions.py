"""Single runs of two checkouts side by side, turn by turn, in one measurement.

A check that a change made nothing slower compares two trees (this one and another
checkout with its own environment, e.g. the last release) on the single-run rows of
``bench_full_features.py``. Timed one tree after the other, the two sides meet
different moments of a shared machine, whose speed drifts by more than 10 % within
minutes; here each tree runs in a worker process of its own, both started at once,
and the two take turns run by run (the order swapped each repetition), so that a
drift falls on both alike. Each worker times the row's single run (the simulation
and its metrics, ``Simulation(scenario).run()``) and the row's bare physics
(``bench_sweep.step_bare``: the same pymunk world stepped with fixed commands), and
each side's figure is, as in ``bench_full_features.py``, the bare physics' time
over the run's, here of the fastest of ``--repeat`` turns: on a shared machine a
run's time is its own cost plus whatever the machine did meanwhile, and the fastest
turn holds the least of the latter (the medians of single runs were seen to move by
30 % from one measurement to the next here). The last column is the median over the
turns of the other tree's run time over this one's, each pair of runs timed one
right after the other. With ``--vector K ...``, rows of ``VehicleVectorEnv`` of K
worlds of the Fig. 15 platoon (random actions through episode ends), 100 vector steps
a turn: env steps per second of each side's fastest turn, and the paired median.

    python benchmarks/bench_versions.py --other /path/to/checkout
    python benchmarks/bench_versions.py --other /path/to/checkout --vector 16 64 256
    python benchmarks/bench_versions.py --other ../old --other-python ../old/env/bin/py

The other checkout must hold ``benchmarks/bench_scale.py`` and
``benchmarks/bench_sweep.py`` (this tree's rows are built from them). Not a test: a
table.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: The rows: (name, what the worker builds).
ROWS = (
    ("N = 3, grid, virtual, continuous", "grid:3"),
    ("N = 5, grid, virtual, continuous", "grid:5"),
    ("N = 10, grid, virtual, continuous", "grid:10"),
    ("N = 3, fig15 (12 s)", "fig15"),
)

#: Vector steps of each turn of a ``VehicleVectorEnv`` row.
VECTOR_STEPS = 100

#: The worker: builds the rows' scenarios in its own tree, then times what it is
#: asked, one JSON line a request ("run ROW" or "bare ROW") on stdin.
WORKER = r"""
import json, sys, time, warnings
from pathlib import Path
root = Path(sys.argv[1])
sys.path[:0] = [str(root), str(root / "benchmarks")]
from bench_scale import scenario_doc
from bench_sweep import step_bare
from sandbox.loop.simulation import Simulation
from sandbox.run.metrics import compute_metrics
from sandbox.scenario import load_scenario

VECTOR_STEPS = int(sys.argv[2])

def build(key):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if key.startswith("grid:"):
            return load_scenario(scenario_doc(int(key[5:]), 2000))
        path = root / "scenarios" / "paper" / "fig15_continuous_beta1.yaml"
        return load_scenario(path, overrides=["duration=12"])

def vector_steps(key):
    import numpy as np
    from sandbox.envs import VehicleVectorEnv
    env = VehicleVectorEnv("paper/fig15_continuous_beta1", num_envs=int(key[7:]))
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    shape = env.action_space.shape
    def steps(count):
        t0 = time.perf_counter()
        for _ in range(count):
            env.step(rng.uniform(-1, 1, size=shape).astype(np.float32))
        return time.perf_counter() - t0
    steps(20)  # warm
    return steps

scenarios = {}
for line in sys.stdin:
    what, key = line.split()
    if what == "steps":
        if key not in scenarios:
            scenarios[key] = vector_steps(key)
        print(json.dumps(scenarios[key](VECTOR_STEPS)), flush=True)
        continue
    sc = scenarios.get(key)
    if sc is None:
        sc = scenarios[key] = build(key)
        compute_metrics(Simulation(sc).run())  # warm: first calls, imports
        step_bare(sc, 1)
    if what == "run":
        t0 = time.perf_counter()
        compute_metrics(Simulation(sc).run())
        seconds = time.perf_counter() - t0
    else:
        seconds = step_bare(sc, 1)
    print(json.dumps(seconds), flush=True)
"""


def start(python: str, root: Path) -> subprocess.Popen:
    """A worker of the tree ``root`` run by ``python``."""
    return subprocess.Popen(
        [python, "-c", WORKER, str(root), str(VECTOR_STEPS)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=root,
    )


def ask(worker: subprocess.Popen, what: str, key: str) -> float:
    """Seconds of one ``what`` (run or bare) of the row ``key`` in ``worker``."""
    worker.stdin.write(f"{what} {key}\n")
    worker.stdin.flush()
    line = worker.stdout.readline()
    if not line:
        raise SystemExit(f"a worker ended (status {worker.wait()})")
    return float(json.loads(line))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--other", type=Path, required=True, help="the other checkout")
    p.add_argument(
        "--other-python",
        help="its Python (default: OTHER/.venv/bin/python)",
    )
    p.add_argument("--repeat", type=int, default=30, help="turns of each row")
    p.add_argument(
        "--vector",
        type=int,
        nargs="*",
        default=[],
        metavar="K",
        help="VehicleVectorEnv rows of K worlds as well (e.g. --vector 16 64 256)",
    )
    args = p.parse_args(argv)
    other = args.other.resolve()
    other_python = args.other_python or str(other / ".venv" / "bin" / "python")
    sides = {"other": start(other_python, other), "this": start(sys.executable, ROOT)}
    print(f"other: {other}; this: {ROOT}; {args.repeat} turns of each row")
    print()
    print(
        "| row | other: physics / run | this | this / other (speed) "
        "| run time other / this, median of turns |"
    )
    print("|---|---:|---:|---:|---:|")
    try:
        for name, key in ROWS:
            times = {side: {"run": [], "bare": []} for side in sides}
            for rep in range(args.repeat):
                order = ("other", "this") if rep % 2 == 0 else ("this", "other")
                for what in ("bare", "run"):
                    for side in order:
                        times[side][what].append(ask(sides[side], what, key))
            best = {side: min(t["bare"]) / min(t["run"]) for side, t in times.items()}
            paired = statistics.median(
                a / b
                for a, b in zip(
                    times["other"]["run"], times["this"]["run"], strict=True
                )
            )
            print(
                f"| {name} | {best['other']:.3f} | {best['this']:.3f} | "
                f"{best['this'] / best['other']:.2f} | {paired:.2f} |",
                flush=True,
            )
        if args.vector:
            print()
            print(
                "| VehicleVectorEnv (Fig. 15, random actions) | other: env steps/s "
                "| this | this / other (speed) | step time other / this, median of "
                "turns |"
            )
            print("|---|---:|---:|---:|---:|")
        for K in args.vector:
            times = {side: [] for side in sides}
            for rep in range(args.repeat):
                order = ("other", "this") if rep % 2 == 0 else ("this", "other")
                for side in order:
                    times[side].append(ask(sides[side], "steps", f"vector:{K}"))
            rate = {side: VECTOR_STEPS * K / min(t) for side, t in times.items()}
            pairs = zip(times["other"], times["this"], strict=True)
            paired = statistics.median(a / b for a, b in pairs)
            print(
                f"| num_envs = {K} | {rate['other']:,.0f} | {rate['this']:,.0f} | "
                f"{rate['this'] / rate['other']:.2f} | {paired:.2f} |",
                flush=True,
            )
    finally:
        for worker in sides.values():
            worker.stdin.close()
            worker.wait()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
