"""A sweep on a 2-worker Dask cluster against ``sandbox sweep --jobs 2``.

The workload of ``bench_sweep.py``: the Fig. 15 scenario (three vehicles, 12 s,
1,200 control steps of 4 substeps), ``--runs`` seeds (default 256), into a fresh
store each time. Rows:

- ``sandbox sweep --jobs 2``: the local process pool (its workers started by the
  command, as a user runs it).
- ``sandbox sweep --scheduler``: the same command on a
  ``LocalCluster(n_workers=2, threads_per_worker=1, processes=True)`` started once
  before the timings (as a cluster is: it outlives the sweeps sent to it) and warmed
  up by a sweep of 8 runs, so that its workers have imported the simulation.

Each row is timed once per repetition, alternating, with the bare physics of
``bench_sweep.bare_physics`` timed just before and after it (``--bare`` runs): the
ratio is the bare-physics time per run over the row's time per run, the median over
``--repeat`` repetitions (default 3). The target of issue 22 is a Dask sweep within
1.3x of ``--jobs 2``: the last line prints the median of ``jobs 2 / Dask`` per
repetition (1.0: as fast; 1.3: Dask takes 30 % longer).

    python benchmarks/bench_dask.py                      # 256 runs, 3 repetitions
    python benchmarks/bench_dask.py --runs 64 --repeat 1  # quicker
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from bench_sweep import DURATION, SCENARIO, bare_physics  # noqa: E402

from sandbox.cli import main as sandbox_main  # noqa: E402


def sweep(runs: int, out: Path, *engine: str) -> float:
    """Seconds of ``sandbox sweep`` over ``runs`` seeds on ``engine``'s options."""
    argv = ["sweep", str(SCENARIO), "--set", f"duration={DURATION}"]
    argv += ["--seeds", f"0:{runs}", "--out", str(out), *engine]
    t0 = time.perf_counter()
    code = sandbox_main(argv)
    elapsed = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"sandbox sweep failed with status {code}")
    return elapsed


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=256, help="runs per measurement")
    p.add_argument("--bare", type=int, default=64, help="bare runs beside each row")
    p.add_argument("--repeat", type=int, default=3, help="repetitions (median)")
    args = p.parse_args(argv)
    from distributed import LocalCluster

    runs, bare_runs = args.runs, min(args.bare, args.runs)
    floor = "bare pymunk (same bodies, joints, steps)"
    local, dask = "sandbox sweep --jobs 2", "sandbox sweep --scheduler (2 workers)"
    times: dict[str, list[float]] = {floor: [], local: [], dask: []}
    ratios: dict[str, list[float]] = {local: [], dask: []}

    def measure(name: str, run) -> None:
        before = bare_physics(bare_runs)
        seconds = run()
        after = bare_physics(bare_runs)
        phys = (before + after) / (2 * bare_runs)  # per run
        times[floor].extend((before / bare_runs, after / bare_runs))
        times[name].append(seconds / runs)
        ratios[name].append(phys / (seconds / runs))

    load_before = os.getloadavg()
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        tempfile.TemporaryDirectory() as tmp,
    ):
        address = cluster.scheduler_address
        sweep(8, Path(tmp) / "warm", "--scheduler", address)
        for rep in range(args.repeat):
            out = Path(tmp) / f"rep{rep}"
            measure(local, lambda o=out: sweep(runs, o / "j2", "--jobs", "2"))
            measure(dask, lambda o=out: sweep(runs, o / "dask", "--scheduler", address))
    load_after = os.getloadavg()
    print(
        f"{runs} runs of fig15 ({DURATION:g} s, 1,200 steps x 4 substeps), "
        f"median of {args.repeat}; load average (1, 5, 15 min) "
        f"{_load(load_before)} before, {_load(load_after)} after"
    )
    print()
    print("| engine | runs | per run [ms] | runs/s | physics / engine |")
    print("|---|---:|---:|---:|---:|")
    for name in (floor, local, dask):
        per = statistics.median(times[name])
        ratio = statistics.median(ratios[name]) if name in ratios else 1.0
        count = bare_runs if name == floor else runs
        print(f"| {name} | {count} | {1000 * per:.1f} | {1 / per:.1f} | {ratio:.3f} |")
    print()
    slower = [a / b for a, b in zip(ratios[local], ratios[dask], strict=True)]
    print(
        f"Dask time over --jobs 2 time: {statistics.median(slower):.2f}x (median; "
        f"target <= 1.3x); each repetition: {', '.join(f'{x:.2f}' for x in slower)}"
    )
    for name in (local, dask):
        each = ", ".join(f"{runs * t:.1f}" for t in times[name])
        print(f"{name}: {each} s per repetition")
    return 0


def _load(avg: tuple[float, float, float]) -> str:
    return ", ".join(f"{x:.2f}" for x in avg)


if __name__ == "__main__":
    raise SystemExit(main())
