"""``sandbox run FILE``: simulate, write the run directory, print a summary."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sandbox._startup import StopOnSignal
from sandbox.cli.common import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    add_command,
    add_gif_options,
    add_plugin_option,
    check_gif_frames,
    check_mp4,
    nonempty,
    positive,
    progress,
    render_gif,
    scenario_file,
)
from sandbox.cli.info import not_built_warnings
from sandbox.errors import Problem, ScenarioError

#: What the first SIGINT/SIGTERM of a run says.
STOP_NOTICE = (
    "stopping: the run ends at this step and its outputs are written (a second "
    "Ctrl-C stops at once, without them)"
)


def cmd_run(args: argparse.Namespace) -> int:
    """``sandbox run FILE``: simulate, write the run directory, print a summary."""
    from sandbox.loop.simulation import Simulation
    from sandbox.run.metrics import compute_metrics
    from sandbox.run.output import check_out_dir, write_run_dir
    from sandbox.run.record import (
        STATUS_DIVERGED,
        STATUS_ERROR,
        STATUS_INTERRUPTED,
    )
    from sandbox.scenario import load_scenario

    if args.format == "parquet":
        from sandbox.run.analysis import require

        require("pyarrow", "--format parquet")  # before simulating, not after
    overrides = list(args.set or [])
    if args.duration is not None:
        overrides.append(f"duration={args.duration!r}")
    try:
        scenario = load_scenario(scenario_file(args.file), overrides=overrides)
    except ScenarioError as exc:
        raise _blame_duration_option(exc, args.duration) from None
    out_dir = Path(args.out) if args.out is not None else Path("runs") / scenario.name
    check_out_dir(out_dir)  # before simulating: refuse early, not after a long run
    if args.html:
        from sandbox.cli.view import EXIT_INVALID, html_problem

        problem = html_problem(out_dir)
        if problem:
            print(f"error: {problem}", file=sys.stderr)
            return EXIT_INVALID
    check_mp4(args)
    if args.gif:
        check_gif_frames(scenario.duration, args)
    # Building the run: a signal ends the command (nothing is written yet). Then a
    # first SIGINT/SIGTERM only raises the flag until the outputs are written: the
    # run stops at the next step and its outputs so far are written whole
    # (atomically); a second stops the command at once (sandbox/_startup.py).
    sim = Simulation(scenario)
    with StopOnSignal(STOP_NOTICE) as stop:
        with progress(sim.steps, "simulating") as bar:
            run = sim.run(progress=bar, should_stop=stop)
        metrics = compute_metrics(run)
        write_run_dir(run, metrics, out_dir, trajectory=args.format)
    _print_summary(scenario.name, metrics, out_dir, args.format)
    for line in [*metrics.get("warnings", []), *not_built_warnings()]:
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
    if args.html and run.status != STATUS_INTERRUPTED:
        from sandbox.cli.view import print_written, write_run_html

        beams = bool(getattr(args, "show_beams", False))
        page = write_run_html(run, out_dir / "replay.html", metrics, show_beams=beams)
        print_written(page)
    elif args.html:
        print(f"html: skipped, the run was interrupted (sandbox view {out_dir})")
    if run.status == STATUS_DIVERGED:
        d = metrics.get("diverged", {})
        print(
            f"error: the run diverged at t = {d.get('t', 0):.3f} s "
            f"(vehicle {d.get('vehicle')}: {d.get('reason')}); outputs up to then are "
            f"in {out_dir}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    if run.status == STATUS_ERROR:
        e = metrics.get("error", {})
        print(
            f"error: at t = {e.get('t', 0):.3f} s the {e.get('plugin')} failed: "
            f"{e.get('message')}; outputs up to then are in {out_dir} (status 'error')",
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


def _print_summary(name: str, metrics: dict, out_dir: Path, fmt: str) -> None:
    from sandbox.run.metrics import (
        convergence_summary,
        deadlock_summary,
        summary_rows,
    )

    col = metrics["collisions"]
    md = metrics["min_distance"]
    print(
        f"{name}: status {metrics['status']}, {metrics['duration']:.2f} s simulated, "
        f"converged: {convergence_summary(metrics)}"
    )
    print(
        f"collisions: {col['total']} (vehicle-vehicle {col['vehicle_vehicle']}, "
        f"vehicle-obstacle {col['vehicle_obstacle']}); min distance: "
        f"{'-' if md is None else f'{md:.3f} m'}"
    )
    print(deadlock_summary(metrics))
    for pname, p in metrics.get("platoons", {}).items():  # with platoons: only
        st = p["settling_time"]
        print(
            f"platoon {pname}: converged {'yes' if p['converged'] else 'no'}, "
            f"settle {'-' if st is None else f'{st:.2f} s'}, contacts within "
            f"{p['collisions']['intra_platoon']}, with other platoons "
            f"{p['collisions']['inter_platoon']}"
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
    print(
        f"outputs: {out_dir}/ (trajectory.{fmt}, metrics.json, scenario.yaml, run.npz)"
    )


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``run`` command."""
    p = add_command(
        sub,
        "run",
        "run a scenario file or a bundled scenario",
        [
            "sandbox run paper/rotating_circle      # a bundled one (sandbox list)",
            "sandbox run my.yaml --out runs/try1 --gif try1.gif",
            "sandbox run failures/follower_stop --set recovery.beta=2.5 --duration 10",
            "sandbox run scale/grid_1000 --format parquet",
        ],
        description=(
            "Simulate a scenario, write its run directory (trajectory, metrics.json, "
            "scenario.yaml, run.npz) and print a summary. A progress bar with an ETA "
            "is shown on a terminal (not in pipes or under CI)."
        ),
    )
    p.add_argument(
        "file",
        metavar="SCENARIO",
        help="scenario YAML file, or a bundled name such as paper/rotating_circle",
    )
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
    p.add_argument(
        "--format",
        choices=("csv", "parquet"),
        default="csv",
        help="trajectory file: trajectory.csv (default) or trajectory.parquet "
        "(needs the 'analysis' extra)",
    )
    p.add_argument("--gif", type=nonempty, help="also render the run to this GIF file")
    add_gif_options(p)
    p.add_argument(
        "--html",
        action="store_true",
        help="also write the interactive replay OUT/replay.html (see sandbox view)",
    )
    add_plugin_option(p, trust=True)
    p.set_defaults(func=cmd_run)
