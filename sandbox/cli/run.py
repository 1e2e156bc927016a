"""``sandbox run FILE``: simulate, write the run directory, print a summary."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sandbox.cli.common import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    StopFlag,
    add_gif_options,
    add_plugin_option,
    check_gif_frames,
    check_mp4,
    nonempty,
    positive,
    progress_printer,
    render_gif,
)
from sandbox.errors import Problem, ScenarioError
from sandbox.metrics import compute_metrics, summary_rows
from sandbox.output import check_out_dir, write_run_dir
from sandbox.run import STATUS_DIVERGED, STATUS_INTERRUPTED
from sandbox.scenario import load_scenario
from sandbox.simulation import Simulation


def cmd_run(args: argparse.Namespace) -> int:
    """``sandbox run FILE``: simulate, write the run directory, print a summary."""
    overrides = list(args.set or [])
    if args.duration is not None:
        overrides.append(f"duration={args.duration!r}")
    try:
        scenario = load_scenario(args.file, overrides=overrides)
    except ScenarioError as exc:
        raise _blame_duration_option(exc, args.duration) from None
    for line in scenario.warnings:
        print(f"warning: {line}", file=sys.stderr)
    out_dir = Path(args.out) if args.out is not None else Path("runs") / scenario.name
    check_out_dir(out_dir)  # before simulating: refuse early, not after a long run
    check_mp4(args)
    if args.gif:
        check_gif_frames(scenario.duration, args)
    # SIGINT/SIGTERM only raise the flag until the outputs are written: the run stops
    # at the next step and its outputs so far are still written whole (atomically).
    with StopFlag() as stop:
        run = Simulation(scenario).run(progress=progress_printer(), should_stop=stop)
        metrics = compute_metrics(run)
        write_run_dir(run, metrics, out_dir)
    _print_summary(scenario.name, metrics, out_dir)
    for line in metrics.get("warnings", []):
        print(f"warning: {line}", file=sys.stderr)
    if stop() and run.status != STATUS_INTERRUPTED:
        # The signal came after the last step, while the outputs were written: they
        # are complete; the GIF is skipped and the exit status says it was stopped.
        print(
            f"interrupted: the run had finished; its outputs are complete in {out_dir}",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    if args.gif and run.status == STATUS_INTERRUPTED:
        print(
            f"gif: skipped, the run was interrupted (sandbox render {out_dir} --gif "
            f"{args.gif} renders what was simulated)",
            file=sys.stderr,
        )
    elif args.gif or args.mp4:
        render_gif(run, args)
    if run.status == STATUS_DIVERGED:
        d = metrics.get("diverged", {})
        print(
            f"error: the run diverged at t = {d.get('t', 0):.3f} s "
            f"(vehicle {d.get('vehicle')}: {d.get('reason')}); outputs up to then are "
            f"in {out_dir}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    if run.status == STATUS_INTERRUPTED:
        print(
            f"interrupted: outputs so far are in {out_dir} (status 'interrupted')",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    return EXIT_OK


def _blame_duration_option(exc: ScenarioError, duration: float | None) -> ScenarioError:
    """Problems that ``--duration`` caused, pointed at it rather than at a ``--set``."""
    if duration is None:
        return exc
    item = f"[from --set duration={duration!r}]"
    problems = [
        Problem(
            p.path, p.message.replace(item, f"[from --duration {duration:g}]"), p.line
        )
        for p in exc.problems
    ]
    return ScenarioError(problems, exc.source)


def _print_summary(name: str, metrics: dict, out_dir: Path) -> None:
    col = metrics["collisions"]
    md = metrics["min_distance"]
    print(
        f"{name}: status {metrics['status']}, {metrics['duration']:.2f} s simulated, "
        f"converged: {'yes' if metrics['converged'] else 'no'}"
    )
    print(
        f"collisions: {col['total']} (vehicle-vehicle {col['vehicle_vehicle']}, "
        f"vehicle-obstacle {col['vehicle_obstacle']}); min distance: "
        f"{'-' if md is None else f'{md:.3f} m'}"
    )
    header = (
        "vehicle",
        "final err [m]",
        "rms last 1/4",
        "settle [s]",
        "effort",
        "switches",
    )
    rows = summary_rows(metrics)
    shown = rows[:20]
    widths = [max(len(r[i]) for r in [header, *shown]) for i in range(len(header))]
    for r in [header, *shown]:
        print(
            "  ".join(
                c.rjust(w) if i else c.ljust(w)
                for i, (c, w) in enumerate(zip(r, widths, strict=True))
            )
        )
    if len(rows) > len(shown):
        print(f"... and {len(rows) - len(shown)} more vehicles (see metrics.json)")
    print(f"outputs: {out_dir}/ (trajectory.csv, metrics.json, scenario.yaml, run.npz)")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``run`` command."""
    p = sub.add_parser("run", help="run a scenario file")
    p.add_argument("file", help="scenario YAML file")
    p.add_argument(
        "--out", type=nonempty, help="output directory (default runs/<name>/)"
    )
    p.add_argument(
        "--duration",
        type=positive(float),
        help="override the duration [s], a number > 0",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="override a field, e.g. --set recovery.beta=2.5 (repeatable)",
    )
    p.add_argument("--gif", type=nonempty, help="also render the run to this GIF file")
    add_gif_options(p)
    add_plugin_option(p)
    p.set_defaults(func=cmd_run)
