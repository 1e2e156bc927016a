"""Detection delay, kind accuracy and false alarms of ``residual`` and ``glr``.

Each small fault is ``scenarios/failures/detect_follower_stuck_steering.yaml``'s red
failing at 3 s with another failure (``--set failures[0]...``), run for
``--duration`` seconds under ``position_noise`` / ``heading_noise`` of
1 cm / 0.005 rad and 2 cm / 0.01 rad, over ``--seeds`` seeds (each draws other
noise); false alarms are counted on ``scenarios/failures/detect_fault_free.yaml``
(4 vehicles x 60 s a seed; 45 seeds = 3 vehicle-hours). A missed fault (no
detection before the end) counts in ``missed`` and not in the delays. Prints a
Markdown table::

    python benchmarks/bench_detection.py                     # everything
    python benchmarks/bench_detection.py --seeds 10 --fault-free 5 --jobs 2
    python benchmarks/bench_detection.py --methods glr --noises 0.02

``--json FILE`` also keeps every run's numbers.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from multiprocessing import Pool
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

FAILURES = ROOT / "scenarios" / "failures"
BASE = FAILURES / "detect_follower_stuck_steering.yaml"
FAULT_FREE = FAILURES / "detect_fault_free.yaml"
#: name -> overrides of the failure (red at 3 s).
FAULTS = {
    "stuck_steering +0.2": ["failures[0].v2=0.2"],
    "stuck_steering -0.2": ["failures[0].v2=-0.2"],
    "stuck_steering +0.4": ["failures[0].v2=0.4"],
    "stuck_steering -0.4": ["failures[0].v2=-0.4"],
    # A slow runaway: constant 1.2 m/s and 0.1 rad/s (a 12 m-radius arc), against
    # the bundled 2 m/s and 0.5 rad/s.
    "slow runaway": [
        "failures[0].kind=uncontrolled",
        "failures[0].v1=1.2",
        "failures[0].v2=0.1",
    ],
}
METHODS = {
    "residual": ["detection.method=residual", "detection.lambda=12"],
    "glr": ["detection.method=glr", "detection.lambda=null"],
}


def noise_sets(noise: float) -> list[str]:
    """Position noise ``noise`` [m] and heading noise ``noise / 2`` [rad]."""
    return [f"sensing.position_noise={noise}", f"sensing.heading_noise={noise / 2}"]


def one(task: tuple) -> dict:
    """Run one task: ``(method, fault or None, noise, seed, duration)``."""
    from sandbox import compute_metrics, load_scenario, simulate

    method, fault, noise, seed, duration = task
    sets = [*METHODS[method], *noise_sets(noise), f"seed={seed}"]
    if fault is None:
        sc = load_scenario(FAULT_FREE, overrides=sets)
    else:
        sets += [*FAULTS[fault], f"duration={duration}"]
        sc = load_scenario(BASE, overrides=sets)
    m = compute_metrics(simulate(sc))
    det = m["detection"]
    out = {"method": method, "fault": fault, "noise": noise, "seed": seed}
    out["false_alarms"] = det["false_alarms"]
    out["hours"] = sc.duration * len(sc.vehicles) / 3600.0
    if fault is not None:
        (f,) = det["failures"]
        out["delay"] = f["delay"]
        out["kind"] = f["detected_kind"]
        out["kind_right"] = f["kind_right"]
    return out


def table(results: list[dict]) -> str:
    """The Markdown table of the results."""
    lines = []
    if any(r["fault"] for r in results):
        lines += [
            "| method | fault | noise [m] | seeds | missed | median delay [s] "
            "| max delay [s] | kind right | false alarms in failure runs |",
            "|---|---|---|---:|---:|---:|---:|---:|---:|",
        ]
    keys = sorted(
        {(r["method"], r["fault"], r["noise"]) for r in results if r["fault"]},
        key=lambda k: (k[0], list(FAULTS).index(k[1]), k[2]),
    )
    for method, fault, noise in keys:
        rs = [
            r
            for r in results
            if (r["method"], r["fault"], r["noise"]) == (method, fault, noise)
        ]
        delays = [r["delay"] for r in rs if r["delay"] is not None]
        right = sum(bool(r["kind_right"]) for r in rs)
        med = f"{statistics.median(delays):.2f}" if delays else "-"
        top = f"{max(delays):.2f}" if delays else "-"
        fa = sum(r["false_alarms"] for r in rs)
        lines.append(
            f"| {method} | {fault} | {noise:g} | {len(rs)} | {len(rs) - len(delays)} "
            f"| {med} | {top} | {right}/{len(rs)} ({100 * right / len(rs):.0f} %) "
            f"| {fa} |"
        )
    free = [r for r in results if r["fault"] is None]
    if free:
        lines += [
            *([""] if lines else []),
            "| method | noise [m] | fault-free runs | vehicle-hours | false alarms |",
            "|---|---|---:|---:|---:|",
        ]
        for method, noise in sorted({(r["method"], r["noise"]) for r in free}):
            rs = [r for r in free if (r["method"], r["noise"]) == (method, noise)]
            hours = sum(r["hours"] for r in rs)
            fa = sum(r["false_alarms"] for r in rs)
            lines.append(f"| {method} | {noise:g} | {len(rs)} | {hours:.2f} | {fa} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=40, help="seeds per fault")
    parser.add_argument("--fault-free", type=int, default=45, help="fault-free seeds")
    parser.add_argument("--duration", type=float, default=6.0, help="[s] per run")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--methods", nargs="+", default=list(METHODS))
    parser.add_argument("--noises", nargs="+", type=float, default=[0.01, 0.02])
    parser.add_argument(
        "--fault-free-noises",
        nargs="+",
        type=float,
        default=None,
        help="noises of the fault-free runs (default: --noises)",
    )
    parser.add_argument("--faults", nargs="+", default=list(FAULTS))
    parser.add_argument("--json", type=Path, help="keep every run's numbers")
    args = parser.parse_args(argv)
    tasks = [
        (method, fault, noise, seed, args.duration)
        for method in args.methods
        for fault in args.faults
        for noise in args.noises
        for seed in range(args.seeds)
    ]
    free_noises = (
        args.noises if args.fault_free_noises is None else (args.fault_free_noises)
    )
    tasks += [
        (method, None, noise, seed, None)
        for method in args.methods
        for noise in free_noises
        for seed in range(args.fault_free)
    ]
    start = time.perf_counter()
    with Pool(args.jobs) as pool:
        results = []
        for k, r in enumerate(pool.imap_unordered(one, tasks, chunksize=1), 1):
            results.append(r)
            if k % 20 == 0 or k == len(tasks):
                print(f"{k}/{len(tasks)} runs", file=sys.stderr, flush=True)
    elapsed = time.perf_counter() - start
    print(table(results))
    print(f"\n{len(tasks)} runs in {elapsed:.0f} s with {args.jobs} workers")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
