"""Many small runs: single runs, batches of worlds and sweeps against bare physics.

The workload of a study: the Fig. 15 scenario (three vehicles, 12 s, 1,200 control
steps of 4 substeps), ``--runs`` times (default 256).

- ``bare pymunk``: for each run, the scenario's pymunk world (the same bodies, motor
  joints and obstacles, built by :class:`sandbox.physics.world.World`) stepped 1,200
  control periods of ``substeps`` calls of ``Space.step`` with fixed commands: no
  controller, no law, no recovery, no recording, no metrics: the floor a sweep
  could reach.
- ``single runs``: ``Simulation(scenario).run()`` and ``compute_metrics``, one run
  after the other (``--single`` runs of them, default 16: they are slow).
- ``batch of K``: the runs as K worlds of the one loop
  (``Simulation.stacked(scenarios).run_all()``; building, stepping, metrics).
- ``sweep --jobs 1`` and ``--jobs 2``: the whole ``sandbox sweep`` command, in-process
  (``sandbox.cli.main``; scenario loading, batches of up to 128 worlds, metrics, the
  results store); and ``--jobs 1`` again with ``safety: {filter: cbf}``,
  ``detection: {method: residual}``, ``sensing: {position_noise: 0.01}``, and the
  leader crashing at 6 s with ``on_leader_failure: elect`` and ``reconfigure:
  {assign: hungarian}`` (a handover and a reassignment in every run), each against
  the bare physics of the same bodies.

Every row is timed once per repetition, in one process, with the bare physics timed
just before and just after it (``--bare`` runs each time, default 64): the ratio is
the bare-physics time per run over the row's time per run (1.0: the row runs at the
physics' own speed), the median over ``--repeat`` repetitions (default 3). Timing the
floor beside each row keeps the ratios fair on a machine whose load changes while the
benchmark runs; the load averages before and after are printed with the table.

With ``--scaling RUNS`` (the target: 1,024) it also times ``--jobs 1`` against
``--jobs 2`` on that many runs (the pool's workers forked from the sweep, then from a
fork server), and beside it the machine's own two-core speed-up: the same batches in
one process alone, then in two processes at once (``--scaling-only``: these rows
alone).

    python benchmarks/bench_sweep.py                      # 256 runs, 3 repetitions
    python benchmarks/bench_sweep.py --runs 64 --repeat 1  # quicker
    python benchmarks/bench_sweep.py --scaling 1024       # and --jobs 2 scaling
    python benchmarks/bench_sweep.py --scaling 1024 --scaling-only --repeat 5
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sandbox.cli import main as sandbox_main  # noqa: E402
from sandbox.loop.simulation import Simulation  # noqa: E402
from sandbox.physics.world import World  # noqa: E402
from sandbox.run.metrics import compute_metrics  # noqa: E402
from sandbox.scenario import load_scenario  # noqa: E402
from sandbox.study.engine import usable_cores  # noqa: E402

SCENARIO = ROOT / "scenarios" / "paper" / "fig15_continuous_beta1.yaml"
DURATION = 12.0
SIZES = (16, 64, 128, 256)


def scenario():
    """The benchmark's scenario (fig15 cut to 12 s)."""
    return load_scenario(SCENARIO, overrides=[f"duration={DURATION}"])


def bare_physics(runs: int) -> float:
    """Seconds to step ``runs`` fresh worlds of the scenario for its whole duration."""
    return step_bare(scenario(), runs)


def step_bare(sc, runs: int) -> float:
    """Seconds to step ``runs`` fresh worlds of ``sc`` for its whole duration.

    The scenario's pymunk world (its bodies, motor joints and obstacles), fixed
    commands: no controller, no law, no recording.
    """
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


def single_runs(runs: int) -> float:
    """Seconds for ``runs`` single runs with their metrics."""
    sc = scenario()
    t0 = time.perf_counter()
    for _ in range(runs):
        compute_metrics(Simulation(sc).run())
    return time.perf_counter() - t0


def batched(runs: int, size: int) -> float:
    """Seconds for ``runs`` runs as batches of ``size`` worlds, with their metrics."""
    sc = scenario()
    t0 = time.perf_counter()
    for start in range(0, runs, size):
        k = min(size, runs - start)
        for run in Simulation.stacked([sc] * k).run_all():
            compute_metrics(run)
    return time.perf_counter() - t0


#: The features measured in a sweep of their own: (row name, --set assignments).
FEATURES = (
    ("safety: {filter: cbf}", ("safety.filter=cbf",)),
    ("detection: {method: residual}", ("detection.method=residual",)),
    ("sensing: {position_noise: 0.01}", ("sensing.position_noise=0.01",)),
    (
        "the leader crashing at 6 s, re-formed (elect, hungarian)",
        (
            "failures=[{vehicle: leader, at: 6.0, kind: crash}]",
            "on_leader_failure=elect",
            "reconfigure={assign: hungarian, close_gap: true}",
        ),
    ),
)


def sweep(runs: int, jobs: int, out: Path, extra: tuple[str, ...] = ()) -> float:
    """Seconds of ``sandbox sweep`` over ``runs`` seeds into a fresh directory."""
    argv = ["sweep", str(SCENARIO), "--set", f"duration={DURATION}"]
    for assignment in extra:
        argv += ["--set", assignment]
    argv += ["--seeds", f"0:{runs}", "--jobs", str(jobs), "--out", str(out)]
    t0 = time.perf_counter()
    code = sandbox_main(argv)
    elapsed = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"sandbox sweep failed with status {code}")
    return elapsed


def _batch_process(runs: int) -> subprocess.Popen:
    """A fresh process that prints the seconds of ``batched(runs, 128)``.

    Its imports and a warm-up are not timed.
    """
    code = (
        "import sys, time; sys.path.insert(0, sys.argv[1]); "
        "from bench_sweep import batched; batched(8, 8); t = time.perf_counter(); "
        "batched(int(sys.argv[2]), 128); print(time.perf_counter() - t)"
    )
    here = str(Path(__file__).resolve().parent)
    return subprocess.Popen(
        [sys.executable, "-c", code, here, str(runs)], stdout=subprocess.PIPE, text=True
    )


def ceiling(runs: int) -> float:
    """The machine's own speed-up on two cores: one batch alone against two at once.

    The same work (``runs`` runs in batches of 128) in one process, then in two
    processes started together: ``2 t_alone / t_pair`` (2.0: the two cores are
    independent; less where they share a physical core, caches or memory bandwidth,
    or the host is busy). No sweep can scale beyond it.
    """
    alone = float(_batch_process(runs).communicate()[0])
    pair = [_batch_process(runs) for _ in range(2)]
    both = max(float(p.communicate()[0]) for p in pair)
    return 2 * alone / both


def served_pool(start: bool = False):
    """A pool's start method without the fork: a fork server, its imports preloaded."""
    import multiprocessing as mp

    from sandbox.study import engine

    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(engine.PRELOAD)
    if start:
        from multiprocessing import forkserver

        forkserver.ensure_running()
    return ctx


def scaling(runs: int, repeat: int, out: Path) -> dict[str, list[float]]:
    """``--jobs 2`` over ``--jobs 1`` on ``runs`` runs, and the machine's ceiling.

    Each repetition times ``sandbox sweep --jobs 1``, ``--jobs 2`` (its workers
    forked from the sweep, as on Linux), ``--jobs 2`` with its workers from a fork
    server (as beside threads, or before workers were forked from the sweep) and
    :func:`ceiling`, one after the other (each sweep into a fresh store, the pool
    started by the command as a user's is). Returns the lists of speed-ups over
    ``--jobs 1`` (``"fork"``, ``"fork server"``) and of ceilings (``"ceiling"``).
    """
    from sandbox.study import engine

    found: dict[str, list[float]] = {"fork": [], "fork server": [], "ceiling": []}
    forked = engine.pool_context
    for rep in range(repeat):
        one = sweep(runs, 1, out / f"s{rep}j1")
        found["fork"].append(one / sweep(runs, 2, out / f"s{rep}j2"))
        engine.pool_context = served_pool
        try:
            found["fork server"].append(one / sweep(runs, 2, out / f"s{rep}j2s"))
        finally:
            engine.pool_context = forked
        found["ceiling"].append(ceiling(runs))
    return found


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=256, help="runs per measurement")
    p.add_argument("--single", type=int, default=16, help="single runs measured")
    p.add_argument("--bare", type=int, default=64, help="bare runs beside each row")
    p.add_argument("--repeat", type=int, default=3, help="repetitions (median)")
    p.add_argument(
        "--scaling",
        type=int,
        default=0,
        metavar="RUNS",
        help="also time --jobs 1 against --jobs 2 on RUNS runs (the target: 1024), "
        "beside the machine's own two-core speed-up",
    )
    p.add_argument(
        "--scaling-only",
        action="store_true",
        help="time the --scaling rows only (not the table of 256 runs)",
    )
    args = p.parse_args(argv)
    if args.scaling_only:
        if not args.scaling or usable_cores() < 2:
            p.error("--scaling-only needs --scaling RUNS and two usable cores")
        with tempfile.TemporaryDirectory() as tmp:
            found = scaling(args.scaling, args.repeat, Path(tmp))
        print_scaling(args.scaling, found)
        return 0
    runs, cores, bare_runs = args.runs, usable_cores(), min(args.bare, args.runs)
    rows: dict[str, tuple[int, list[float]]] = {}
    ratios: dict[str, list[float]] = {}
    floor = "bare pymunk (same bodies, joints, steps)"

    def measure(name: str, count: int, run) -> None:
        before = bare_physics(bare_runs)
        seconds = run()
        after = bare_physics(bare_runs)
        phys = (before + after) / (2 * bare_runs)  # per run
        rows.setdefault(floor, (bare_runs, []))[1].extend((before, after))
        rows.setdefault(name, (count, []))[1].append(seconds)
        ratios.setdefault(name, []).append(phys / (seconds / count))

    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(args.repeat):
            out = Path(tmp) / f"rep{rep}"
            measure(
                "single runs (Simulation.run)",
                args.single,
                lambda: single_runs(args.single),
            )
            for size in SIZES:
                if size <= runs:
                    measure(
                        f"batch of {size} worlds", runs, lambda s=size: batched(runs, s)
                    )
            measure(
                "sandbox sweep --jobs 1", runs, lambda o=out: sweep(runs, 1, o / "j1")
            )
            for k, (name, assignments) in enumerate(FEATURES):
                measure(
                    f"sandbox sweep --jobs 1, {name}",
                    runs,
                    lambda o=out, a=assignments, k=k: sweep(runs, 1, o / f"f{k}", a),
                )
            if cores > 1:
                measure(
                    "sandbox sweep --jobs 2",
                    runs,
                    lambda o=out: sweep(runs, 2, o / "j2"),
                )
    load_after = os.getloadavg()
    print(
        f"{runs} runs of fig15 ({DURATION:g} s, 1,200 steps x 4 substeps), "
        f"{cores} usable cores, median of {args.repeat}; load average (1, 5, 15 min) "
        f"{_load(load_before)} before, {_load(load_after)} after"
    )
    print()
    print("| engine | runs | per run [ms] | runs/s | physics / engine |")
    print("|---|---:|---:|---:|---:|")
    ratios[floor] = [1.0]
    for name, (count, times) in [(floor, rows[floor])] + [
        item for item in rows.items() if item[0] != floor
    ]:
        per = statistics.median(times) / count
        print(
            f"| {name} | {count} | {1000 * per:.1f} | {1 / per:.1f} | "
            f"{statistics.median(ratios[name]):.3f} |"
        )
    print()
    if "sandbox sweep --jobs 2" in ratios:
        speedup = [
            b / a
            for a, b in zip(
                ratios["sandbox sweep --jobs 1"],
                ratios["sandbox sweep --jobs 2"],
                strict=True,
            )
        ]
        print(f"--jobs 2 over --jobs 1: {statistics.median(speedup):.2f}x (median)")
    if args.scaling and cores > 1:
        with tempfile.TemporaryDirectory() as tmp:
            found = scaling(args.scaling, args.repeat, Path(tmp))
        print_scaling(args.scaling, found)
    return 0


def print_scaling(runs: int, found: dict[str, list[float]]) -> None:
    """The table of :func:`scaling`: medians, and each repetition."""
    print()
    print(f"| {runs} runs | median | each repetition |")
    print("|---|---:|---|")
    names = {
        "fork": "--jobs 2 over --jobs 1 (workers forked from the sweep)",
        "fork server": "--jobs 2 over --jobs 1 (workers from a fork server)",
        "ceiling": "two batches at once over one alone (the machine's ceiling)",
    }
    for key, name in names.items():
        each = ", ".join(f"{x:.2f}" for x in found[key])
        print(f"| {name} | {statistics.median(found[key]):.2f}x | {each} |")


def _load(avg: tuple[float, float, float]) -> str:
    return ", ".join(f"{x:.2f}" for x in avg)


if __name__ == "__main__":
    raise SystemExit(main())
