"""Detection delay against false-alarm rate over the CUSUM threshold lambda.

The residual detector (``sandbox/detection.py``) is run once per scenario with its
alarms switched off (``lambda`` = 1e9) and every window's log-likelihood ratio
recorded (``memory["trace"]``). A run is the same for every ``lambda`` up to its first
alarm, so the CUSUM of each ``lambda`` of the grid is recomputed from the one trace:

- false alarms: ``scenarios/failures/detect_fault_free.yaml`` over ``--seeds`` seeds
  (4 vehicles x 60 s each; 45 seeds = 3 vehicle-hours), alarms counted with the CUSUM
  restarted after each, per vehicle-hour, against the theory (one every e^lambda
  windows for independent windows: Lorden's bound);
- delays: the six ``scenarios/failures/detect_*.yaml`` failures, the time from the
  onset to the first alarm on the failed vehicle.

Prints a table and writes the figure (default
``studies/figures/detection_delay_false_alarms.png``)::

    python benchmarks/detection_lambda.py                # 45 seeds, about 4 min
    python benchmarks/detection_lambda.py --seeds 5      # quicker
    python benchmarks/detection_lambda.py --replot FIGURE.json   # redraw only

The table is also written beside the figure, as ``.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sandbox import Simulation, load_scenario  # noqa: E402

FAILURES = ROOT / "scenarios" / "failures"
FAILED = (
    "detect_follower_stop",
    "detect_follower_spin",
    "detect_follower_stuck_steering",
    "detect_follower_crash",
    "detect_uncontrolled_into_leader",
    "detect_leader_spin",
)
LAMBDAS = (4.0, 6.0, 8.0, 10.0, 12.0, 16.0, 20.0, 30.0, 40.0, 60.0)
OFF = "detection.lambda=1e9"
#: What the .json beside the figure keeps (the table), in _figure's order.
SAVED = ("hours", "theory", "measured", "mean_delay", "max_delay")


def trace(path: Path, *sets: str) -> tuple[Simulation, np.ndarray]:
    """Run a scenario with alarms off; its windows' ``(t, vehicle, l)`` rows."""
    sim = Simulation(load_scenario(path, overrides=[OFF, *sets]))
    rows: list = []
    sim.detection.memory["trace"] = rows
    sim.run()
    return sim, np.array(rows, dtype=float).reshape(-1, 3)


def alarms(rows: np.ndarray, vehicle: int, lam: float) -> list[float]:
    """Alarm times of one vehicle's CUSUM at threshold ``lam`` (restarted at each)."""
    g, out = 0.0, []
    for t, _, x in rows[rows[:, 1] == vehicle]:
        g = max(0.0, g + x)
        if g >= lam:
            out.append(float(t))
            g = 0.0
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the study, print the table, write the figure."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=45, help="fault-free seeds")
    parser.add_argument(
        "--out",
        type=Path,
        default=ROOT / "studies" / "figures" / "detection_delay_false_alarms.png",
    )
    parser.add_argument(
        "--replot",
        type=Path,
        help="draw the figure from a table saved by an earlier run (its .json)",
    )
    args = parser.parse_args(argv)
    if args.replot is not None:
        saved = json.loads(args.replot.read_text(encoding="utf-8"))
        _figure(args.out, *(saved[k] for k in SAVED))
        print(f"figure: {args.out}")
        return 0

    false_alarms = {lam: 0 for lam in LAMBDAS}
    hours = 0.0
    windows = 0
    window_period = None
    for seed in range(args.seeds):
        sim, rows = trace(FAILURES / "detect_fault_free.yaml", f"seed={seed}")
        sc = sim.scenario
        hours += sc.duration * len(sc.vehicles) / 3600.0
        windows += len(rows)
        # Each window lasts `window` and the next starts at the next observation.
        window_period = sc.detection.params["window"] + sc.dt
        for lam in LAMBDAS:
            for i in range(len(sc.vehicles)):
                false_alarms[lam] += len(alarms(rows, i, lam))
        print(f"seed {seed}: {len(rows)} windows", file=sys.stderr, flush=True)

    delays: dict[float, list[float | None]] = {lam: [] for lam in LAMBDAS}
    for name in FAILED:
        sim, rows = trace(FAILURES / f"{name}.yaml")
        (failure,) = sim.scenario.failures
        i = sim.names.index(failure.vehicle)
        for lam in LAMBDAS:
            hit = [t for t in alarms(rows, i, lam) if t >= failure.at - 1e-9]
            delays[lam].append(hit[0] - failure.at if hit else None)

    print(
        f"\nfault-free: {args.seeds} runs, {hours:.2f} vehicle-hours, "
        f"{windows} windows of {window_period:g} s"
    )
    print(
        "| lambda | theory: alarms per vehicle-hour (e^-lambda per window) "
        "| false alarms | per vehicle-hour | mean delay [s] | max delay [s] |"
    )
    print("|---|---|---|---|---|---|")
    theory, measured, mean_delay, max_delay = [], [], [], []
    for lam in LAMBDAS:
        th = 3600.0 / window_period * math.exp(-lam)
        rate = false_alarms[lam] / hours
        found = [d for d in delays[lam] if d is not None]
        missed = len(delays[lam]) - len(found)
        mean = float(np.mean(found)) if found else float("nan")
        worst = max(found) if found else float("nan")
        theory.append(th)
        measured.append(rate)
        mean_delay.append(mean)
        max_delay.append(worst)
        miss = f" ({missed} missed)" if missed else ""
        print(
            f"| {lam:g} | {th:.3g} | {false_alarms[lam]} | {rate:.3g} | "
            f"{mean:.3f}{miss} | {worst:.2f} |"
        )
    numbers = dict(
        zip(SAVED, (hours, theory, measured, mean_delay, max_delay), strict=True)
    )
    numbers["lambda"] = list(LAMBDAS)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(
        json.dumps(numbers, indent=1) + "\n", encoding="utf-8"
    )
    _figure(args.out, hours, theory, measured, mean_delay, max_delay)
    print(f"\nfigure: {args.out}")
    return 0


def _figure(out, hours, theory, measured, mean_delay, max_delay) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lam = np.array(LAMBDAS)
    measured = np.array(measured)
    theory = np.array(theory)
    bound = 3.0 / hours  # 95 % upper bound of a rate with no event in `hours`
    fig, (left, right) = plt.subplots(1, 2, figsize=(10.0, 4.2), dpi=120)
    # Left: the trade-off. x: the measured rate, or (hollow) the theory's where no
    # alarm was seen in the fault-free hours.
    seen = measured > 0
    x = np.where(seen, measured, theory)
    left.plot(x, mean_delay, "-", color="tab:blue", lw=1.0)
    left.plot(
        x[seen],
        np.array(mean_delay)[seen],
        "o",
        color="tab:blue",
        label="mean delay, rate measured",
    )
    left.plot(
        x[~seen],
        np.array(mean_delay)[~seen],
        "o",
        mfc="none",
        color="tab:blue",
        label="mean delay, rate from theory (none seen)",
    )
    left.plot(x, max_delay, "s--", color="tab:orange", ms=5, label="max delay")
    for k, (lv, xv, yv) in enumerate(zip(lam, x, mean_delay, strict=True)):
        # alternate above and below: neighbouring points sit close on the log axis
        left.annotate(
            f"{lv:g}",
            (xv, yv),
            textcoords="offset points",
            xytext=(3, 5 if k % 2 else -12),
            fontsize=8,
        )
    left.axvline(1.0, color="tab:red", lw=0.8, ls="--")
    left.set_xscale("log")
    left.set_xlabel("false alarms per vehicle-hour")
    left.set_ylabel("detection delay [s], 6 bundled failures")
    left.set_title("Delay against false alarms (lambda on each point)", fontsize=10)
    left.legend(fontsize=7, loc="upper right")
    left.grid(True, which="both", alpha=0.3)
    # Right: the false-alarm rate against lambda.
    right.semilogy(
        lam, theory, ":", color="tab:gray", label="theory, e^-lambda per window"
    )
    right.semilogy(lam[seen], measured[seen], "o", color="tab:blue", label="measured")
    right.semilogy(
        lam[~seen],
        np.full((~seen).sum(), bound),
        "v",
        mfc="none",
        color="tab:blue",
        label=f"none in {hours:.1f} h: below {bound:.2g}",
    )
    right.axhline(1.0, color="tab:red", lw=0.8, ls="--")
    right.set_ylim(1e-6, 3e3)
    right.set_xlabel("lambda [nats]")
    right.set_ylabel("false alarms per vehicle-hour")
    right.set_title(f"Fault-free, {hours:.1f} vehicle-hours", fontsize=10)
    right.legend(fontsize=7, loc="upper right")
    right.grid(True, which="both", alpha=0.3)
    fig.suptitle("Residual CUSUM under 1 cm / 0.005 rad broadcast noise", fontsize=11)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, metadata={"Software": None})
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
