"""Full-feature sweeps and single runs against the bare physics of the same steps.

Two tables, every figure a ratio: the bare pymunk physics' time per run over the
row's (1.0: the row runs at the physics' own speed).

**Sweeps** (``sandbox sweep --jobs 1``, ``--runs`` seeds, default 128, in-process):
the follower-stop platoon (``scenarios/failures/follower_stop.yaml``: four vehicles,
the rotating law, continuous recovery, red's motors stopping at 3 s) cut to 8 s
(800 control periods of 4 substeps), as written; then with each feature alone,
``safety: {filter: cbf}``, ``sensing: {position_noise: 0.01}`` and ``detection:
{method: residual}`` (which, with the failure, detects the stop and reads its kind
from the track); then with the three together. The bare physics (the scenario's
pymunk world, its bodies, motor joints and steps, fixed commands: the floor) is
timed just before and just after each row.

**Single runs** (``Simulation(scenario).run()`` and the run's metrics, one run after
the other): N = 3, 5 and 10 vehicles of the workload of ``bench_scale.py`` (a grid
on a straight ``virtual`` reference at 1 m/s, ``continuous`` recovery), 2,000
control periods, and the Fig. 15 platoon of three (12 s), each against its bare
physics timed beside it.

Targets (issue 35): the combined sweep >= 0.35, each feature alone >= 0.6, single
runs at N = 10 >= 0.2. The median over ``--repeat`` repetitions (default 3); the
load averages before and after are printed with the tables. Not a test: a table.

    python benchmarks/bench_full_features.py
    python benchmarks/bench_full_features.py --runs 64 --repeat 1   # quicker
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_scale import scenario_doc  # noqa: E402
from bench_sweep import step_bare  # noqa: E402

from sandbox.cli import main as sandbox_main  # noqa: E402
from sandbox.loop.simulation import Simulation  # noqa: E402
from sandbox.run.metrics import compute_metrics  # noqa: E402
from sandbox.scenario import load_scenario  # noqa: E402

SCENARIO = ROOT / "scenarios" / "failures" / "follower_stop.yaml"
DURATION = 8.0
FIG15 = ROOT / "scenarios" / "paper" / "fig15_continuous_beta1.yaml"

#: The sweep rows: (row name, --set assignments).
FEATURES = (
    ("as written (the failure only)", ()),
    ("safety: {filter: cbf}", ("safety.filter=cbf",)),
    ("sensing: {position_noise: 0.01}", ("sensing.position_noise=0.01",)),
    ("detection: {method: residual}", ("detection.method=residual",)),
    (
        "all three",
        (
            "safety.filter=cbf",
            "sensing.position_noise=0.01",
            "detection.method=residual",
        ),
    ),
)

#: The single-run rows: (row name, scenario loader).
SINGLES = (
    ("N = 3, grid, virtual, continuous", lambda: _grid(3)),
    ("N = 5, grid, virtual, continuous", lambda: _grid(5)),
    ("N = 10, grid, virtual, continuous", lambda: _grid(10)),
    (
        "N = 3, fig15 (12 s)",
        lambda: load_scenario(FIG15, overrides=["duration=12"]),
    ),
)


def _grid(n: int):
    with warnings.catch_warnings():  # the workload's slots are within R: known
        warnings.simplefilter("ignore")
        return load_scenario(scenario_doc(n, 2000))


def sweep_scenario(extra: tuple[str, ...]):
    """The sweep's scenario with the row's assignments (for its bare physics)."""
    return load_scenario(SCENARIO, overrides=[f"duration={DURATION}", *extra])


def sweep(runs: int, out: Path, extra: tuple[str, ...]) -> float:
    """Seconds of ``sandbox sweep --jobs 1`` over ``runs`` seeds."""
    argv = ["sweep", str(SCENARIO), "--set", f"duration={DURATION}"]
    for assignment in extra:
        argv += ["--set", assignment]
    argv += ["--seeds", f"0:{runs}", "--jobs", "1", "--out", str(out)]
    t0 = time.perf_counter()
    code = sandbox_main(argv)
    elapsed = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"sandbox sweep failed with status {code}")
    return elapsed


def single(sc, runs: int) -> float:
    """Seconds of ``runs`` single runs of ``sc`` with their metrics."""
    t0 = time.perf_counter()
    for _ in range(runs):
        compute_metrics(Simulation(sc).run())
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=128, help="seeds of each sweep")
    p.add_argument("--bare", type=int, default=32, help="bare runs beside each row")
    p.add_argument("--single", type=int, default=3, help="single runs of each row")
    p.add_argument("--repeat", type=int, default=3, help="repetitions (median)")
    p.add_argument("--only", choices=("sweeps", "singles"), help="one table only")
    args = p.parse_args(argv)
    ratios: dict[str, list[float]] = {}
    per_run: dict[str, list[float]] = {}

    def measure(name: str, sc, count: int, bare_count: int, run) -> None:
        before = step_bare(sc, bare_count)
        seconds = run()
        after = step_bare(sc, bare_count)
        phys = (before + after) / (2 * bare_count)
        ratios.setdefault(name, []).append(phys / (seconds / count))
        per_run.setdefault(name, []).append(seconds / count)

    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        # Not timed: the first sweep imports what a sweep needs (the store, metrics,
        # the features' modules), which no row should pay.
        sweep(8, Path(tmp) / "warm-up", FEATURES[-1][1])
        for rep in range(args.repeat):
            if args.only != "singles":
                for k, (name, extra) in enumerate(FEATURES):
                    out = Path(tmp) / f"r{rep}f{k}"
                    measure(
                        f"sweep: {name}",
                        sweep_scenario(extra),
                        args.runs,
                        args.bare,
                        lambda o=out, e=extra: sweep(args.runs, o, e),
                    )
            if args.only != "sweeps":
                for name, make in SINGLES:
                    sc = make()
                    measure(
                        f"single: {name}",
                        sc,
                        args.single,
                        args.single,
                        lambda s=sc: single(s, args.single),
                    )
    load_after = os.getloadavg()
    print(
        f"median of {args.repeat}; sweeps of {args.runs} seeds of follower_stop "
        f"({DURATION:g} s) with --jobs 1; load average (1, 5, 15 min) "
        f"{_load(load_before)} before, {_load(load_after)} after"
    )
    print()
    print("| row | per run [ms] | physics / row | each repetition |")
    print("|---|---:|---:|---|")
    for name, found in ratios.items():
        each = ", ".join(f"{x:.3f}" for x in found)
        print(
            f"| {name} | {1000 * statistics.median(per_run[name]):.1f} | "
            f"{statistics.median(found):.3f} | {each} |"
        )
    return 0


def _load(avg: tuple[float, float, float]) -> str:
    return ", ".join(f"{x:.2f}" for x in avg)


if __name__ == "__main__":
    raise SystemExit(main())
