"""The CBF filter's stage per control period in a batch of K worlds: C against numpy.

The workload of ``bench_full_features.py``'s filter row: K seeds (default 64, a
sweep's group) of the follower-stop platoon (``scenarios/failures/follower_stop.yaml``,
four vehicles, 8 s) with ``safety: {filter: cbf}``, run as one batch
(``Simulation.batch``). Each period it times, per call:

- ``stage``: the loop's safety stage (``Safety.commands``: the filter's context
  for the K worlds, the filter, its counters, the commands' copies);
- ``filter``: :func:`~sandbox.behaviour.safety.cbf.filter_commands` alone;
- ``counters``: :func:`~sandbox.behaviour.safety.accounting.account_worlds` alone.

and the batch's time per run. The C path (``filter_kernel.py``, ``accounting.py``)
and the numpy path (``sandbox.accel.switched_off("filter")``) alternate in this process,
``--repeat`` times each (default 3), so their ratio is measured on one machine state;
the table gives each path's median over the repetitions of the mean per period, and
the load averages before and after. Not a test: a table.

    python benchmarks/bench_filter_stage.py
    python benchmarks/bench_filter_stage.py --worlds 128 --repeat 5
    python benchmarks/bench_filter_stage.py --set sensing.position_noise=0.01
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sandbox import accel  # noqa: E402
from sandbox.behaviour.safety import cbf  # noqa: E402
from sandbox.loop.safety import Safety  # noqa: E402
from sandbox.loop.simulation import Simulation  # noqa: E402
from sandbox.scenario import load_scenario  # noqa: E402

SCENARIO = ROOT / "scenarios" / "failures" / "follower_stop.yaml"


class Timers:
    """Per-call times [s] of the stage, the filter and the counters, while installed."""

    def __init__(self) -> None:
        self.times: dict[str, list[float]] = {"stage": [], "filter": [], "counters": []}
        self._saved: list[tuple[object, str, object]] = []

    def install(self) -> None:
        """Wrap the three functions where the loop and the filter look them up."""
        for owner, name, key in (
            (Safety, "commands", "stage"),
            (cbf, "filter_commands", "filter"),
            (cbf, "account_worlds", "counters"),
        ):
            real = getattr(owner, name)
            self._saved.append((owner, name, real))
            setattr(owner, name, self._timed(real, self.times[key]))

    def uninstall(self) -> None:
        """Put the functions back."""
        for owner, name, real in reversed(self._saved):
            setattr(owner, name, real)
        self._saved.clear()

    @staticmethod
    def _timed(real, into: list[float]):
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            out = real(*args, **kwargs)
            into.append(time.perf_counter() - t0)
            return out

        return timed


def measure(scenarios: list, use_c: bool) -> dict[str, float]:
    """Mean [ms] per period of each timed call, and [ms] per run, of one batch."""
    timers = Timers()
    timers.install()
    try:
        with contextlib.ExitStack() as stack:
            if not use_c:
                stack.enter_context(accel.switched_off("filter"))
            t0 = time.perf_counter()
            Simulation.batch(scenarios, group_size=len(scenarios))
            elapsed = time.perf_counter() - t0
    finally:
        timers.uninstall()
    out = {k: 1e3 * statistics.fmean(v) for k, v in timers.times.items() if v}
    out["run"] = 1e3 * elapsed / len(scenarios)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--worlds", type=int, default=64, help="seeds in the batch")
    p.add_argument("--duration", type=float, default=8.0, help="[s] of each run")
    p.add_argument("--repeat", type=int, default=3, help="batches of each path")
    p.add_argument(
        "--set", action="append", default=[], help="more assignments (a.b=v)"
    )
    args = p.parse_args(argv)
    sets = [f"duration={args.duration}", "safety.filter=cbf", *args.set]
    scenarios = [
        load_scenario(SCENARIO, overrides=[*sets, f"seed={s}"])
        for s in range(args.worlds)
    ]
    if accel.module("filter") is None:
        print("the compiled path filter is off (sandbox info): numpy alone")
    Simulation.batch(scenarios[:2])  # not timed: the imports
    load_before = os.getloadavg()
    found: dict[str, list[dict[str, float]]] = {"C": [], "numpy": []}
    for _ in range(args.repeat):
        for name in found:
            found[name].append(measure(scenarios, name == "C"))
    load_after = os.getloadavg()
    print(
        f"{args.worlds} worlds of follower_stop ({args.duration:g} s), "
        f"{' '.join(sets[1:])}; median of {args.repeat}; load average "
        f"{_load(load_before)} before, {_load(load_after)} after"
    )
    print()
    print("| path | stage [ms/period] | filter | counters | per run [ms] |")
    print("|---|---:|---:|---:|---:|")
    for name, rows in found.items():
        cells = [
            statistics.median(r.get(k, float("nan")) for r in rows)
            for k in ("stage", "filter", "counters", "run")
        ]
        print(
            f"| {name} | {cells[0]:.3f} | {cells[1]:.3f} | {cells[2]:.3f} | "
            f"{cells[3]:.1f} |"
        )
    return 0


def _load(avg: tuple[float, float, float]) -> str:
    return ", ".join(f"{x:.2f}" for x in avg)


if __name__ == "__main__":
    raise SystemExit(main())
