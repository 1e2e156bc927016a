"""Many small runs: ``sandbox sweep`` against the bare physics of the same runs.

The workload of a study: the Fig. 15 scenario (three vehicles, 12 s, 1,200 control
steps of 4 substeps), ``--runs`` times (default 256), seeds 0 to runs-1.

- ``bare pymunk``: for each run, the scenario's pymunk world (the same bodies, motor
  joints and obstacles, built by :class:`sandbox.world.World`) stepped 1,200 control
  periods of ``substeps`` calls of ``Space.step`` with fixed commands: no controller,
  no law, no recovery, no recording, no metrics. The floor a sweep could reach.
- ``sweep --jobs 1`` and ``--jobs 2``: the whole ``sandbox sweep`` command, in-process
  (``sandbox.cli.main``; scenario loading, simulation, metrics, the results store).

The ratio is bare-physics time over sweep time (1.0: the sweep runs at the physics'
own speed). The physics is measured before and after the sweeps, in the same process,
and the mean is used.

    python benchmarks/bench_sweep.py            # 256 runs
    python benchmarks/bench_sweep.py --runs 32  # quicker
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sandbox.cli import main as sandbox_main  # noqa: E402
from sandbox.scenario import load_scenario  # noqa: E402
from sandbox.study.engine import usable_cores  # noqa: E402
from sandbox.world import World  # noqa: E402

SCENARIO = ROOT / "scenarios" / "paper" / "fig15_continuous_beta1.yaml"
DURATION = 12.0


def bare_physics(runs: int) -> float:
    """Seconds to step ``runs`` fresh worlds of the scenario for its whole duration."""
    sc = load_scenario(SCENARIO, overrides=[f"duration={DURATION}"])
    steps = int(round(sc.duration / sc.dt))
    n = len(sc.vehicles)
    theta = np.array([v.pose[2] for v in sc.vehicles])
    h, sub = sc.dt, sc.substeps
    t0 = time.perf_counter()
    for _ in range(runs):
        world = World(sc.vehicles, sc.obstacles, sc.metrics.contact_release, sub)
        world.write_commands(theta, np.full(n, 1.0), np.zeros(n), h)
        space, dt = world.space, h / sub
        for _ in range(steps * sub):
            space.step(dt)
    return time.perf_counter() - t0


def sweep(runs: int, jobs: int, out: Path) -> float:
    """Seconds of ``sandbox sweep`` over ``runs`` seeds into a fresh directory."""
    argv = ["sweep", str(SCENARIO), "--set", f"duration={DURATION}"]
    argv += ["--seeds", f"0:{runs}", "--jobs", str(jobs), "--out", str(out)]
    t0 = time.perf_counter()
    code = sandbox_main(argv)
    elapsed = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"sandbox sweep failed with status {code}")
    return elapsed


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=256, help="runs per measurement")
    args = p.parse_args(argv)
    runs = args.runs
    cores = usable_cores()
    with tempfile.TemporaryDirectory() as tmp:
        phys_a = bare_physics(runs)
        one = sweep(runs, 1, Path(tmp) / "jobs1")
        two = sweep(runs, min(2, cores), Path(tmp) / "jobs2") if cores > 1 else None
        phys_b = bare_physics(runs)
    phys = (phys_a + phys_b) / 2
    print(
        f"{runs} runs of fig15 ({DURATION:g} s, 1,200 steps x 4 substeps), "
        f"{cores} usable cores"
    )
    print()
    print("| engine | wall [s] | per run [ms] | runs/s | physics / engine |")
    print("|---|---:|---:|---:|---:|")
    rows = [("bare pymunk (same bodies, joints, steps)", phys)]
    rows.append(("sandbox sweep --jobs 1", one))
    if two is not None:
        rows.append(("sandbox sweep --jobs 2", two))
    for name, t in rows:
        print(
            f"| {name} | {t:.2f} | {1000 * t / runs:.1f} | {runs / t:.1f} | "
            f"{phys / t:.3f} |"
        )
    print()
    print(f"bare physics before / after the sweeps: {phys_a:.2f} s / {phys_b:.2f} s")
    if two is not None:
        print(f"--jobs 2 speed-up over --jobs 1: {one / two:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
