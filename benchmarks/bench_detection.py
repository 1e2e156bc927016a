"""Detection delay, kind read and false alarms of ``residual`` and ``glr``, paired.

Each fault is ``scenarios/failures/detect_follower_stop.yaml``'s red failing with
another failure (``--set failures[0]...``), its onset drawn from the seed uniformly in
3-4 s (``randomize``), each run ``--after`` seconds past the latest onset, under
``position_noise`` / ``heading_noise`` of ``noise`` / ``noise / 2`` and the broadcast
``--delay``, over ``--seeds`` seeds (each draws other noise and another onset). Every
seed is run with each safety filter of ``--filters``: ``none``, ``cbf`` (the velocity
barrier) and ``braking`` (the braking barrier), the same starts, so that the filters
are compared pair by pair. The faults are the bundled large ones (the stop braking at
5 m/s^2, the crash, the spin at 3 rad/s, the steering stuck at -0.8 rad/s, the
runaway at 2 m/s and 0.5 rad/s) and small ones: a stop braking at 1 m/s^2, a
slow-down (the drive held at 0.8 m/s), a spin at 0.3 rad/s, the steering stuck at
+-0.2 and +-0.4 rad/s and a slow runaway (1.2 m/s, 0.1 rad/s). False alarms are also
counted on ``scenarios/failures/detect_fault_free.yaml`` (4 vehicles x 60 s a seed;
45 seeds = 3 vehicle-hours). A missed fault (no detection before the end) counts in
``missed``, not in the delays, and as a wrong kind. The runs of a setting are one
batch of worlds (:meth:`Simulation.batch <sandbox.Simulation.batch>`, each world
the bytes of its single run). Prints Markdown tables, with Wilson 95 % intervals::

    python benchmarks/bench_detection.py                  # every fault, filter, method
    python benchmarks/bench_detection.py --faults stop "slow stop" --seeds 20
    python benchmarks/bench_detection.py --methods glr --filters none --fault-free 0
    python benchmarks/bench_detection.py --tables runs.json   # a kept run's tables

``--json FILE`` also keeps every run's numbers.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections import Counter
from multiprocessing import Pool
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

FAILURES = ROOT / "scenarios" / "failures"
BASE = FAILURES / "detect_follower_stop.yaml"
FAULT_FREE = FAILURES / "detect_fault_free.yaml"
#: The onsets drawn, uniform [s].
ONSETS = (3.0, 4.0)
#: name -> (size, overrides of red's failure or vehicle).
FAULTS = {
    "stop": ("large", []),
    "crash": ("large", ["failures[0].kind=crash"]),
    "spin 3": ("large", ["failures[0].kind=spin", "failures[0].v2=3.0"]),
    "stuck_steering -0.8": (
        "large",
        ["failures[0].kind=stuck_steering", "failures[0].v2=-0.8"],
    ),
    "runaway": (
        "large",
        ["failures[0].kind=uncontrolled", "failures[0].v1=2.0", "failures[0].v2=0.5"],
    ),
    # red's drive brakes at 1 m/s^2 (its max_accel), not 5
    "slow stop": ("small", ["vehicles[1].max_accel=1.0"]),
    # the drive held at 0.8 m/s, straight on: a partial slow-down
    "slow-down": (
        "small",
        ["failures[0].kind=uncontrolled", "failures[0].v1=0.8", "failures[0].v2=0.0"],
    ),
    "spin 0.3": ("small", ["failures[0].kind=spin", "failures[0].v2=0.3"]),
    **{
        f"stuck_steering {v:+g}": (
            "small",
            ["failures[0].kind=stuck_steering", f"failures[0].v2={v}"],
        )
        for v in (0.2, -0.2, 0.4, -0.4)
    },
    # a 12 m-radius arc, against the bundled 2 m/s and 0.5 rad/s
    "slow runaway": (
        "small",
        ["failures[0].kind=uncontrolled", "failures[0].v1=1.2", "failures[0].v2=0.1"],
    ),
}
METHODS = {
    "residual": ["detection.method=residual", "detection.lambda=12"],
    "glr": ["detection.method=glr", "detection.lambda=null"],
}
FILTERS = {
    "none": ["safety.filter=none"],
    "cbf": ["safety.filter=cbf"],
    "braking": ["safety.filter=cbf", "safety.barrier=braking"],
}


def sensing_sets(noise: float, delay: float) -> list[str]:
    """Position noise ``noise`` [m], heading noise ``noise / 2`` [rad], a delay [s]."""
    return [
        f"sensing.position_noise={noise}",
        f"sensing.heading_noise={noise / 2}",
        f"sensing.delay={delay}",
    ]


def scenarios(task: tuple) -> list:
    """The scenarios of a task, one per seed."""
    from sandbox import load_scenario

    method, fault, filt, noise, delay, seeds, after = task
    sets = [*METHODS[method], *FILTERS[filt], *sensing_sets(noise, delay)]
    if fault is None:
        return [
            load_scenario(FAULT_FREE, overrides=[*sets, f"seed={s}"]) for s in seeds
        ]
    draw = {"failures[0].at": {"uniform": list(ONSETS)}}
    sets += [
        *FAULTS[fault][1],
        f"duration={ONSETS[1] + after}",
        f"randomize={json.dumps(draw)}",
    ]
    return [load_scenario(BASE, overrides=[*sets, f"seed={s}"]) for s in seeds]


def run(task: tuple) -> list[dict]:
    """Run a task, ``(method, fault or None, filter, noise, delay, seeds, after)``.

    Its seeds are one batch of worlds; one row per seed.
    """
    from sandbox import Simulation, compute_metrics

    method, fault, filt, noise, delay, seeds, _ = task
    scs = scenarios(task)
    out = []
    for seed, sc, r in zip(seeds, scs, Simulation.batch(scs), strict=True):
        det = compute_metrics(r)["detection"]
        row = {"method": method, "fault": fault, "filter": filt, "noise": noise}
        row |= {"delay_s": delay, "seed": seed}
        row["false_alarms"] = det["false_alarms"]
        row["hours"] = sc.duration * len(sc.vehicles) / 3600.0
        if fault is not None:
            (f,) = det["failures"]
            row |= {"at": f["at"], "delay": f["delay"], "kind": f["detected_kind"]}
            row["kind_right"] = bool(f["kind_right"])
        out.append(row)
    return out


def interval(k: int, n: int) -> str:
    """``k/n (lo-hi %)``: a count and its Wilson 95 % interval."""
    from sandbox.study.summary import wilson

    lo, hi = wilson(k, n)
    return f"{k}/{n} ({100 * lo:.0f}-{100 * hi:.0f} %)"


def quantile(values: list[float], q: float) -> str:
    """The ``q`` quantile of ``values`` to 0.01 (``-`` for none)."""
    if not values:
        return "-"
    if len(values) == 1:
        return f"{values[0]:.2f}"
    cuts = statistics.quantiles(values, n=100, method="inclusive")
    return f"{cuts[round(q * 100) - 1]:.2f}"


def fault_table(results: list[dict]) -> str:
    """Per method, fault, filter and noise: delays and the kinds read."""
    lines = [
        "| method | fault | size | filter | noise [m] | missed | median delay [s] "
        "| 90 % [s] | max [s] | kind right | read as | false alarms |",
        "|---|---|---|---|---|---:|---:|---:|---:|---:|---|---:|",
    ]
    keys = sorted(
        {(r["method"], r["fault"], r["filter"], r["noise"]) for r in results},
        key=lambda k: (k[0], list(FAULTS).index(k[1]), list(FILTERS).index(k[2]), k[3]),
    )
    for method, fault, filt, noise in keys:
        rs = [
            r
            for r in results
            if (r["method"], r["fault"], r["filter"], r["noise"])
            == (method, fault, filt, noise)
        ]
        delays = sorted(r["delay"] for r in rs if r["delay"] is not None)
        right = sum(r["kind_right"] for r in rs)
        read = Counter(r["kind"] or "missed" for r in rs)
        kinds = ", ".join(f"{k} {c}" for k, c in read.most_common())
        med = f"{statistics.median(delays):.2f}" if delays else "-"
        top = f"{delays[-1]:.2f}" if delays else "-"
        fa = sum(r["false_alarms"] for r in rs)
        lines.append(
            f"| {method} | {fault} | {FAULTS[fault][0]} | {filt} | {noise:g} "
            f"| {len(rs) - len(delays)} | {med} | {quantile(delays, 0.9)} | {top} "
            f"| {interval(right, len(rs))} | {kinds} | {fa} |"
        )
    return "\n".join(lines)


def paired_table(results: list[dict]) -> str:
    """Each filter against none on the same seeds: how much later it detects."""
    lines = [
        "| method | fault | noise [m] | filter | pairs | median delay, none -> filter "
        "[s] | median difference [s] | later by > 0.05 s | missed, none -> filter |",
        "|---|---|---|---|---:|---|---:|---:|---|",
    ]
    index = {
        (r["method"], r["fault"], r["filter"], r["noise"], r["seed"]): r
        for r in results
    }
    keys = sorted(
        {(r["method"], r["fault"], r["filter"], r["noise"]) for r in results},
        key=lambda k: (k[0], list(FAULTS).index(k[1]), k[3], list(FILTERS).index(k[2])),
    )
    for method, fault, filt, noise in keys:
        if filt == "none":
            continue
        pairs = [
            (index[(method, fault, "none", noise, r["seed"])], r)
            for r in results
            if (r["method"], r["fault"], r["filter"], r["noise"])
            == (method, fault, filt, noise)
            and (method, fault, "none", noise, r["seed"]) in index
        ]
        if not pairs:
            continue
        end = ONSETS[1] + 60.0  # a missed fault: later than any delay
        both = [
            (a["delay"] if a["delay"] is not None else end - a["at"],
             b["delay"] if b["delay"] is not None else end - b["at"])
            for a, b in pairs
        ]  # fmt: skip
        diff = statistics.median(b - a for a, b in both)
        later = sum(b > a + 0.05 + 1e-9 for a, b in both)
        found = [
            [r["delay"] for r in side if r["delay"] is not None]
            for side in zip(*pairs, strict=True)
        ]
        med = " -> ".join(f"{statistics.median(d):.2f}" if d else "-" for d in found)
        missed = " -> ".join(str(len(pairs) - len(d)) for d in found)
        lines.append(
            f"| {method} | {fault} | {noise:g} | {filt} | {len(pairs)} | {med} "
            f"| {diff:+.2f} | {interval(later, len(pairs))} | {missed} |"
        )
    return "\n".join(lines)


def free_table(free: list[dict]) -> str:
    """False alarms on the fault-free platoon."""
    lines = [
        "| method | filter | noise [m] | fault-free runs | vehicle-hours "
        "| false alarms |",
        "|---|---|---|---:|---:|---:|",
    ]
    for method, filt, noise in sorted(
        {(r["method"], r["filter"], r["noise"]) for r in free}
    ):
        rs = [
            r
            for r in free
            if (r["method"], r["filter"], r["noise"]) == (method, filt, noise)
        ]
        hours = sum(r["hours"] for r in rs)
        fa = sum(r["false_alarms"] for r in rs)
        lines.append(
            f"| {method} | {filt} | {noise:g} | {len(rs)} | {hours:.2f} | {fa} |"
        )
    return "\n".join(lines)


def tables(results: list[dict]) -> str:
    """Every table of the results."""
    faulty = [r for r in results if r["fault"] is not None]
    free = [r for r in results if r["fault"] is None]
    parts = []
    if faulty:
        parts += [fault_table(faulty), paired_table(faulty)]
    if free:
        parts.append(free_table(free))
    return "\n\n".join(p for p in parts if p.count("\n") > 1)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=60, help="seeds per setting")
    parser.add_argument("--fault-free", type=int, default=45, help="fault-free seeds")
    parser.add_argument(
        "--after", type=float, default=3.0, help="[s] run past the latest onset"
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--filters", nargs="+", default=list(FILTERS), choices=FILTERS)
    parser.add_argument("--noises", nargs="+", type=float, default=[0.02])
    parser.add_argument("--delay", type=float, default=0.05, help="[s] broadcast delay")
    parser.add_argument(
        "--fault-free-filters",
        nargs="+",
        default=["none"],
        choices=FILTERS,
        help="filters of the fault-free runs",
    )
    parser.add_argument("--faults", nargs="+", default=list(FAULTS), choices=FAULTS)
    parser.add_argument("--json", type=Path, help="keep every run's numbers")
    parser.add_argument(
        "--tables", type=Path, help="print the tables of a --json file, run nothing"
    )
    args = parser.parse_args(argv)
    if args.tables is not None:
        print(tables(json.loads(args.tables.read_text(encoding="utf-8"))))
        return 0
    seeds = tuple(range(args.seeds))
    tasks = [
        (method, fault, filt, noise, args.delay, seeds, args.after)
        for method in args.methods
        for fault in args.faults
        for filt in args.filters
        for noise in args.noises
    ]
    free = tuple(range(args.fault_free))
    tasks += [
        (method, None, filt, noise, args.delay, free, None)
        for method in args.methods
        for filt in args.fault_free_filters
        for noise in args.noises
        if free
    ]
    # the slowest first (the braking barrier, the fault-free hour), for the pool
    tasks.sort(key=lambda task: (task[1] is not None, task[2] != "braking"))
    start = time.perf_counter()
    results = []
    with Pool(args.jobs) as pool:
        for k, rows in enumerate(pool.imap_unordered(run, tasks, chunksize=1), 1):
            results += rows
            print(f"{k}/{len(tasks)} settings", file=sys.stderr, flush=True)
    elapsed = time.perf_counter() - start
    print(tables(results))
    runs = len(results)
    print(f"\n{runs} runs in {elapsed:.0f} s with {args.jobs} worker processes")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
