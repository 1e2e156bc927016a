"""Command-line interface: ``sandbox run | validate | list | render | plot | schema``.

No simulation logic lives here: the commands call the same API as Python users. Every
user mistake ends in one line per problem on stderr and a non-zero exit, never a
traceback.

Exit status: 0 success; 1 a run diverged or a command failed; 2 invalid input;
130 a run was interrupted (its outputs so far are written, flagged ``interrupted``).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType

from sandbox.errors import SandboxError, ScenarioError
from sandbox.metrics import compute_metrics, summary_rows
from sandbox.output import check_out_dir, load_run_dir, write_run_dir, write_text_atomic
from sandbox.run import STATUS_DIVERGED, STATUS_INTERRUPTED, Run
from sandbox.scenario import load_scenario
from sandbox.simulation import Simulation

EXIT_OK, EXIT_FAILED, EXIT_INVALID, EXIT_INTERRUPTED = 0, 1, 2, 130


def bundled_scenarios_dir() -> Path:
    """The ``scenarios/`` folder: the working directory's, else the source tree's."""
    here = Path.cwd() / "scenarios"
    if here.is_dir():
        return here
    return Path(__file__).resolve().parent.parent / "scenarios"


def _progress_printer() -> Callable[[int, int], None] | None:
    """A progress line on an interactive terminal; nothing under CI or into a pipe."""
    if os.environ.get("CI") or not sys.stderr.isatty():
        return None

    def show(step: int, steps: int) -> None:
        sys.stderr.write(f"\r  simulating: {100 * step // max(steps, 1):3d}%")
        sys.stderr.flush()
        if step + max(1, steps // 100) > steps:
            sys.stderr.write("\r" + " " * 24 + "\r")

    return show


class _StopFlag:
    """SIGINT/SIGTERM handler that asks the running simulation to stop cleanly."""

    def __init__(self) -> None:
        self.raised = False
        self._old: dict[int, object] = {}

    def __call__(self) -> bool:
        return self.raised

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.raised = True

    def __enter__(self) -> _StopFlag:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def cmd_run(args: argparse.Namespace) -> int:
    """``sandbox run FILE``: simulate, write the run directory, print a summary."""
    overrides = list(args.set or [])
    if args.duration is not None:
        overrides.append(f"duration={args.duration}")
    scenario = load_scenario(args.file, overrides=overrides)
    for line in scenario.warnings:
        print(f"warning: {line}", file=sys.stderr)
    out_dir = Path(args.out) if args.out else Path("runs") / scenario.name
    check_out_dir(out_dir)  # before simulating: refuse early, not after a long run
    # SIGINT/SIGTERM only raise the flag until the outputs are written: the run stops
    # at the next step and its outputs so far are still written whole (atomically).
    with _StopFlag() as stop:
        run = Simulation(scenario).run(progress=_progress_printer(), should_stop=stop)
        metrics = compute_metrics(run)
        write_run_dir(run, metrics, out_dir)
    _print_summary(scenario.name, metrics, out_dir)
    if args.gif and run.status == STATUS_INTERRUPTED:
        print(
            f"gif: skipped, the run was interrupted (sandbox render {out_dir} --gif "
            f"{args.gif} renders what was simulated)",
            file=sys.stderr,
        )
    elif args.gif:
        _gif(run, args)
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


def _gif(run: Run, args: argparse.Namespace) -> None:
    """Render ``run`` to ``args.gif`` (atomically: temporary file, then rename)."""
    from sandbox.render import write_gif

    try:
        info = write_gif(
            run,
            Path(args.gif),
            fps=args.fps,
            size=args.size,
            speed=args.speed,
            zones=args.zones,
            follow=args.follow,
        )
    except ValueError as exc:  # an option the renderer refuses (fps, size, ...)
        raise GifOptionError(f"--gif {args.gif}: {exc}") from None
    print(f"gif: {info['path']} ({info['frames']} frames, {info['duration']:.1f} s)")


class GifOptionError(SandboxError):
    """A GIF option the renderer refuses."""


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


def cmd_validate(args: argparse.Namespace) -> int:
    """``sandbox validate FILE...``: check files without running them."""
    status = EXIT_OK
    for name in args.files:
        try:
            scenario = load_scenario(name, overrides=args.set)
        except ScenarioError as exc:
            for line in exc.lines:
                print(line, file=sys.stderr)
            status = EXIT_INVALID
            continue
        for line in scenario.warnings:
            print(f"warning: {line}", file=sys.stderr)
        print(
            f"{name}: ok ({len(scenario.vehicles)} vehicles, {scenario.duration:g} s)"
        )
    return status


def cmd_list(args: argparse.Namespace) -> int:
    """``sandbox list``: the bundled scenarios with their descriptions."""
    root = bundled_scenarios_dir()
    files = sorted(p for p in root.rglob("*.yaml") if p.name != "reference.yaml")
    if not files:
        print(f"no scenarios found under {root}", file=sys.stderr)
        return EXIT_FAILED
    for path in files:
        try:
            sc = load_scenario(path)
            desc = (sc.description.splitlines() or [""])[0]
        except ScenarioError as exc:
            desc = f"(invalid: {exc.lines[0]})"
        print(f"{path.relative_to(root.parent)}\n    {desc}")
    return EXIT_OK


def cmd_render(args: argparse.Namespace) -> int:
    """``sandbox render RUN_DIR --gif PATH``: a GIF from a saved run."""
    run = load_run_dir(Path(args.run_dir))
    _gif(run, args)
    return EXIT_OK


def cmd_gallery(args: argparse.Namespace) -> int:
    """``sandbox gallery``: run and render every scenario of the given folders."""
    from sandbox.gallery import render_gallery

    folders = [
        Path(f) for f in (args.folders or ["scenarios/paper", "scenarios/failures"])
    ]
    missing = [str(f) for f in folders if not f.is_dir()]
    if missing:
        print(f"error: no such folder: {', '.join(missing)}", file=sys.stderr)
        return EXIT_FAILED
    render_gallery(folders, Path(args.out), zones=args.zones)
    return EXIT_OK


def cmd_plot(args: argparse.Namespace) -> int:
    """``sandbox plot RUN_DIR``: the four report-style figures."""
    from sandbox.plot import plot_run

    run = load_run_dir(Path(args.run_dir))
    for path in plot_run(run, Path(args.out) if args.out else Path(args.run_dir)):
        print(path)
    return EXIT_OK


def cmd_schema(args: argparse.Namespace) -> int:
    """``sandbox schema [--out FILE]``: the JSON Schema of the scenario format."""
    from sandbox.schema import schema_json

    text = schema_json()
    if not args.out:
        sys.stdout.write(text)
        return EXIT_OK
    write_text_atomic(Path(args.out), text)
    print(f"schema: {args.out}")
    return EXIT_OK


def cmd_compare(args: argparse.Namespace) -> int:
    """``sandbox compare FILE...``: a table of metrics per scenario and strategy."""
    from sandbox.compare import compare, format_table

    def names(text: str) -> list[str]:
        return [x.strip() for x in text.split(",") if x.strip()]

    try:
        rows = compare(
            args.files,
            names(args.strategies),
            names(args.derivatives),
            args.set or [],
            jobs=args.jobs,
        )
    except ValueError as exc:
        if isinstance(exc, ScenarioError):
            raise
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    sys.stdout.write(format_table(rows, args.format))
    return EXIT_OK


def _positive(kind: type) -> Callable[[str], float]:
    """An argparse type: a finite number greater than 0."""

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            message = f"expected a number, got {text!r}"
            raise argparse.ArgumentTypeError(message) from None
        if not (0 < value < float("inf")):
            raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
        return value

    return parse


def _add_gif_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--fps",
        type=_positive(float),
        default=25.0,
        help="frames per second, at most 50 (default 25)",
    )
    p.add_argument(
        "--size",
        type=_positive(int),
        default=640,
        help="frame size in pixels (default 640)",
    )
    p.add_argument(
        "--speed",
        type=_positive(float),
        default=1.0,
        help="playback speed relative to simulated time (default 1)",
    )
    p.add_argument("--zones", action="store_true", help="draw the R (and r) safe zones")
    p.add_argument(
        "--follow",
        choices=("leader",),
        default=None,
        help="camera follows the leader instead of framing the whole run",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``sandbox`` command."""
    parser = argparse.ArgumentParser(
        prog="sandbox",
        description=(
            "Physics-backed 2D sandbox for collective motion of unicycle vehicles."
        ),
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="run a scenario file")
    p.add_argument("file", help="scenario YAML file")
    p.add_argument("--out", help="output directory (default runs/<name>/)")
    p.add_argument("--duration", help="override the duration [s]")
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="override a field, e.g. --set recovery.beta=2.5 (repeatable)",
    )
    p.add_argument("--gif", help="also render the run to this GIF file")
    _add_gif_options(p)
    p.set_defaults(func=cmd_run)
    p = sub.add_parser("validate", help="check scenario files without running them")
    p.add_argument("files", nargs="+")
    p.add_argument("--set", action="append", metavar="PATH=VALUE")
    p.set_defaults(func=cmd_validate)
    p = sub.add_parser("list", help="list the bundled scenarios")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("render", help="render a saved run to a GIF")
    p.add_argument("run_dir")
    p.add_argument("--gif", required=True, help="output GIF file")
    _add_gif_options(p)
    p.set_defaults(func=cmd_render)
    p = sub.add_parser("gallery", help="run and render every scenario of some folders")
    p.add_argument(
        "folders",
        nargs="*",
        help="scenario folders (default scenarios/paper scenarios/failures)",
    )
    p.add_argument("--out", default="renders", help="output folder (default renders/)")
    p.add_argument("--zones", action="store_true", help="draw the R (and r) safe zones")
    p.set_defaults(func=cmd_gallery)
    p = sub.add_parser("plot", help="write report-style figures of a saved run")
    p.add_argument("run_dir")
    p.add_argument("--out", help="directory for the PNGs (default: the run directory)")
    p.set_defaults(func=cmd_plot)
    p = sub.add_parser("schema", help="print the JSON Schema of scenario files")
    p.add_argument("--out", help="write it to this file instead of printing it")
    p.set_defaults(func=cmd_schema)
    p = sub.add_parser("compare", help="compare recovery strategies on scenario files")
    p.add_argument("files", nargs="+", help="scenario YAML files")
    p.add_argument(
        "--strategies",
        default="none,discontinuous,continuous,smooth",
        help="comma-separated strategies, or file for each file's own "
        "(default: all four)",
    )
    p.add_argument(
        "--derivatives",
        default="hold",
        help="comma-separated target_derivatives modes: hold, estimate (default hold)",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="override a field in every run (repeatable)",
    )
    p.add_argument("--format", choices=("markdown", "csv"), default="markdown")
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="worker processes (default 1); the table is the same",
    )
    p.set_defaults(func=cmd_compare)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ScenarioError as exc:
        for line in exc.lines:
            print(line, file=sys.stderr)
        return EXIT_INVALID
    except GifOptionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except SandboxError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except BrokenPipeError:
        # The reader of our output went away (e.g. `sandbox schema | head`).
        sys.stderr.close()
        return EXIT_FAILED
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
